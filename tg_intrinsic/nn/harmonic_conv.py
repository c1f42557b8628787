import math
from typing import Optional

import torch
from torch import Tensor
from torch.nn import Parameter
from torch_geometric.nn import MessagePassing

from tg_intrinsic.geometry.checks import (check_edge_index,
                                          check_positive_int, check_rows,
                                          check_tensor)
from tg_intrinsic.geometry.geodesics.harmonic import (HarmonicOperator,
                                                      check_harmonic_graph)
from tg_intrinsic.geometry.precision import (at_least_float32, complex_from,
                                             refuse_low_precision)
from tg_intrinsic.nn._machinery import sets_per_edge_machinery


class HarmonicConv(MessagePassing):
    r"""The harmonic convolution from the `"CNNs on Surfaces using
    Rotation-Equivariant Features" <https://doi.org/10.1145/3386569.3392437>`_
    paper (Harmonic Surface Networks, SIGGRAPH 2020). From input stream
    :math:`M` to output stream :math:`M' = M + m`:

    .. math::
        x_i^{M'} = \sum_{M = 0}^{P} \sum_{j \in \mathcal{N}(i)} w_j\,
        R_{MM'}(r_{ij})\, e^{i(m\theta_{ij} + \beta_{MM'})}\,
        e^{iM\phi_{ji}}\, x_j^M ,

    with a learned radial profile :math:`R_{MM'}` (values on :math:`Q`
    rings, linearly interpolated, zero at the disc radius) and phase offset
    :math:`\beta_{MM'}` per input and output channel. When the frame at a
    point turns by :math:`-\varphi`, every order-:math:`M'` output there is
    multiplied by :math:`e^{iM'\varphi}` (gauge equivariance); order 0 is
    invariant.

    The neighbourhoods are aggregated first through a sparse
    :class:`~tg_intrinsic.geometry.geodesics.harmonic.HarmonicOperator` and
    contracted with the weights afterwards, so memory grows with
    :math:`N \cdot Q \cdot \text{orders}^2 \cdot C`, never with
    :math:`E \cdot Q \cdot \text{orders}^2 \cdot C`; ``backend='message'``
    runs the same maths as per-edge messages (the reference).

    Edges follow PyG's flow: ``edge_index[0]`` is the neighbour :math:`j`,
    ``edge_index[1]`` the centre :math:`i`.

    Args:
        in_channels (int): Input channels per stream.
        out_channels (int): Output channels per stream.
        max_order (int, optional): Highest output order :math:`O`; outputs
            have streams :math:`0..O`. (default: :obj:`1`)
        rings (int, optional): Rings :math:`Q` of the radial profile; must
            match :class:`~tg_intrinsic.transforms.HarmonicPrecompute`.
            (default: :obj:`6`)
        prev_order (int, optional): Highest input order :math:`P`
            (:obj:`0` for a first layer on real or invariant input).
            (default: :obj:`1`)
        offset (bool, optional): Learn the phase offsets :math:`\beta`.
            (default: :obj:`True`)
        separate_streams (bool, optional): A radial profile per pair
            :math:`(M, M')`; otherwise one per :math:`|m|`.
            (default: :obj:`True`)

    Shapes:
        - **input:** x complex :math:`(N, P + 1, C_{in})` (a real
          :math:`(N, C_{in})` is taken as stream 0), edge_index
          :math:`(2, E)`, harmonic complex :math:`(E, Q, \geq O + 1)`,
          transport :math:`(E)`
        - **output:** complex :math:`(N, O + 1, C_{out})`
    """
    def __init__(self, in_channels: int, out_channels: int,
                 max_order: int = 1, rings: int = 6, prev_order: int = 1,
                 offset: bool = True, separate_streams: bool = True):
        super().__init__(aggr='add', flow='source_to_target')
        for name, value, low in (('in_channels', in_channels, 1),
                                 ('out_channels', out_channels, 1),
                                 ('rings', rings, 1),
                                 ('max_order', max_order, 0),
                                 ('prev_order', prev_order, 0)):
            check_positive_int(value, name, minimum=low)
        self.in_channels = in_channels
        self.out_channels = out_channels
        self.max_order = max_order
        self.rings = rings
        self.prev_order = prev_order
        self.offset = offset
        self.separate_streams = separate_streams
        m = (torch.arange(max_order + 1).view(1, -1)
             - torch.arange(prev_order + 1).view(-1, 1))
        if separate_streams:
            profile_index = torch.arange(m.numel()).view_as(m)
        else:
            profile_index = m.abs()
        self.register_buffer('profile_index', profile_index,
                             persistent=False)
        profiles = int(profile_index.max()) + 1
        self.radial = Parameter(torch.empty(profiles, rings, in_channels,
                                            out_channels))
        if offset:
            self.phase = Parameter(torch.empty(profiles, in_channels,
                                               out_channels))
        else:
            self.register_parameter('phase', None)
        self.reset_parameters()

    def reset_parameters(self):
        # Every output sums (P + 1) x Q x C_in complex terms of unit scale.
        fan_in = (self.prev_order + 1) * self.rings * self.in_channels
        bound = math.sqrt(6.0 / (fan_in + self.out_channels))
        torch.nn.init.uniform_(self.radial, -bound, bound)
        if self.phase is not None:
            torch.nn.init.uniform_(self.phase, -math.pi, math.pi)

    def weights(self) -> Tensor:
        """Complex weights :math:`R\\, e^{i\\beta}` per (M, M'):
        ``[P + 1, O + 1, Q, C_in, C_out]``."""
        radial = self.radial[self.profile_index]
        if self.phase is None:
            return torch.complex(radial, torch.zeros_like(radial))
        phase = self.phase[self.profile_index].unsqueeze(2)
        return torch.complex(radial * torch.cos(phase),
                             radial * torch.sin(phase))

    def forward(self, x: Tensor, edge_index: Optional[Tensor] = None,
                harmonic: Optional[Tensor] = None,
                transport: Optional[Tensor] = None,
                operator: Optional[HarmonicOperator] = None,
                backend: Optional[str] = None) -> Tensor:
        r"""Convolves the complex stream features :obj:`x` on the disc
        graph.

        Pass either the disc graph with its precomputed :obj:`harmonic` and
        :obj:`transport`, or an :obj:`operator` built once on them and
        shared by several layers.

        Args:
            x (torch.Tensor): Complex features :math:`(N, P + 1, C_{in})`,
                or real features :math:`(N, C_{in})`, taken as stream 0
                (then :math:`P = 0`).
            edge_index (torch.Tensor, optional): The disc graph
                :math:`(2, E)`, in PyG's flow. (default: :obj:`None`)
            harmonic (torch.Tensor, optional): The harmonic terms of every
                edge, complex :math:`(E, Q, K)` with
                :math:`K \geq \max(P, O) + 1` (``data.harmonic`` of
                :class:`~tg_intrinsic.transforms.HarmonicPrecompute`).
                (default: :obj:`None`)
            transport (torch.Tensor, optional): The parallel transport angle
                :math:`\phi_{ji}` of every edge :math:`(E)`.
                (default: :obj:`None`)
            operator (HarmonicOperator, optional): The aggregation built on
                the disc graph for :math:`P + 1 \to O + 1` orders and
                :math:`Q` rings; with :obj:`backend="message"` and no
                :obj:`edge_index`, its graph is used. (default: :obj:`None`)
            backend (str, optional): :obj:`"sparse"`, :obj:`"message"`
                (per-edge messages through :meth:`propagate`), or
                :obj:`None`: messages while an edge mask (PyG's explainers)
                or a propagate hook is set, sparse otherwise; both compute
                the same values. (default: :obj:`None`)

        Returns:
            torch.Tensor: Complex features :math:`(N, O + 1, C_{out})`.
        """
        if backend is None:
            backend = 'message' if sets_per_edge_machinery(self) \
                else 'sparse'
        if backend == 'message' and operator is not None \
                and edge_index is None:
            edge_index, harmonic, transport = operator.graph
            operator = None
        refuse_low_precision(self.radial, 'weights', 'HarmonicConv')
        x = self._complex_input(x)
        if backend == 'sparse' and operator is not None:
            if not isinstance(operator, HarmonicOperator):
                raise ValueError(f"'operator' must be a HarmonicOperator, "
                                 f"got {type(operator).__name__}")
            check_rows(x, 'x', operator.num_nodes, "'operator'")
        elif backend in ('sparse', 'message'):
            if edge_index is None or harmonic is None or transport is None:
                raise ValueError(f"backend={backend!r} needs 'edge_index', "
                                 f"'harmonic' and 'transport'" +
                                 (", or a prebuilt 'operator'"
                                  if backend == 'sparse' else ''))
            # The sparse product would read past the end of x otherwise.
            check_edge_index(edge_index, x.size(0), x,
                             "rows in 'x' (one per node of the graph)",
                             ref_name='x')
            # Messages index harmonic by order and view it by rings.
            check_harmonic_graph(edge_index, harmonic, transport,
                                 max(self.prev_order, self.max_order) + 1,
                                 self.rings)
        if backend == 'message':
            y = self.propagate(edge_index, x=x.flatten(1), harmonic=harmonic,
                               transport=transport, size=None)
            y = y.view(x.size(0), self.rings, self.prev_order + 1,
                       self.max_order + 1, self.in_channels)
        elif backend == 'sparse':
            if operator is None:
                operator = HarmonicOperator(
                    edge_index, harmonic, transport, x.size(0),
                    self.prev_order + 1, self.max_order + 1)
            elif (operator.in_orders, operator.out_orders, operator.rings) \
                    != (self.prev_order + 1, self.max_order + 1, self.rings):
                raise ValueError("the operator was built for other orders or "
                                 "rings than this layer's")
            y = operator.aggregate(x)
        else:
            raise ValueError(f"backend must be 'sparse' or 'message', got "
                             f"{backend!r}")
        # out[n, M', o] = sum_{q, M, c} y[n, q, M, M', c] W[M, M', q, c, o]
        return torch.einsum('nqabc,abqco->nbo', y, self.weights())

    def message(self, x_j: Tensor, harmonic: Tensor,
                transport: Tensor) -> Tensor:
        m = self.max_order + 1
        p = self.prev_order + 1
        x_j = x_j.view(-1, p, self.in_channels)
        order = torch.arange(p, device=x_j.device)
        transport = at_least_float32(transport)  # complex maths in float32
        spin = torch.polar(torch.ones_like(transport).unsqueeze(1),
                           transport.unsqueeze(1) * order)
        x_j = x_j * spin.unsqueeze(2)  # transported, [E, P+1, C]
        diff = torch.arange(m, device=x_j.device).view(1, -1) \
            - order.view(-1, 1)
        h = harmonic[:, :, diff.abs()]  # [E, Q, P+1, O+1]
        h = torch.where(diff < 0, h.conj(), h)
        msg = h.unsqueeze(-1) * x_j.view(-1, 1, p, 1, self.in_channels)
        return msg.flatten(1)

    def _complex_input(self, x: Tensor) -> Tensor:
        check_tensor(x, 'x')
        if not x.is_complex():
            if x.dim() != 2:
                raise ValueError("real input must be [N, C] (stream 0)")
            x = complex_from(x).unsqueeze(1)
        if x.dim() != 3 or x.size(1) != self.prev_order + 1 \
                or x.size(2) != self.in_channels:
            raise ValueError(f"expected features [N, {self.prev_order + 1}, "
                             f"{self.in_channels}] (streams 0..prev_order), "
                             f"got {list(x.shape)}")
        return x

    def __repr__(self) -> str:
        return (f'{self.__class__.__name__}({self.in_channels}, '
                f'{self.out_channels}, max_order={self.max_order}, '
                f'rings={self.rings}, prev_order={self.prev_order}, '
                f'offset={self.offset}, '
                f'separate_streams={self.separate_streams})')
