from typing import Optional, Sequence

import torch
import torch.nn.functional as F
from torch import Tensor
from torch_geometric.data import Data

from tg_intrinsic.nn.harmonic_conv import HarmonicConv
from tg_intrinsic.nn.harmonic_resnet_block import (DEFAULT_COMPLEX_NORM,
                                                   HarmonicResNetBlock)
from tg_intrinsic.nn.models._hsn_base import (HSNBase, input_features,
                                              invariant, lift, prepare_levels)
from tg_intrinsic.pool import ParallelTransportPool, ParallelTransportUnpool


class HSNSegmentation(HSNBase):
    r"""Harmonic Surface Network for per-vertex segmentation, from the
    `"CNNs on Surfaces using Rotation-Equivariant Features"
    <https://doi.org/10.1145/3386569.3392437>`_ paper: a two-level U-ResNet
    of :class:`HarmonicResNetBlock` (two per level and in the decoder),
    parallel-transport pooling and unpooling, a skip connection by
    concatenation, and a last :class:`HarmonicConv` whose stream magnitudes
    are the (gauge-invariant) logits. It computes

    .. math::
        \hat{y}_i = \sum_M \big| \mathrm{conv}\big(\mathrm{dec}\big(
        [\mathbf{z}^{(0)} \,\|\, \mathrm{unpool}(\mathrm{enc}_1(
        \mathrm{pool}(\mathbf{z}^{(0)})))]\big)\big)_i^M \big| + \mathbf{b},
        \qquad \mathbf{z}^{(0)} = \mathrm{enc}_0(\mathbf{x}).

    Needs the same data as :class:`HSNClassification`.

    Args:
        in_channels (int): Input features per point (``data.x``, else
            ``data.pos``).
        num_classes (int): Number of part classes :math:`C`.
        channels (Sequence[int], optional): Features on levels 0 and 1.
            (default: :obj:`(16, 32)`)
        max_order (int, optional): Highest rotation order; :obj:`0` gives
            the one-stream ablation. (default: :obj:`1`)
        rings (int, optional): Rings of the radial profiles.
            (default: :obj:`6`)
        norm (str, optional): The blocks' normalisation, see
            :class:`HarmonicResNetBlock`: :obj:`'instance'` (per shape),
            :obj:`'batch'` or :obj:`None`. (default: :obj:`'instance'`)

    Shapes:
        - **input:** a (batched) :class:`~tg_intrinsic.data.IntrinsicData`
        - **output:** logits :math:`(N, C)`
    """
    def __init__(self, in_channels: int, num_classes: int,
                 channels: Sequence[int] = (16, 32), max_order: int = 1,
                 rings: int = 6, norm: Optional[str] = DEFAULT_COMPLEX_NORM):
        super().__init__(in_channels, num_classes, channels, max_order, rings,
                         norm)
        c0, c1 = self.channels
        p = max_order

        def blocks(c_in, c_out, first_order=p):
            return torch.nn.ModuleList([
                HarmonicResNetBlock(c_in, c_out, p, rings, first_order,
                                    norm=norm),
                HarmonicResNetBlock(c_out, c_out, p, rings, p, norm=norm)])

        self.enc0 = blocks(c0, c0, first_order=0)
        self.enc1 = blocks(c0, c1)
        self.dec0 = blocks(c0 + c1, c0)
        self.pool = ParallelTransportPool()
        self.unpool = ParallelTransportUnpool()
        self.conv = HarmonicConv(c0, num_classes, p, rings, prev_order=p,
                                 offset=False)

    def reset_parameters(self):
        super().reset_parameters()
        for module in [self.conv, *self.enc0, *self.enc1, *self.dec0]:
            module.reset_parameters()

    def forward(self, data: Data) -> Tensor:
        r"""Classifies every vertex of a (batched) data object.

        Args:
            data (torch_geometric.data.Data): The shapes, as for
                :class:`HSNClassification`: ``x`` :math:`(N, C_{in})` (else
                ``pos``), optionally ``batch`` :math:`(N)`, and the disc
                graphs of levels 0 and 1 and the pooling between them.

        Returns:
            torch.Tensor: Logits :math:`(N, C)`, one row per vertex.
        """
        x = input_features(data, self.in_channels)
        o = self.max_order + 1
        (fine, level1), shapes = prepare_levels(data, x, [[(1, o), (o, o)],
                                                          [(o, o)]])
        z = lift(F.relu(self.lin(x)))
        for block in self.enc0:
            z = block(z, fine.operators, fine.batch, shapes)
        coarse = self.pool(z, level1.cluster, level1.angle, level1.size)
        for block in self.enc1:
            coarse = block(coarse, level1.operators, level1.batch, shapes)
        z = torch.cat([z, self.unpool(coarse, level1.cluster, level1.angle)],
                      dim=2)
        for block in self.dec0:
            z = block(z, fine.operators, fine.batch, shapes)
        z = self.conv(z, operator=fine.operators[(o, o)])
        return invariant(z) + self.bias
