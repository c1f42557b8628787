from typing import List, Optional, Tuple

import torch
from torch import Tensor
from torch_geometric.data import Data
from torch_geometric.utils import scatter

from tg_intrinsic.geometry.checks import check_positive_int, check_tensor
from tg_intrinsic.geometry.pointcloud.operators import SurfaceOperators
from tg_intrinsic.nn.delta_conv import DeltaConv, scalar_mlp
from tg_intrinsic.nn.models._deltanet_base import category_one_hot
from tg_intrinsic.nn.vector_linear import VectorLinear
from tg_intrinsic.pool.gravo_pool import GravoPool
from tg_intrinsic.pool.gravo_unpool import GravoUnpool
from tg_intrinsic.pool.tangent_vector_pool import TangentVectorPool
from tg_intrinsic.surface_attributes import check_operator_graph
from tg_intrinsic.transforms.pooling_levels import METHODS

NUM_SCALES = 4
VECTOR_SCALES = 3
LEVEL_KEYS = ('pos', 'edge_index', 'grad_weight', 'div_weight',
              'pool_edge_index', 'pool_weight', 'pool_transport')


class _Level:
    """The graph, operators and pooling edges of one level of a batch."""
    def __init__(self, data: Data, level: int):
        suffix = '' if level == 0 else f'_{level}'
        self.edge_index = data[f'edge_index{suffix}']
        pos = data[f'pos{suffix}']
        self.num_nodes = pos.size(0)
        self.operators = SurfaceOperators(
            self.edge_index, data[f'grad_weight{suffix}'].to(pos.dtype),
            data[f'div_weight{suffix}'].to(pos.dtype), self.num_nodes)
        if level > 0:  # pooling edges from the level above (finer)
            self.pool_index = data[f'pool_edge_index{suffix}']
            self.pool_weight = data[f'pool_weight{suffix}'].to(pos.dtype)
            self.pool_transport = data[f'pool_transport{suffix}']


class _ResNetBlock(torch.nn.Module):
    """KPFCNN's bottleneck ResNet block with a DeltaConv in the middle:
    unary ``C_in -> C_out / 4``, DeltaConv, unary ``C_out / 4 -> C_out``,
    plus a (linear) shortcut; the vector stream likewise with
    :class:`VectorLinear` maps."""
    def __init__(self, in_channels: int, out_channels: int,
                 vector_in: int, vector: bool):
        super().__init__()
        mid = max(out_channels // 4, 8)
        self.vector = vector
        self.down = scalar_mlp([in_channels, mid])
        self.conv = DeltaConv(mid, mid, vector=vector, vector_input=vector)
        self.up = torch.nn.Sequential(
            torch.nn.Linear(mid, out_channels, bias=False),
            torch.nn.BatchNorm1d(out_channels))
        self.shortcut = torch.nn.Identity() if in_channels == out_channels \
            else torch.nn.Sequential(
                torch.nn.Linear(in_channels, out_channels, bias=False),
                torch.nn.BatchNorm1d(out_channels))
        self.act = torch.nn.LeakyReLU(0.2)
        if vector:
            self.v_down = VectorLinear(vector_in, mid)
            self.v_up = VectorLinear(mid, out_channels)
            self.v_shortcut = torch.nn.Identity() \
                if vector_in == out_channels \
                else VectorLinear(vector_in, out_channels)

    def reset_parameters(self):
        for module in self.modules():
            if module is not self and hasattr(module, 'reset_parameters'):
                module.reset_parameters()

    def forward(self, x: Tensor, v: Optional[Tensor], level: _Level
                ) -> Tuple[Tensor, Optional[Tensor]]:
        h, hv = self.down(x), None
        if self.vector:
            hv = self.v_down(v)
        h, hv = self.conv(h, hv, level.edge_index, level.operators)
        x = self.act(self.up(h) + self.shortcut(x))
        if self.vector:
            v = self.v_up(hv) + self.v_shortcut(v)
        return x, (v if self.vector else None)


class DeltaUResNet(torch.nn.Module):
    r"""The Delta-U-ResNet for per-point segmentation from the DeltaConv
    thesis by Wiersma: the `"DeltaConv" <https://arxiv.org/abs/2111.08799>`_
    operators in the U-ResNet of KPFCNN. The network is in appendix A.2 of
    the thesis; KPFCNN is by Thomas et al. (ICCV 2019).

    Four encoder scales with two bottleneck ResNet blocks each, whose
    middle layer is a :class:`DeltaConv`; every scale keeps a quarter of
    the points of the previous one (the levels of
    :class:`~tg_intrinsic.transforms.PoolingLevels`) and doubles the
    features (:obj:`channels`, :math:`2 \cdot` :obj:`channels`, ...). The
    first three scales carry a vector stream. Pooling takes the maximum of
    the scalars over a coarse point's cluster and the mean of the vectors
    parallel transported into its frame (:class:`TangentVectorPool`); with
    :obj:`pooling='gravo'`, a Gravo MG hierarchy's normalised restriction
    (:class:`GravoPool`) for both. The decoder upsamples (nearest point,
    or the Gravo prolongation), concatenates the encoder's features of the
    same scale and applies a unary layer, as KPFCNN; two more ResNet
    blocks of :obj:`final_channels` (whose vector stream starts from the
    first scale's vectors) and an optional object category embedding lead
    to the per-point head:

    .. math::
        \mathbf{x}^{(s)} = \mathrm{Res}^2\big(\mathrm{pool}(
        \mathbf{x}^{(s-1)})\big), \qquad
        \mathbf{y}^{(s-1)} = \mathrm{MLP}\big([\mathrm{up}(
        \mathbf{y}^{(s)}) \,\|\, \mathbf{x}^{(s-1)}]\big), \qquad
        \hat{y}_i = \mathrm{MLP}\big(\mathrm{Res}^2(\mathbf{y}^{(0)})_i
        \,\|\, \mathbf{c}\big).

    Scalar outputs do not depend on the choice of tangent frames, so the
    logits are invariant to rotations of the input when the input
    features are.

    Args:
        in_channels (int): Input scalars per point (``data.x``, else
            ``data.pos``).
        num_classes (int): Number of part classes.
        channels (int, optional): Features of the first scale.
            (default: :obj:`64`)
        final_channels (int, optional): Features of the two blocks after
            the decoder. (default: :obj:`128`)
        pooling (str, optional): :obj:`'fps'` or :obj:`'gravo'`; must be
            the method the data's levels were built with.
            (default: :obj:`'fps'`)
        num_categories (int, optional): If set, ``data.category`` (one-hot
            :math:`(B, \text{num\_categories})` or indices :math:`(B)`) is
            embedded and appended. (default: :obj:`None`)
        dropout (float, optional): Dropout in the head.
            (default: :obj:`0.5`)

    Shapes:
        - **input:** a (batched) :class:`~tg_intrinsic.data.IntrinsicData`
          with the levels of
          :class:`~tg_intrinsic.transforms.PoolingLevels` (3 levels)
        - **output:** logits :math:`(N, C)`
    """
    def __init__(self, in_channels: int, num_classes: int,
                 channels: int = 64, final_channels: int = 128,
                 pooling: str = 'fps',
                 num_categories: Optional[int] = None,
                 dropout: float = 0.5):
        super().__init__()
        check_positive_int(in_channels, 'in_channels')
        check_positive_int(num_classes, 'num_classes')
        check_positive_int(channels, 'channels')
        check_positive_int(final_channels, 'final_channels')
        if pooling not in METHODS:
            raise ValueError(f"'pooling' must be one of {METHODS}, got "
                             f"{pooling!r}")
        if num_categories is not None:
            check_positive_int(num_categories, 'num_categories')
        self.in_channels = in_channels
        self.num_classes = num_classes
        self.channels = channels
        self.final_channels = final_channels
        self.pooling = pooling
        self.num_categories = num_categories
        widths = [channels * 2 ** s for s in range(NUM_SCALES)]
        self.stem = DeltaConv(in_channels, widths[0], centralized=True)
        self.encoder = torch.nn.ModuleList()
        for s, width in enumerate(widths):
            previous = widths[max(s - 1, 0)]
            vector = s < VECTOR_SCALES
            self.encoder.append(torch.nn.ModuleList([
                _ResNetBlock(previous, width, previous, vector),
                _ResNetBlock(width, width, width, vector)]))
        self.decoder = torch.nn.ModuleList([
            scalar_mlp([widths[s] + widths[s - 1], widths[s - 1]])
            for s in range(1, NUM_SCALES)])
        self.final = torch.nn.ModuleList([
            _ResNetBlock(widths[0], final_channels, widths[0], True),
            _ResNetBlock(final_channels, final_channels, final_channels,
                         True)])
        extra = 0
        self.category = None
        if num_categories is not None:
            self.category = scalar_mlp([num_categories, 64])
            extra = 64
        self.head = torch.nn.Sequential(
            scalar_mlp([final_channels + extra, final_channels]),
            torch.nn.Dropout(dropout),
            torch.nn.Linear(final_channels, num_classes))
        self.vector_pool = TangentVectorPool()
        self.gravo_pool = GravoPool()
        self.unpool = GravoUnpool()

    def reset_parameters(self):
        for module in self.modules():
            if module is not self and hasattr(module, 'reset_parameters'):
                module.reset_parameters()

    def forward(self, data: Data) -> Tensor:
        r"""Classifies every point of a (batched) point cloud.

        Args:
            data (torch_geometric.data.Data): The points, with ``pos``
                :math:`(N, 3)`, optionally ``x`` :math:`(N, C_{in})` (the
                input scalars, ``pos`` otherwise) and ``batch`` :math:`(N)`,
                and the three levels of
                :class:`~tg_intrinsic.transforms.PoolingLevels` built with
                :obj:`method=pooling` (their DeltaConv operators and pooling
                edges); with :obj:`num_categories`, also ``category``
                (one-hot :math:`(B, \text{num\_categories})` or indices
                :math:`(B)`).

        Returns:
            torch.Tensor: Logits :math:`(N, C)`, one row per point.
        """
        x = self._input(data)
        levels = self._levels(data)
        v = levels[0].operators.grad(x)
        x, v = self.stem(x, v, levels[0].edge_index, levels[0].operators)
        skips: List[Tuple[Tensor, Optional[Tensor]]] = []
        for s, blocks in enumerate(self.encoder):
            if s > 0:
                x, v = self._pool(x, v, levels[s], s < VECTOR_SCALES)
            for block in blocks:
                x, v = block(x, v, levels[s])
            skips.append((x, v))
        for s in range(NUM_SCALES - 1, 0, -1):
            level = levels[s]
            up = self.unpool(x, level.pool_index, level.pool_weight,
                             levels[s - 1].num_nodes)
            x = self.decoder[s - 1](torch.cat([up, skips[s - 1][0]], 1))
        v = skips[0][1]
        for block in self.final:
            x, v = block(x, v, levels[0])
        if self.category is not None:
            batch = getattr(data, 'batch', None)
            if batch is None:
                batch = torch.zeros(x.size(0), dtype=torch.long,
                                    device=x.device)
            size = int(batch.max()) + 1
            category = category_one_hot(getattr(data, 'category', None),
                                        self.num_categories, size, x)
            x = torch.cat([x, self.category(category.to(x.dtype))[batch]],
                          1)
        return self.head(x)

    def _pool(self, x: Tensor, v: Optional[Tensor], level: _Level,
              vector: bool) -> Tuple[Tensor, Optional[Tensor]]:
        fine, coarse = level.pool_index
        if self.pooling == 'gravo':
            x = self.gravo_pool(x, level.pool_index, level.pool_weight,
                                level.num_nodes)
        else:
            x = scatter(x[fine], coarse, dim=0, dim_size=level.num_nodes,
                        reduce='max')
        if vector:
            v = self.vector_pool(v, level.pool_index, level.pool_weight,
                                 level.pool_transport, level.num_nodes)
        return x, (v if vector else None)

    def _input(self, data: Data) -> Tensor:
        x = getattr(data, 'x', None)
        x = data.pos if x is None else x
        x = check_tensor(x, 'data.x')
        if x.dim() != 2 or x.size(-1) != self.in_channels:
            raise ValueError(f"the model expects {self.in_channels} input "
                             f"channels per point but data.x (or data.pos) "
                             f"has shape {list(x.shape)}")
        return x

    def _levels(self, data: Data) -> List[_Level]:
        record = getattr(data, 'pooling_levels', None)
        missing = [f'{key}_{level}' for level in range(1, NUM_SCALES)
                   for key in LEVEL_KEYS if f'{key}_{level}' not in data]
        if record is None or missing or 'grad_weight' not in data:
            raise ValueError(
                f"DeltaUResNet needs {NUM_SCALES - 1} pooling levels with "
                f"DeltaConv operators (missing: "
                f"{', '.join(missing[:3]) or 'pooling_levels'}); apply "
                f"tg_intrinsic.transforms.PoolingLevels(num_levels="
                f"{NUM_SCALES - 1}, method={self.pooling!r}) to every "
                f"example (e.g. as the data set's pre_transform)")
        record = record.reshape(-1, 4)
        methods = {METHODS[int(m)] for m in record[:, 3].tolist()}
        if methods != {self.pooling}:
            raise ValueError(f"the data's levels were built with method "
                             f"{sorted(methods)}, but this model pools with "
                             f"{self.pooling!r}; build them with "
                             f"PoolingLevels(method={self.pooling!r})")
        check_operator_graph(data, 'grad_weight, div_weight',
                             'PoolingLevels')
        return [_Level(data, level) for level in range(NUM_SCALES)]

    def __repr__(self) -> str:
        return (f'{self.__class__.__name__}({self.in_channels}, '
                f'{self.num_classes}, channels={self.channels}, '
                f'final_channels={self.final_channels}, '
                f'pooling={self.pooling!r}, '
                f'num_categories={self.num_categories})')
