from torch_geometric.data import Data
from torch_geometric.data.datapipes import functional_transform

from tg_intrinsic.data import IntrinsicData
from tg_intrinsic.geometry.checks import check_points, check_positive_int
from tg_intrinsic.geometry.multigrid.gravo import (check_options,
                                                   gravo_hierarchy)
from tg_intrinsic.surface_attributes import surface_graph
from tg_intrinsic.transforms._batching import GraphTransform


@functional_transform('gravo_hierarchy')
class GravoHierarchy(GraphTransform):
    r"""Builds a Gravo MG multigrid hierarchy (Wiersma et al., "A Fast
    Geometric Multigrid Method for Curved Surfaces", SIGGRAPH 2023;
    functional name: :obj:`gravo_hierarchy`).

    The neighbour graph is the mesh edges (``face``), else ``edge_index``,
    else a :obj:`k`-nearest-neighbour graph of ``pos``. Every level keeps
    about one in :obj:`ratio` points, sampled in one sweep with the
    exclusion radius :math:`r = \text{ratio}^{1/3} \bar h`; fine points join
    the graph Voronoi cell of their nearest sample (exactly, or with
    :obj:`voronoi='sweep'` as the original implementation's partial
    correction of the cells the sweep claimed), cells that touch make
    coarse edges, and the prolongation interpolates on the closest coarse
    triangle (3-clique) incident to a point's own cell:

    .. math::
        (P_l)_{i,\cdot} = \text{barycentric coordinates of }
        \operatorname*{arg\,min}_{q \in T,\; T \ni c(i)} \|q - p_i\|,

    with inverse distance weights to the three closest coarse neighbours
    where no triangle exists. Coarsening stops before a level would have
    fewer than :obj:`lower_bound` points, or after :obj:`max_levels`.

    Writes, per level :math:`l \geq 1`: ``pos_l``, ``edge_index_l``,
    ``sample_index_l`` (the level-:math:`(l-1)` point of every coarse
    point), ``cluster_l`` (the Voronoi cell of every level-:math:`(l-1)`
    point), ``prolong_index_l`` and ``prolong_weight_l`` (:math:`P_{l-1}`:
    row 0 fine, row 1 coarse); returns an
    :class:`~tg_intrinsic.data.IntrinsicData`, so batches offset them
    correctly and their prolongations are block diagonal.

    Args:
        ratio (float, optional): Reduction factor per level.
            (default: :obj:`8.0`)
        lower_bound (int, optional): Smallest level size.
            (default: :obj:`1000`)
        max_levels (int, optional): Most coarse levels. (default: :obj:`10`)
        shift (bool, optional): Move every coarse point to the mean of its
            cell. (default: :obj:`True`)
        weighting (str, optional): :obj:`'barycentric'`,
            :obj:`'inverse_distance'` or :obj:`'uniform'` (a third to each
            corner of the closest triangle). (default: :obj:`'barycentric'`)
        voronoi (str, optional): :obj:`'exact'` (multi-source Dijkstra) or
            :obj:`'sweep'` (the sweep's cells, corrected where the Dijkstra
            reaches, as the original). (default: :obj:`'exact'`)
        k (int, optional): Neighbours of the graph built for point clouds
            without ``edge_index``. (default: :obj:`8`)

    Shapes:
        - **input:** ``pos`` :math:`(N, 3)`, and ``face`` :math:`(3, F)` or
          ``edge_index`` :math:`(2, E)` (optional)
        - **output:** the keys above, :math:`n_l \approx N / \text{ratio}^l`
    """
    def __init__(self, ratio: float = 8.0, lower_bound: int = 1000,
                 max_levels: int = 10, shift: bool = True,
                 weighting: str = 'barycentric', voronoi: str = 'exact',
                 k: int = 8):
        for name, value in (('lower_bound', lower_bound),
                            ('max_levels', max_levels), ('k', k)):
            check_positive_int(value, name)
        check_options(ratio, weighting, voronoi)
        self.ratio = float(ratio)
        self.lower_bound = lower_bound
        self.max_levels = max_levels
        self.shift = shift
        self.weighting = weighting
        self.voronoi = voronoi
        self.k = k

    def forward(self, data: Data) -> IntrinsicData:
        pos = check_points(data.pos)
        graph = surface_graph(data, self.k)
        levels = gravo_hierarchy(pos.detach(), graph, self.ratio,
                                 self.lower_bound, self.max_levels,
                                 self.shift, self.weighting, self.voronoi)
        data = IntrinsicData(**{k: v for k, v in data.to_dict().items()})
        for level, step in enumerate(levels, start=1):
            data[f'pos_{level}'] = step.pos
            data[f'edge_index_{level}'] = step.edge_index
            data[f'sample_index_{level}'] = step.sample
            data[f'cluster_{level}'] = step.cluster
            data[f'prolong_index_{level}'] = step.prolong_index
            data[f'prolong_weight_{level}'] = step.prolong_weight
        return data

    def __repr__(self) -> str:
        return (f'{self.__class__.__name__}(ratio={self.ratio}, '
                f'lower_bound={self.lower_bound}, shift={self.shift}, '
                f'weighting={self.weighting!r}, voronoi={self.voronoi!r})')
