from typing import List, Optional, Sequence

import torch
from torch import Tensor
from torch_geometric.data import Data
from torch_geometric.nn import global_mean_pool

from tg_intrinsic.geometry.checks import (check_channels, check_choice,
                                          check_positive_int)
from tg_intrinsic.nn.complex_relu import ComplexReLU
from tg_intrinsic.nn.harmonic_conv import HarmonicConv
from tg_intrinsic.nn.harmonic_resnet_block import (COMPLEX_NORMS,
                                                   apply_complex_norm,
                                                   complex_norm)
from tg_intrinsic.nn.models._hsn_base import (input_features, invariant,
                                              prepare_levels)
from tg_intrinsic.pool import ParallelTransportPool


class HSNConvClassification(torch.nn.Module):
    r"""A plain (non-residual) Harmonic Surface Network classifier over any
    number of pooling levels, from the `"CNNs on Surfaces using
    Rotation-Equivariant Features" <https://doi.org/10.1145/3386569.3392437>`_
    paper: the network of its rotated-MNIST-on-a-sphere experiment,
    Conv8, Conv8, Pool, Conv16, Conv16, Pool, Conv32, Conv32, Conv10, with
    the default :obj:`channels`. Level :math:`l` runs :obj:`convs_per_level`
    :class:`HarmonicConv` layers of ``channels[l]`` features, each followed
    by a normalisation (:class:`ComplexBatchNorm` by default) and
    :class:`ComplexReLU`, then
    parallel-transport pooling to level :math:`l + 1`; a last
    :class:`HarmonicConv` to :math:`C` channels on the coarsest level, the
    magnitudes of its streams (gauge invariant) and a global mean give the
    logits:

    .. math::
        \hat{y} = \frac{1}{n_L} \sum_{i} \sum_{M} \big|
        \mathrm{conv}(\mathbf{z}^{(L)})_i^M \big| + \mathbf{b},
        \qquad \mathbf{z}^{(l + 1)} = \mathrm{pool}\big(
        \sigma(\mathrm{N}(\mathrm{conv}(\cdots\sigma(\mathrm{N}(
        \mathrm{conv}(\mathbf{z}^{(l)}))))))\big).

    With :obj:`max_order=0` (one stream) every filter is isotropic, so the
    network is rotation invariant but blind to directions; with
    :obj:`max_order=1` (two streams) it sees directions and stays invariant
    through the equivariant order-1 stream.

    The data must carry the disc graphs of levels
    :math:`0 .. L` (``edge_index``, ``harmonic``, ``transport`` and their
    ``_l`` versions) and the pooling (``cluster_l``, ``pool_transport_l``),
    as written by :class:`~tg_intrinsic.transforms.LogMap`,
    :class:`~tg_intrinsic.transforms.MultiscaleSupports` and
    :class:`~tg_intrinsic.transforms.HarmonicPrecompute` (see
    :class:`~tg_intrinsic.datasets.SphereDigits`).

    Args:
        in_channels (int): Input features per point (``data.x``, else
            ``data.pos``).
        num_classes (int): Number of classes :math:`C`.
        channels (Sequence[int], optional): Features on levels
            :math:`0 .. L`. (default: :obj:`(8, 16, 32)`)
        convs_per_level (int, optional): Convolutions per level.
            (default: :obj:`2`)
        max_order (int, optional): Highest rotation order; :obj:`0` gives
            the one-stream ablation. (default: :obj:`1`)
        rings (int, optional): Rings of the radial profiles (as
            precomputed). (default: :obj:`6`)
        norm (str, optional): The normalisation after each convolution,
            see :class:`HarmonicResNetBlock`: :obj:`'batch'`,
            :obj:`'instance'` (per example) or :obj:`None`. Unlike the
            mesh models, whose protocols train one mesh per batch, this
            network classifies many signals on one shared mesh in large
            batches, where batch norm works and per-example normalisation
            measured 2-18 points worse on ``benchmarks/sphere_digits.py``.
            (default: :obj:`'batch'`)

    Shapes:
        - **input:** a (batched) :class:`~tg_intrinsic.data.IntrinsicData`
        - **output:** logits :math:`(B, C)`
    """
    def __init__(self, in_channels: int, num_classes: int,
                 channels: Sequence[int] = (8, 16, 32),
                 convs_per_level: int = 2, max_order: int = 1,
                 rings: int = 6, norm: Optional[str] = 'batch'):
        super().__init__()
        self.in_channels = check_positive_int(in_channels, 'in_channels')
        self.num_classes = check_positive_int(num_classes, 'num_classes')
        self.channels = check_channels(channels, 'channels')
        self.convs_per_level = check_positive_int(convs_per_level,
                                                  'convs_per_level')
        self.max_order = check_positive_int(max_order, 'max_order', 0)
        self.rings = check_positive_int(rings, 'rings')
        self.norm = check_choice(norm, 'norm', COMPLEX_NORMS)
        self.convs = torch.nn.ModuleList()
        self.norms = torch.nn.ModuleList()
        self.acts = torch.nn.ModuleList()
        width, order = self.in_channels, 0
        for c in self.channels:
            for _ in range(self.convs_per_level):
                self.convs.append(HarmonicConv(width, c, max_order, rings,
                                               prev_order=order))
                self.norms.append(complex_norm(norm, c, max_order + 1))
                self.acts.append(ComplexReLU(c))
                width, order = c, max_order
        self.pool = ParallelTransportPool()
        self.out = HarmonicConv(width, num_classes, max_order, rings,
                                prev_order=max_order, offset=False)
        self.bias = torch.nn.Parameter(torch.zeros(num_classes))

    def reset_parameters(self):
        for module in (*self.convs, *self.norms, *self.acts, self.out):
            if hasattr(module, 'reset_parameters'):
                module.reset_parameters()
        torch.nn.init.zeros_(self.bias)

    def operators(self, data: Data) -> List[dict]:
        """The harmonic operators of every level of ``data``, as
        :meth:`forward` builds them; pass them to :meth:`forward` to reuse
        them for batches that share their meshes and precomputation (only
        ``x`` and ``y`` differ)."""
        levels, _ = prepare_levels(data, data.pos, self._pairs())
        return [level.operators for level in levels]

    def _pairs(self) -> List[List[tuple]]:
        o = self.max_order + 1
        return [[(1 if level == 0 else o, o), (o, o)]
                for level in range(len(self.channels))]

    def forward(self, data: Data,
                operators: Optional[List[dict]] = None) -> Tensor:
        r"""Classifies every example of a (batched) data object.

        Args:
            data (torch_geometric.data.Data): The examples, with ``x``
                :math:`(N, C_{in})` (else ``pos``), optionally ``batch``
                :math:`(N)`, and the disc graphs of levels :math:`0 .. L`
                and the pooling between them (see above).
            operators (List[dict], optional): The harmonic operators of
                every level, from :meth:`operators`, for batches that share
                their meshes and precomputation; :obj:`None` builds them
                from :obj:`data`. (default: :obj:`None`)

        Returns:
            torch.Tensor: Logits :math:`(B, C)`, one row per example.
        """
        z = input_features(data, self.in_channels)
        o = self.max_order + 1
        levels, shapes = prepare_levels(data, z, self._pairs(), operators)
        layer = 0
        for level, here in enumerate(levels):
            if level > 0:
                z = self.pool(z, here.cluster, here.angle, here.size)
            for k in range(self.convs_per_level):
                pair = (1 if level == 0 else o, o) if k == 0 else (o, o)
                z = self.convs[layer](z, operator=here.operators[pair])
                z = self.acts[layer](apply_complex_norm(
                    self.norms[layer], z, here.batch, shapes))
                layer += 1
        z = self.out(z, operator=levels[-1].operators[(o, o)])
        return global_mean_pool(invariant(z), levels[-1].batch, shapes) \
            + self.bias

    def __repr__(self) -> str:
        return (f'{self.__class__.__name__}({self.in_channels}, '
                f'{self.num_classes}, channels={self.channels}, '
                f'convs_per_level={self.convs_per_level}, '
                f'max_order={self.max_order}, rings={self.rings}'
                + (f', norm={self.norm!r}' if self.norm != 'batch' else '')
                + ')')
