from typing import Optional, Sequence

import torch.nn.functional as F
from torch import Tensor
from torch_geometric.data import Data
from torch_geometric.nn import global_mean_pool

from tg_intrinsic.nn.harmonic_conv import HarmonicConv
from tg_intrinsic.nn.harmonic_resnet_block import (DEFAULT_COMPLEX_NORM,
                                                   HarmonicResNetBlock)
from tg_intrinsic.nn.models._hsn_base import (HSNBase, input_features,
                                              invariant, lift, prepare_levels)
from tg_intrinsic.pool import ParallelTransportPool


class HSNClassification(HSNBase):
    r"""Harmonic Surface Network for shape classification, from the `"CNNs
    on Surfaces using Rotation-Equivariant Features"
    <https://doi.org/10.1145/3386569.3392437>`_ paper: the encoder half of
    the U-ResNet. A linear lift of the input to stream 0, a
    :class:`HarmonicResNetBlock` on level 0, parallel-transport pooling, a
    block on level 1, a last :class:`HarmonicConv` to :math:`C` channels,
    the magnitudes of its streams (gauge invariant) and a global mean:

    .. math::
        \hat{y} = \frac{1}{n_1} \sum_{i} \sum_{M} \big|
        \mathrm{conv}(\mathrm{block}_1(\mathrm{pool}(
        \mathrm{block}_0(\mathbf{x}))))_i^M \big| + \mathbf{b}.

    The data must carry the disc graphs of levels 0 and 1 (``edge_index``,
    ``harmonic``, ``transport`` and their ``_1`` versions) and the pooling
    (``cluster_1``, ``pool_transport_1``), as written by
    :class:`~tg_intrinsic.transforms.LogMap`,
    :class:`~tg_intrinsic.transforms.ParallelTransport`,
    :class:`~tg_intrinsic.transforms.MultiscaleSupports` and
    :class:`~tg_intrinsic.transforms.HarmonicPrecompute`.

    Args:
        in_channels (int): Input features per point (``data.x``, else
            ``data.pos``).
        num_classes (int): Number of classes :math:`C`.
        channels (Sequence[int], optional): Features on levels 0 and 1.
            (default: :obj:`(16, 32)`)
        max_order (int, optional): Highest rotation order; :obj:`0` gives
            the one-stream ablation. (default: :obj:`1`)
        rings (int, optional): Rings of the radial profiles (as
            precomputed). (default: :obj:`6`)
        norm (str, optional): The blocks' normalisation, see
            :class:`HarmonicResNetBlock`: :obj:`'instance'` (per shape, so
            that :meth:`eval` scores what training scores), :obj:`'batch'`
            or :obj:`None`. (default: :obj:`'instance'`)

    Shapes:
        - **input:** a (batched) :class:`~tg_intrinsic.data.IntrinsicData`
        - **output:** logits :math:`(B, C)`
    """
    def __init__(self, in_channels: int, num_classes: int,
                 channels: Sequence[int] = (16, 32), max_order: int = 1,
                 rings: int = 6, norm: Optional[str] = DEFAULT_COMPLEX_NORM):
        super().__init__(in_channels, num_classes, channels, max_order, rings,
                         norm)
        c0, c1 = self.channels
        self.block0 = HarmonicResNetBlock(c0, c0, max_order, rings,
                                          prev_order=0, norm=norm)
        self.pool = ParallelTransportPool()
        self.block1 = HarmonicResNetBlock(c0, c1, max_order, rings,
                                          prev_order=max_order, norm=norm)
        self.conv = HarmonicConv(c1, num_classes, max_order, rings,
                                 prev_order=max_order, offset=False)

    def reset_parameters(self):
        super().reset_parameters()
        for module in (self.block0, self.block1, self.conv):
            module.reset_parameters()

    def forward(self, data: Data) -> Tensor:
        r"""Classifies every shape of a (batched) data object.

        Args:
            data (torch_geometric.data.Data): The shapes, with ``x``
                :math:`(N, C_{in})` (else ``pos``), optionally ``batch``
                :math:`(N)`, and the disc graphs of levels 0 and 1 and the
                pooling between them (see above).

        Returns:
            torch.Tensor: Logits :math:`(B, C)`, one row per shape.
        """
        x = input_features(data, self.in_channels)
        o = self.max_order + 1
        (fine, coarse), shapes = prepare_levels(data, x, [[(1, o), (o, o)],
                                                          [(o, o)]])
        z = self.block0(lift(F.relu(self.lin(x))), fine.operators,
                        fine.batch, shapes)
        z = self.pool(z, coarse.cluster, coarse.angle, coarse.size)
        z = self.block1(z, coarse.operators, coarse.batch, shapes)
        z = self.conv(z, operator=coarse.operators[(o, o)])
        return global_mean_pool(invariant(z), coarse.batch, shapes) \
            + self.bias
