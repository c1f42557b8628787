from typing import Optional

import torch
from torch import Tensor

from tg_intrinsic.geometry.checks import (check_choice, check_positive_int,
                                          check_rows)
from tg_intrinsic.geometry.geodesics.harmonic import (HarmonicOperator,
                                             harmonic_layout)
from tg_intrinsic.nn.complex_batch_norm import ComplexBatchNorm
from tg_intrinsic.nn.complex_instance_norm import ComplexInstanceNorm
from tg_intrinsic.nn.complex_linear import ComplexLinear
from tg_intrinsic.nn.complex_relu import ComplexReLU
from tg_intrinsic.nn.harmonic_conv import HarmonicConv


#: The normalisations of HSN's blocks; 'instance' (per shape) is the
#: default: with one mesh per batch, as the papers' protocols train, batch
#: norm's running statistics fit no single mesh
#: (``benchmarks/normalisation.py``).
COMPLEX_NORMS = ('instance', 'batch', None)
DEFAULT_COMPLEX_NORM = 'instance'


def complex_norm(norm: Optional[str], channels: int, streams: int
                 ) -> torch.nn.Module:
    """The normalisation :obj:`norm` of :data:`COMPLEX_NORMS`:
    :class:`ComplexInstanceNorm`, :class:`ComplexBatchNorm` or none."""
    check_choice(norm, 'norm', COMPLEX_NORMS)
    if norm == 'instance':
        return ComplexInstanceNorm(channels, streams)
    if norm == 'batch':
        return ComplexBatchNorm(channels, streams)
    return torch.nn.Identity()


def norm_repr(norm: Optional[str]) -> str:
    """The ``norm`` argument for a repr, where it is not the default."""
    return '' if norm == DEFAULT_COMPLEX_NORM else f', norm={norm!r}'


def apply_complex_norm(norm: torch.nn.Module, z: Tensor,
                       batch: Optional[Tensor] = None,
                       num_shapes: Optional[int] = None) -> Tensor:
    """``norm(z)``, with the shape of every point where :obj:`norm`
    normalises per shape."""
    if isinstance(norm, ComplexInstanceNorm):
        return norm(z, batch, num_shapes)
    return norm(z)


class HarmonicResNetBlock(torch.nn.Module):
    r"""A residual block of Harmonic Surface Networks: two harmonic
    convolutions with C-ReLU, and a skip connection (a
    :class:`ComplexLinear` without bias when the widths differ). It
    computes

    .. math::
        \mathbf{z}' = \sigma\Big(\mathrm{N}\big(
        \mathrm{conv}_2(\sigma(\mathrm{N}(\mathrm{conv}_1 \mathbf{z})))
        \big) + S\mathbf{z}\Big).

    Args:
        in_channels (int): Input channels per stream.
        out_channels (int): Output channels per stream.
        max_order (int, optional): Highest order of both convolutions.
            (default: :obj:`1`)
        rings (int, optional): Rings of the radial profiles.
            (default: :obj:`6`)
        prev_order (int, optional): Highest input order.
            (default: :obj:`1`)
        norm (str, optional): The normalisation after each convolution:
            :obj:`'instance'` (:class:`ComplexInstanceNorm`, statistics per
            shape: training and evaluation agree at any batch size),
            :obj:`'batch'` (:class:`ComplexBatchNorm`) or :obj:`None`.
            (default: :obj:`'instance'`)
        separate_streams (bool, optional): See :class:`HarmonicConv`.
            (default: :obj:`True`)

    Shapes:
        - **input:** complex :math:`(N, P + 1, C_{in})`, and the disc
          operator of the level (:class:`HarmonicOperator` built for
          :math:`P + 1 \to O + 1` and :math:`O + 1 \to O + 1` orders, or
          the per-edge data)
        - **output:** complex :math:`(N, O + 1, C_{out})`
    """
    def __init__(self, in_channels: int, out_channels: int,
                 max_order: int = 1, rings: int = 6, prev_order: int = 1,
                 norm: Optional[str] = DEFAULT_COMPLEX_NORM,
                 separate_streams: bool = True):
        super().__init__()
        for name, value, low in (('in_channels', in_channels, 1),
                                 ('out_channels', out_channels, 1),
                                 ('max_order', max_order, 0),
                                 ('prev_order', prev_order, 0)):
            check_positive_int(value, name, minimum=low)
        self.in_channels = in_channels
        self.out_channels = out_channels
        self.max_order = max_order
        self.prev_order = prev_order
        self.conv1 = HarmonicConv(in_channels, out_channels, max_order, rings,
                                  prev_order,
                                  separate_streams=separate_streams)
        self.conv2 = HarmonicConv(out_channels, out_channels, max_order,
                                  rings, max_order,
                                  separate_streams=separate_streams)
        self.act1 = ComplexReLU(out_channels)
        self.act2 = ComplexReLU(out_channels)
        streams = max_order + 1
        self.norm = norm
        self.norm1 = complex_norm(norm, out_channels, streams)
        self.norm2 = complex_norm(norm, out_channels, streams)
        self.skip = ComplexLinear(in_channels, out_channels, bias=False) \
            if in_channels != out_channels else torch.nn.Identity()

    def reset_parameters(self):
        for module in self.modules():
            if module is not self and hasattr(module, 'reset_parameters'):
                module.reset_parameters()

    def forward(self, z: Tensor, operators: dict,
                batch: Optional[Tensor] = None,
                num_shapes: Optional[int] = None) -> Tensor:
        r"""Applies the block to the complex stream features :obj:`z`.

        Args:
            z (torch.Tensor): Complex features :math:`(N, P + 1, C_{in})`.
            operators (dict): Maps ``(in_orders, out_orders)`` to the
                :class:`HarmonicOperator` of this level (see
                :func:`harmonic_operators`); it must hold the pairs
                :math:`(P + 1, O + 1)` and :math:`(O + 1, O + 1)`.
            batch (torch.Tensor, optional): The shape index of every point
                :math:`(N)` (PyG's ``batch`` on this level), which the
                instance normalisation needs; :obj:`None`: one shape.
                (default: :obj:`None`)
            num_shapes (int, optional): The number of shapes; computed from
                :obj:`batch` if not given. (default: :obj:`None`)

        Returns:
            torch.Tensor: Complex features :math:`(N, O + 1, C_{out})`.
        """
        p, o = self.prev_order + 1, self.max_order + 1
        missing = [pair for pair in ((p, o), (o, o))
                   if not isinstance(operators, dict) or pair not in operators]
        if missing:
            raise ValueError(f"'operators' must be a dict holding the "
                             f"HarmonicOperator of this level for the order "
                             f"pairs {missing}; build it with "
                             f"harmonic_operators(..., pairs={missing})")
        # Checked here so that the error names this block's input.
        check_rows(z, 'z', operators[(p, o)].num_nodes, "'operators'")
        h = apply_complex_norm(self.norm1, self.conv1(
            z, operator=operators[(p, o)]), batch, num_shapes)
        h = apply_complex_norm(self.norm2, self.conv2(
            self.act1(h), operator=operators[(o, o)]), batch, num_shapes)
        skip = z
        if p != o:  # streams the input lacks are 0; extra ones are dropped
            skip = torch.cat([z, z.new_zeros(z.size(0), max(0, o - p),
                                              z.size(2))], 1)[:, :o]
        return self.act2(h + self.skip(skip))

    def __repr__(self) -> str:
        return (f'{self.__class__.__name__}({self.in_channels}, '
                f'{self.out_channels}, max_order={self.max_order}, '
                f'prev_order={self.prev_order}' + norm_repr(self.norm)
                + ')')


def harmonic_operators(edge_index: Tensor, harmonic: Tensor,
                       transport: Tensor, num_nodes: int, pairs
                       ) -> dict:
    """The :class:`HarmonicOperator` of one level for every
    ``(in_orders, out_orders)`` pair that its layers use."""
    layout = harmonic_layout(edge_index, harmonic, num_nodes)
    return {pair: HarmonicOperator(edge_index, harmonic, transport,
                                   num_nodes, *pair, layout=layout)
            for pair in set(pairs)}


__all__ = ['HarmonicResNetBlock', 'harmonic_operators', 'complex_norm',
           'apply_complex_norm', 'COMPLEX_NORMS']
