from typing import Optional, Sequence

import torch
import torch.nn.functional as F
from torch import Tensor
from torch_geometric.data import Data

from tg_intrinsic.geometry.checks import check_channels, check_positive_int
from tg_intrinsic.nn.harmonic_conv import HarmonicConv
from tg_intrinsic.geometry.checks import check_choice
from tg_intrinsic.nn.harmonic_resnet_block import (COMPLEX_NORMS,
                                                   DEFAULT_COMPLEX_NORM,
                                                   HarmonicResNetBlock,
                                                   norm_repr)
from tg_intrinsic.nn.models._hsn_base import (input_features, invariant,
                                              lift, prepare_levels)
from tg_intrinsic.pool import ParallelTransportPool, ParallelTransportUnpool


class HSNUResNet(torch.nn.Module):
    r"""The U-ResNet of Harmonic Surface Networks, from the `"CNNs on
    Surfaces using Rotation-Equivariant Features"
    <https://doi.org/10.1145/3386569.3392437>`_ paper: stacks of
    :class:`HarmonicResNetBlock` in a U-Net with parallel-transport
    pooling and unpooling and skip connections by concatenation. It is the
    paper's segmentation and correspondence network (Fig. 2.6 of the
    thesis).

    With :math:`L` levels (``len(channels)``), an encoder stack runs on
    every level :math:`0, \dots, L - 1` (pooling between them), one more
    stack on the coarsest level, and a decoder stack on every level
    :math:`L - 2, \dots, 0` after unpooling and concatenation with the
    encoder's features of that level,

    .. math::
        \mathbf{d}_l = \mathrm{dec}_l\big([\mathbf{e}_l \,\|\,
        \mathrm{unpool}(\mathbf{d}_{l + 1})]\big), \qquad
        \mathbf{d}_{L - 1} = \mathrm{mid}(\mathbf{e}_{L - 1}), \qquad
        \mathbf{e}_l = \mathrm{enc}_l(\mathrm{pool}(\mathbf{e}_{l - 1})),

    so the default two levels give the paper's four stacks of two blocks
    (16 and 32 features, rotation orders 0 and 1, as in the released
    code); ``channels=(16, 32, 64)`` gives the deeper three-level net.
    A last :class:`HarmonicConv` maps :math:`\mathbf{d}_0` to
    :math:`C` channels whose stream magnitudes (gauge invariant) are the
    per-vertex outputs, :math:`\hat{y}_i = \sum_M |\mathrm{conv}
    (\mathbf{d}_0)_i^M| + \mathbf{b}`; with ``out_channels=None`` the
    network returns the invariant features :math:`\sum_M |\mathbf{d}_{0,
    i}^M|` instead (for a head such as :class:`HSNCorrespondence`).

    Needs the disc graphs and harmonic terms of every level and the
    pooling between them (``edge_index``, ``harmonic``, ``transport``,
    their ``_l`` versions, ``cluster_l``, ``pool_transport_l``), as
    written by :class:`~tg_intrinsic.transforms.LogMap`,
    :class:`~tg_intrinsic.transforms.ParallelTransport`,
    :class:`~tg_intrinsic.transforms.MultiscaleSupports` (one ratio and
    radius per level after the first) and
    :class:`~tg_intrinsic.transforms.HarmonicPrecompute`.

    Args:
        in_channels (int): Input features per point (``data.x``, else
            ``data.pos``).
        out_channels (int, optional): Output channels :math:`C` per vertex,
            or :obj:`None` for the invariant features of the last stack.
            (default: :obj:`None`)
        channels (Sequence[int], optional): Features on levels
            :math:`0, \dots, L - 1` (at least two levels).
            (default: :obj:`(16, 32)`)
        max_order (int, optional): Highest rotation order; :obj:`0` gives
            the one-stream ablation. (default: :obj:`1`)
        rings (int, optional): Rings of the radial profiles (as
            precomputed). (default: :obj:`6`)
        blocks (int, optional): ResNet blocks per stack.
            (default: :obj:`2`)
        norm (str, optional): The blocks' normalisation, see
            :class:`HarmonicResNetBlock`: :obj:`'instance'` (per shape),
            :obj:`'batch'` or :obj:`None`. (default: :obj:`'instance'`)

    Shapes:
        - **input:** a (batched) :class:`~tg_intrinsic.data.IntrinsicData`
        - **output:** :math:`(N, C)`, or :math:`(N, \text{channels}[0])`
          with ``out_channels=None``
    """
    def __init__(self, in_channels: int, out_channels: Optional[int] = None,
                 channels: Sequence[int] = (16, 32), max_order: int = 1,
                 rings: int = 6, blocks: int = 2,
                 norm: Optional[str] = DEFAULT_COMPLEX_NORM):
        super().__init__()
        self.in_channels = check_positive_int(in_channels, 'in_channels')
        self.out_channels = None if out_channels is None else \
            check_positive_int(out_channels, 'out_channels')
        self.channels = check_channels(channels, 'channels', min_length=2)
        self.max_order = check_positive_int(max_order, 'max_order',
                                            minimum=0)
        self.rings = check_positive_int(rings, 'rings')
        self.blocks = check_positive_int(blocks, 'blocks')
        self.norm = check_choice(norm, 'norm', COMPLEX_NORMS)
        c, p = self.channels, self.max_order

        def stack(c_in, c_out, first_order=p):
            return torch.nn.ModuleList([
                HarmonicResNetBlock(c_in if b == 0 else c_out, c_out, p,
                                    rings, prev_order=first_order if b == 0
                                    else p, norm=norm)
                for b in range(blocks)])

        self.lin = torch.nn.Linear(in_channels, c[0])
        self.enc = torch.nn.ModuleList(
            [stack(c[0], c[0], first_order=0)]
            + [stack(c[l - 1], c[l]) for l in range(1, len(c))])
        self.mid = stack(c[-1], c[-1])
        # dec[l] runs on level l, for l = 0 .. L - 2
        self.dec = torch.nn.ModuleList(
            [stack(c[l] + c[l + 1], c[l]) for l in range(len(c) - 1)])
        self.pool = ParallelTransportPool()
        self.unpool = ParallelTransportUnpool()
        if self.out_channels is None:
            self.conv, self.bias = None, None
        else:
            self.conv = HarmonicConv(c[0], self.out_channels, p, rings,
                                     prev_order=p, offset=False)
            self.bias = torch.nn.Parameter(torch.zeros(self.out_channels))

    @property
    def num_levels(self) -> int:
        return len(self.channels)

    def reset_parameters(self):
        self.lin.reset_parameters()
        for module in (*self.enc, self.mid, *self.dec):
            for block in module:
                block.reset_parameters()
        if self.conv is not None:
            self.conv.reset_parameters()
            torch.nn.init.zeros_(self.bias)

    def forward(self, data: Data) -> Tensor:
        r"""Computes the per-vertex outputs of a (batched) data object.

        Args:
            data (torch_geometric.data.Data): The shapes, with ``x``
                :math:`(N, C_{in})` (else ``pos``), optionally ``batch``
                :math:`(N)`, and the disc graphs of levels
                :math:`0, \dots, L - 1` and the pooling between them (see
                above).

        Returns:
            torch.Tensor: Outputs :math:`(N, C)`, or invariant features
            :math:`(N, \text{channels}[0])` with ``out_channels=None``.
        """
        x = input_features(data, self.in_channels)
        o = self.max_order + 1
        levels, shapes = prepare_levels(
            data, x, [[(1, o), (o, o)]] + [[(o, o)]] * (self.num_levels - 1))
        z = lift(F.relu(self.lin(x)))
        skips = []
        for level, stack in enumerate(self.enc):
            here = levels[level]
            if level > 0:
                z = self.pool(z, here.cluster, here.angle, here.size)
            for block in stack:
                z = block(z, here.operators, here.batch, shapes)
            skips.append(z)
        for block in self.mid:
            z = block(z, levels[-1].operators, levels[-1].batch, shapes)
        for level in range(self.num_levels - 2, -1, -1):
            below, here = levels[level + 1], levels[level]
            z = torch.cat([skips[level],
                           self.unpool(z, below.cluster, below.angle)], dim=2)
            for block in self.dec[level]:
                z = block(z, here.operators, here.batch, shapes)
        if self.conv is None:
            return invariant(z)
        z = self.conv(z, operator=levels[0].operators[(o, o)])
        return invariant(z) + self.bias

    def __repr__(self) -> str:
        return (f'{self.__class__.__name__}({self.in_channels}, '
                f'{self.out_channels}, channels={self.channels}, '
                f'max_order={self.max_order}, rings={self.rings}, '
                f'blocks={self.blocks}' + norm_repr(self.norm) + ')')
