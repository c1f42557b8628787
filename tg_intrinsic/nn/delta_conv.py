from typing import Optional, Tuple

import torch
import torch.nn.functional as F
from torch import Tensor
from torch_geometric.nn import MLP, MessagePassing
from torch_geometric.nn.aggr import (MaxAggregation, MeanAggregation,
                                     MinAggregation, SumAggregation)
from torch_geometric.utils import scatter

from tg_intrinsic.geometry.checks import (check_edge_index, compiling,
                                          check_positive_int, check_rows,
                                          check_tensor, check_vector_features)
from tg_intrinsic.geometry.pointcloud.operators import (SurfaceOperators,
                                                        VectorCalculus,
                                                        interleaved, planar,
                                                        vector_norm)
from tg_intrinsic.nn._machinery import sets_per_edge_machinery
from tg_intrinsic.nn.sync_batch_norm import SyncBatchNorm
from tg_intrinsic.nn.vector_linear import VectorLinear
from tg_intrinsic.nn.vector_mlp import VectorMLP
from tg_intrinsic.nn.vector_nonlin import VectorNonLin


def scalar_mlp(channels, plain_last: bool = False) -> MLP:
    """DeltaConv's scalar MLP: bias-free linear, batch norm, LeakyReLU(0.2)."""
    return MLP(channels, act='leaky_relu', act_kwargs={'negative_slope': 0.2},
               norm='batch_norm', bias=False, plain_last=plain_last)


class DeltaConv(MessagePassing):
    r"""The DeltaConv operator from the `"DeltaConv: Anisotropic Operators
    for Geometric Deep Learning on Point Clouds"
    <https://arxiv.org/abs/2111.08799>`_ paper (SIGGRAPH 2022), with a scalar
    and a vector stream. It computes

    .. math::
        \mathbf{v}'_i &= h_0\big(\mathbf{v}, G\mathbf{x}, \Delta_H
        \mathbf{v}\big)_i

        \mathbf{x}'_i &= h_1\big(\mathbf{x}, D\mathbf{v}',
        \operatorname{curl} \mathbf{v}', \|\mathbf{v}'\|\big)_i +
        \max_{j \in \mathcal{N}(i)} h_2(\mathbf{x}_j),

    where :math:`G`, :math:`D` are the MLS gradient and divergence,
    :math:`\operatorname{curl} = -DJ`,
    :math:`\Delta_H = -(GD - JGDJ)` the Hodge Laplacian, :math:`h_1, h_2`
    scalar MLPs and :math:`h_0` a :class:`VectorMLP` applied to the inputs and
    their 90-degree rotations :math:`J(\cdot)`. Scalar outputs do not depend
    on the choice of tangent frames; vector outputs rotate with them.

    Edges follow PyG's flow: ``edge_index[0]`` is the neighbour :math:`j`,
    ``edge_index[1]`` the centre :math:`i`.

    Args:
        in_channels (int): Input channels (scalar and vector).
        out_channels (int): Output channels (scalar and vector).
        depth (int, optional): Layers of every MLP. (default: :obj:`1`)
        centralized (bool, optional): Use :math:`h_2(\mathbf{x}_j -
            \mathbf{x}_i)` in the maximum (a per-edge MLP).
            (default: :obj:`False`)
        vector (bool, optional): Compute the vector stream; set
            :obj:`False` in a last layer that only feeds scalars on; then the
            scalar stream reads the incoming :math:`\mathbf{v}`.
            (default: :obj:`True`)
        aggr (str, optional): Aggregation of :math:`h_2`, any of PyG's
            (:obj:`"max"`, :obj:`"mean"`, :obj:`"sum"`, :obj:`"min"` are
            reduced without per-edge messages on the operators' graph).
            (default: :obj:`"max"`)
        vector_input (bool, optional): Whether the layer receives a vector
            stream. :obj:`False` (with :obj:`vector=False`) gives the
            scalar-only ablation of the paper,
            :math:`\mathbf{x}' = h_1(\mathbf{x}) + \max_j h_2(\mathbf{x}_j)`,
            called with :obj:`v=None`. (default: :obj:`True`)

    Shapes:
        - **input:** scalars :math:`(N, C_{in})`, vectors
          :math:`(N, C_{in}, 2)`, edge_index :math:`(2, E)`, operators built
          on the same points (:class:`SurfaceOperators`)
        - **output:** scalars :math:`(N, C_{out})`, vectors
          :math:`(N, C_{out}, 2)` (or :obj:`None` if :obj:`vector=False`)
    """
    def __init__(self, in_channels: int, out_channels: int, depth: int = 1,
                 centralized: bool = False, vector: bool = True,
                 aggr: str = 'max', vector_input: bool = True):
        super().__init__(aggr=aggr, flow='source_to_target')
        check_positive_int(in_channels, 'in_channels')
        check_positive_int(out_channels, 'out_channels')
        check_positive_int(depth, 'depth')
        self.in_channels = in_channels
        self.out_channels = out_channels
        self.depth = depth
        self.centralized = centralized
        if vector and not vector_input:
            raise ValueError("a layer without vector input cannot produce "
                             "vector output; pass vector=False")
        self.vector = vector
        self.vector_input = vector_input
        hidden = [out_channels] * depth
        self.mlp_neighbors = scalar_mlp([in_channels] + hidden)
        vec_channels = 0 if not vector_input else (
            out_channels if vector else in_channels)
        # h1 and h0 are MLPs on concatenated inputs; their first linear maps
        # are kept separate so that forward() can apply them block by block
        # (no concatenation, and D, curl act on C_out channels, not 2 C_in).
        self.lin_scalar = torch.nn.Linear(in_channels + 3 * vec_channels,
                                          out_channels, bias=False)
        self.post_scalar = torch.nn.Sequential(
            torch.nn.BatchNorm1d(out_channels), torch.nn.LeakyReLU(0.2),
            *([scalar_mlp(hidden)] if depth > 1 else []))
        if vector:
            self.lin_vector = VectorLinear(6 * in_channels, out_channels)
            self.post_vector = torch.nn.Sequential(
                VectorNonLin(out_channels),
                *([VectorMLP(hidden)] if depth > 1 else []))
        else:
            self.lin_vector = self.post_vector = None
        self.reset_parameters()

    def reset_parameters(self):
        super().reset_parameters()
        for module in self.modules():
            if module is not self and hasattr(module, 'reset_parameters'):
                module.reset_parameters()

    def forward(self, x: Tensor, v: Optional[Tensor], edge_index: Tensor,
                operators: Optional[SurfaceOperators],
                backend: Optional[str] = None
                ) -> Tuple[Tensor, Optional[Tensor]]:
        r"""Computes the layer's scalar and vector outputs.

        Args:
            x (torch.Tensor): Scalar features :math:`(N, C_{in})`.
            v (torch.Tensor, optional): Vector features
                :math:`(N, C_{in}, 2)` in the points' tangent frames (for a
                first layer, :obj:`operators.grad(x)`); :obj:`None` for a
                layer built with :obj:`vector_input=False`.
            edge_index (torch.Tensor): The neighbour graph :math:`(2, E)` of
                the aggregation of :math:`h_2`, in PyG's flow; usually the
                graph the :obj:`operators` were built on (that tensor is
                reduced without per-edge messages, and per-edge messages
                require it, or an equal one, whenever :obj:`operators` is
                given).
            operators (SurfaceOperators, optional): Gradient and divergence
                built on the same points; :obj:`None` only for a layer built
                with :obj:`vector_input=False`.
            backend (str, optional): :obj:`"sparse"` (sparse products and
                dense neighbour reductions), :obj:`"message"` (every
                operator as per-edge messages through :meth:`propagate`, so
                that edge masks, explainers and propagate hooks see every
                edge), or :obj:`None`: messages while an edge mask or a hook
                is set, sparse otherwise. Both compute the same values.
                (default: :obj:`None`)

        Returns:
            (torch.Tensor, torch.Tensor or None): Scalar features
            :math:`(N, C_{out})` and vector features :math:`(N, C_{out}, 2)`
            (:obj:`None` if :obj:`vector=False`).
        """
        if not compiling():  # validated once, outside a compiled graph
            self._check_inputs(x, v, edge_index, operators)
        if self._uses_messages(backend):
            calculus = _EdgeMessages(self, edge_index, operators)
            neighbors = self._message_neighbors
        else:
            calculus, neighbors = operators, self._sparse_neighbors
        c_in, c_out = self.in_channels, self.out_channels
        if self.lin_vector is not None:
            # h0 on [u, J u], u = [v, G x, L_H v]: with W = [W_A, W_B],
            # W [u, J u] = W_A u + J W_B u, one product per block of u.
            weight = self.lin_vector.weight
            both = None
            for block, piece in enumerate(
                    (v, calculus.grad(x), calculus.hodge_laplacian(v))):
                cols = slice(block * c_in, (block + 1) * c_in)
                w = torch.cat([weight[:, cols],
                               weight[:, 3 * c_in + cols.start:
                                      3 * c_in + cols.stop]])
                term = F.linear(planar(piece), w)  # [2, N, 2 C_out]
                both = term if both is None else both + term
            a, b = both[..., :c_out], both[..., c_out:]
            v = self.post_vector(interleaved(torch.stack(
                [a[0] - b[1], a[1] + b[0]])))
        weight = self.lin_scalar.weight
        out = F.linear(x, weight[:, :c_in])
        if self.vector_input:
            # h1 on [x, D v, curl v, |v|]: W_d D v + W_c curl v
            # = D (W_d v - J W_c v), a single divergence on C_out channels.
            c = v.size(1)
            dc = F.linear(planar(v), torch.cat([
                weight[:, c_in:c_in + c], weight[:, c_in + c:c_in + 2 * c]]))
            d, k = dc[..., :c_out], dc[..., c_out:]
            out = out + calculus.div(interleaved(torch.stack(
                [d[0] + k[1], d[1] - k[0]])))
            out = out + F.linear(vector_norm(v), weight[:, c_in + 2 * c:])
        out = self.post_scalar(out) + neighbors(x, edge_index, operators)
        return out, (v if self.lin_vector is not None else None)

    def _uses_messages(self, backend: Optional[str]) -> bool:
        if backend is None:
            return sets_per_edge_machinery(self)
        if backend not in ('sparse', 'message'):
            raise ValueError(f"backend must be 'sparse', 'message' or None, "
                             f"got {backend!r}")
        return backend == 'message'

    def _sparse_neighbors(self, x: Tensor, edge_index: Tensor,
                          operators: Optional[SurfaceOperators]) -> Tensor:
        """:math:`\bigoplus_j h_2(x_j)` (or of :math:`h_2(x_j - x_i)`) by
        dense or sparse reductions on the operators' graph; PyG's
        aggregation module on any other graph or reduction."""
        reduce = _FAST_REDUCTION.get(type(self.aggr_module))
        fast = operators is not None and reduce is not None and (
            edge_index is operators.source_edge_index)
        if not fast:
            j, i = edge_index
            h = self.mlp_neighbors(x[j] - x[i]) if self.centralized \
                else self.mlp_neighbors(x)[j]
            return self.aggr_module(h, i, dim_size=x.size(0))
        if not self.centralized:
            return operators.neighbor_reduce(self.mlp_neighbors(x), reduce)
        if reduce == 'max' and self.depth == 1:
            return self._centralized_max(x, operators)
        j, i = operators.edge_index  # a per-edge MLP, then the reduction
        return operators.edge_reduce(self.mlp_neighbors(x[j] - x[i]), reduce)

    def _message_neighbors(self, x: Tensor, edge_index: Tensor,
                           operators: Optional[SurfaceOperators]) -> Tensor:
        if self.centralized:
            return self.edge_messages(edge_index, x, centre=x)
        return self.edge_messages(edge_index, self.mlp_neighbors(x))

    def edge_messages(self, edge_index: Tensor, x: Tensor,
                      centre: Optional[Tensor] = None,
                      grad_weight: Optional[Tensor] = None,
                      div_weight: Optional[Tensor] = None) -> Tensor:
        """One :meth:`propagate` over ``edge_index``: the gradient
        (``grad_weight``), the divergence (``div_weight``) or the
        neighbours' :math:`h_2` reduced by the layer's ``aggr``."""
        linear = grad_weight is not None or div_weight is not None
        # propagate_type: (x: Tensor, centre: Optional[Tensor], grad_weight: Optional[Tensor], div_weight: Optional[Tensor], linear: bool)
        return self.propagate(edge_index, x=x, centre=centre,
                              grad_weight=grad_weight,
                              div_weight=div_weight, linear=linear)

    def _check_inputs(self, x, v, edge_index, operators):
        # Before any sparse product or numba sweep: those read out of
        # bounds (garbage, not errors) on mismatched sizes.
        x = check_tensor(x, 'x')
        if x.dim() != 2 or x.size(1) != self.in_channels \
                or not x.is_floating_point():
            raise ValueError(f"'x' must be float scalar features [N, "
                             f"{self.in_channels}], got {x.dtype} of shape "
                             f"{list(x.shape)}")
        if operators is not None:
            if not isinstance(operators, SurfaceOperators):
                raise ValueError(f"'operators' must be SurfaceOperators, got "
                                 f"{type(operators).__name__}")
            check_rows(x, 'x', operators.num_nodes, "'operators'")
        elif self.vector_input:
            raise ValueError("'operators' is None, but this layer has a "
                             "vector stream: pass SurfaceOperators(edge_"
                             "index, grad_weight, div_weight, N) built on "
                             "the same points (or build the layer with "
                             "vector=False, vector_input=False)")
        if self.vector_input:
            if v is None:
                raise ValueError(f"'v' is None, but this layer has a vector "
                                 f"stream: pass vector features [N, "
                                 f"{self.in_channels}, 2]; for a first layer "
                                 f"use v = operators.grad(x) (as DeltaNet "
                                 f"does), or build the layer with "
                                 f"vector=False, vector_input=False")
            check_vector_features(v, 'v', self.in_channels, x.size(0))
        if operators is None or edge_index is not operators.source_edge_index:
            # The operators checked their own graph when they were built.
            check_edge_index(edge_index, x.size(0), x,
                             "rows in 'x' (one per node of the graph)",
                             ref_name='x')

    def _centralized_max(self, x: Tensor,
                         operators: SurfaceOperators) -> Tensor:
        r""":math:`\max_j \sigma(\mathrm{BN}(W (x_j - x_i)))` in
        :math:`O(N C)`: with :math:`u = W x`, the batch-norm statistics over
        the edges follow from per-point neighbour sums of :math:`u` and
        :math:`u^2`, and since BN is affine per channel and the activation
        increasing, the maximum moves inside: it is taken over
        :math:`u_j` (or the minimum, where the BN scale is negative)."""
        bn = self.mlp_neighbors.norms[0].module
        u = self.mlp_neighbors.lins[0](x)
        if bn.training or not bn.track_running_stats:
            num_edges = operators.edge_index.size(1)
            in_degree = operators.crow.diff().to(u.dtype)
            out_degree = operators.out_degree.to(u.dtype)
            total = (out_degree - in_degree) @ u
            square = ((out_degree + in_degree) @ (u * u)
                      - 2 * (u * operators.neighbor_sum(u)).sum(0))
            if isinstance(bn, SyncBatchNorm):   # over all processes' edges
                c = u.size(1)
                sums = bn.all_reduce(torch.cat([
                    total, square, u.new_full((1, ), float(num_edges))]))
                total, square = sums[:c], sums[c:2 * c]
                num_edges = int(round(float(sums[-1].detach())))
            mean = total / num_edges
            var = square / num_edges - mean * mean
            if bn.training and bn.track_running_stats:
                with torch.no_grad():
                    bn.num_batches_tracked.add_(1)
                    momentum = bn.momentum if bn.momentum is not None \
                        else 1.0 / float(bn.num_batches_tracked)
                    unbiased = var * num_edges / max(num_edges - 1, 1)
                    bn.running_mean.mul_(1 - momentum).add_(momentum * mean)
                    bn.running_var.mul_(1 - momentum).add_(
                        momentum * unbiased)
        else:
            mean, var = bn.running_mean, bn.running_var
        scale = bn.weight / torch.sqrt(var + bn.eps)
        shift = bn.bias - scale * mean
        extreme = torch.where(scale >= 0, operators.neighbor_max(u),
                              -operators.neighbor_max(-u))
        return self.mlp_neighbors.act(scale * (extreme - u) + shift)

    def message(self, x_j: Tensor, centre_i: Optional[Tensor] = None,
                grad_weight: Optional[Tensor] = None,
                div_weight: Optional[Tensor] = None) -> Tensor:
        # Messages stay [E, F] so that PyG's edge masks scale the edge axis.
        if grad_weight is not None:  # G_ij x_j, planes [E, 2 * C]
            return (grad_weight.unsqueeze(-1) * x_j.unsqueeze(1)).flatten(1)
        if div_weight is not None:  # D_ij . v_j from planes [E, 2 * C]
            planes = x_j.view(x_j.size(0), 2, -1)
            return (planes * div_weight.unsqueeze(-1)).sum(1)
        if centre_i is not None:
            return self.mlp_neighbors(x_j - centre_i)
        return x_j

    def aggregate(self, inputs: Tensor, index: Tensor,
                  ptr: Optional[Tensor] = None,
                  dim_size: Optional[int] = None,
                  linear: bool = False) -> Tensor:
        # G and D are sums over the edges whatever the layer's aggr.
        if linear:
            return scatter(inputs, index, 0, dim_size, reduce='sum')
        return super().aggregate(inputs, index, ptr, dim_size)

    def __repr__(self) -> str:
        return (f'{self.__class__.__name__}({self.in_channels}, '
                f'{self.out_channels}, depth={self.depth}, '
                f'centralized={self.centralized}, vector={self.vector}, '
                f'vector_input={self.vector_input})')


#: PyG aggregation modules that the sparse path reduces without messages.
_FAST_REDUCTION = {MaxAggregation: 'max', MinAggregation: 'min',
                   SumAggregation: 'sum', MeanAggregation: 'mean'}


class _EdgeMessages(VectorCalculus):
    """:math:`G` and :math:`D` of a layer's operators as per-edge messages
    through the layer's :meth:`~DeltaConv.propagate`, in the order of the
    given ``edge_index``."""
    def __init__(self, conv: DeltaConv, edge_index: Tensor,
                 operators: Optional[SurfaceOperators]):
        self.conv = conv
        self.edge_index = edge_index
        self.weights = None if operators is None \
            else operators.weights_on(edge_index)

    def grad(self, x: Tensor) -> Tensor:
        out = self.conv.edge_messages(self.edge_index, x,
                                      grad_weight=self.weights[0])
        return interleaved(out.view(x.size(0), 2, -1).transpose(0, 1))

    def div(self, v: Tensor) -> Tensor:
        planes = planar(v).transpose(0, 1).flatten(1)  # [N, 2 * C]
        return self.conv.edge_messages(self.edge_index, planes,
                                       div_weight=self.weights[1])
