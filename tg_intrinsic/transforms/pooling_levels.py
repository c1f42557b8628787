import math

import torch
from torch import Tensor
from torch_geometric.data import Data
from torch_geometric.data.datapipes import functional_transform

from tg_intrinsic.data import IntrinsicData
from tg_intrinsic.geometry import fps, knn, log_map
from tg_intrinsic.geometry.checks import (check_points,
                                          check_positive_float,
                                          check_positive_int)
from tg_intrinsic.geometry.pointcloud.mls import build_mls_operators
from tg_intrinsic.surface_attributes import (mls_parameters,
                                             record_operator_graph,
                                             resolve_frames)
from tg_intrinsic.transforms._batching import GraphTransform
from tg_intrinsic.transforms.gravo_hierarchy import GravoHierarchy

METHODS = ('fps', 'gravo')


def pooling_record(num_levels: int, ratio: float, k: int,
                   method: str) -> Tensor:
    """The record ``[[num_levels, ratio, k, method]]`` (method 0: fps, 1:
    gravo) that :class:`PoolingLevels` stores as ``data.pooling_levels``."""
    return torch.tensor([[float(num_levels), float(ratio), float(k),
                          float(METHODS.index(method))]],
                        dtype=torch.float64)


@functional_transform('pooling_levels')
class PoolingLevels(GraphTransform):
    r"""Builds the pooling levels of a point cloud U-Net with DeltaConv
    operators on every level (functional name: :obj:`pooling_levels`), for
    :class:`~tg_intrinsic.nn.models.DeltaUResNet` (the Delta-U-ResNet of
    the DeltaConv thesis, appendix A.2, after KPFCNN).

    Level :math:`l \geq 1` keeps the fraction :obj:`ratio` of the points of
    level :math:`l - 1`:

    * :obj:`method='fps'`: farthest point sampling (first point first);
      every point of level :math:`l - 1` is pooled into its nearest sample,
      :math:`c(j) = \operatorname{arg\,min}_c \|p_j - p_c\|`, weight 1
      (and unpooled from it: nearest upsampling);
    * :obj:`method='gravo'`: the levels of
      :class:`GravoHierarchy` (reduction :math:`1/\text{ratio}`, unshifted
      samples; the level sizes are approximate), pooled by the normalised
      restriction and unpooled by the prolongation :math:`P_{l-1}`.

    Coarse points keep the tangent frame of the point they were sampled
    from. Every pooling edge :math:`(j, c)` carries the parallel transport
    angle :math:`\phi_{j \to c}` from :math:`j`'s frame to :math:`c`'s (the
    rotation that aligns the normals, :func:`~tg_intrinsic.geometry.log_map`
    with :obj:`'fast'`), and every level gets DeltaConv's MLS operators on
    its own :obj:`k`-nearest-neighbour graph (self loops included; fewer
    neighbours where a level has fewer points):

    .. math::
        (\nabla f)_i = \sum_{j} f_j \, G^{(l)}_{ij}, \qquad
        \mathbf{v}_c = \frac{\sum_{(j, c)} w_{jc} R(\phi_{j \to c})
        \mathbf{v}_j}{\sum_{(j, c)} w_{jc}} .

    Writes level 0 as :class:`MLSOperators` does (``edge_index``,
    ``grad_weight``, ``div_weight``, ``frame``, ``mls_parameters``) and per
    level :math:`l`: ``pos_l``, ``frame_l``, ``sample_index_l``,
    ``edge_index_l``, ``grad_weight_l``, ``div_weight_l``,
    ``pool_edge_index_l`` (row 0 the level-:math:`(l-1)` point, row 1 the
    level-:math:`l` point), ``pool_weight_l``, ``pool_transport_l``; and
    ``pooling_levels`` (the parameters, checked by the model). Returns an
    :class:`~tg_intrinsic.data.IntrinsicData`, so batches offset every
    index by its level's size.

    Args:
        num_levels (int, optional): Coarse levels. (default: :obj:`3`)
        ratio (float, optional): Fraction of the points kept per level.
            (default: :obj:`0.25`)
        k (int, optional): Neighbours of the MLS operators, the point
            itself included. (default: :obj:`20`)
        method (str, optional): :obj:`'fps'` or :obj:`'gravo'`.
            (default: :obj:`'fps'`)
        regularizer (float, optional): MLS regulariser.
            (default: :obj:`1e-3`)
        kernel_width (float, optional): MLS kernel width.
            (default: :obj:`1.0`)
        min_points (int, optional): Fewest points of the coarsest level.
            (default: :obj:`8`)

    Shapes:
        - **input:** ``pos`` :math:`(N, 3)`, ``normal`` :math:`(N, 3)` or
          ``frame`` :math:`(N, 3, 3)` (else normals are estimated)
        - **output:** the keys above, :math:`n_l = \lceil \text{ratio}\,
          n_{l-1} \rceil` with :obj:`'fps'`
    """
    def __init__(self, num_levels: int = 3, ratio: float = 0.25,
                 k: int = 20, method: str = 'fps',
                 regularizer: float = 1e-3, kernel_width: float = 1.0,
                 min_points: int = 8):
        self.num_levels = check_positive_int(num_levels, 'num_levels')
        ratio = check_positive_float(ratio, 'ratio')
        if not ratio < 1:
            raise ValueError(f"'ratio' must lie in (0, 1), got {ratio}")
        self.ratio = ratio
        self.k = check_positive_int(k, 'k', minimum=3)
        if method not in METHODS:
            raise ValueError(f"'method' must be one of {METHODS}, got "
                             f"{method!r}")
        self.method = method
        self.regularizer = regularizer
        self.kernel_width = kernel_width
        self.min_points = check_positive_int(min_points, 'min_points',
                                             minimum=3)

    def level_sizes(self, num_points: int):
        """The level sizes :math:`n_0, \\dots, n_L` of :obj:`'fps'`."""
        sizes = [num_points]
        for _ in range(self.num_levels):
            sizes.append(math.ceil(self.ratio * sizes[-1]))
        return sizes

    def forward(self, data: Data) -> IntrinsicData:
        pos = check_points(getattr(data, 'pos', None), 'data.pos')
        sizes = self.level_sizes(pos.size(0))
        if sizes[-1] < self.min_points:
            least = self.min_points
            for _ in range(self.num_levels):
                least = math.floor((least - 1) / self.ratio) + 1
            raise ValueError(
                f"a cloud of {pos.size(0)} points is too small for "
                f"{self.num_levels} pooling levels of ratio {self.ratio}: "
                f"the coarsest would have {sizes[-1]} points, fewer than "
                f"min_points={self.min_points}; use at least {least} "
                f"points, or fewer levels")
        frame = resolve_frames(data)
        out = IntrinsicData(**{k: v for k, v in data.to_dict().items()})
        out.edge_index, out.grad_weight, out.div_weight = self._operators(
            pos, frame)
        out.frame = frame
        out.mls_parameters = mls_parameters(self.k, self.regularizer,
                                            self.kernel_width)
        record_operator_graph(out)
        if self.method == 'gravo':
            levels = self._gravo(pos)
        else:
            levels = self._fps(pos)
        for level, (sample, pool_index, pool_weight) in enumerate(
                levels, start=1):
            fine_pos, fine_frame = pos, frame
            pos, frame = pos[sample], frame[sample]
            fine, coarse = pool_index
            # (j -> sample of c) on the fine level: phi is the angle at
            # which e_u(j) arrives in the frame of c (= of its sample).
            _, _, phi = log_map(fine_pos, torch.stack([fine, sample[coarse]]),
                                fine_frame, method='fast')
            out[f'pos_{level}'] = pos
            out[f'frame_{level}'] = frame
            out[f'sample_index_{level}'] = sample
            (out[f'edge_index_{level}'], out[f'grad_weight_{level}'],
             out[f'div_weight_{level}']) = self._operators(pos, frame)
            out[f'pool_edge_index_{level}'] = pool_index
            out[f'pool_weight_{level}'] = pool_weight.to(pos.dtype)
            out[f'pool_transport_{level}'] = phi
        out.pooling_levels = pooling_record(self.num_levels, self.ratio,
                                            self.k, self.method)
        return out

    def _operators(self, pos, frame):
        edge_index, _, grad_weight, div_weight = build_mls_operators(
            pos, min(self.k, pos.size(0)), frame=frame,
            kernel_width=self.kernel_width, regularizer=self.regularizer)
        return edge_index, grad_weight, div_weight

    def _fps(self, pos):
        levels = []
        for _ in range(self.num_levels):
            sample = fps(pos, self.ratio, random_start=False)
            nearest = knn(pos[sample], 1, query=pos)
            cluster = torch.empty(pos.size(0), dtype=torch.long,
                                  device=pos.device)
            cluster[nearest[1]] = nearest[0]
            fine = torch.arange(pos.size(0), device=pos.device)
            levels.append((sample, torch.stack([fine, cluster]),
                           torch.ones(pos.size(0), dtype=pos.dtype,
                                      device=pos.device)))
            pos = pos[sample]
        return levels

    def _gravo(self, pos):
        hierarchy = GravoHierarchy(ratio=1 / self.ratio,
                                   lower_bound=3,
                                   max_levels=self.num_levels, shift=False)
        data = hierarchy(Data(pos=pos.detach()))
        found = sum(1 for level in range(1, self.num_levels + 1)
                    if f'pos_{level}' in data)
        if found < self.num_levels:
            raise ValueError(f"the Gravo hierarchy of {pos.size(0)} points "
                             f"stops after {found} of {self.num_levels} "
                             f"levels (a level would have fewer than 3 "
                             f"points); use "
                             f"more points or fewer levels")
        return [(data[f'sample_index_{level}'],
                 data[f'prolong_index_{level}'],
                 data[f'prolong_weight_{level}'])
                for level in range(1, self.num_levels + 1)]

    def __repr__(self) -> str:
        return (f'{self.__class__.__name__}(num_levels={self.num_levels}, '
                f'ratio={self.ratio}, k={self.k}, method={self.method!r})')
