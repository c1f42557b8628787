from typing import Optional

from torch_geometric.data import Data
from torch_geometric.data.datapipes import functional_transform

from tg_intrinsic.geometry.checks import check_positive_int
from tg_intrinsic.geometry.geodesics.harmonic import harmonic_terms
from tg_intrinsic.surface_attributes import check_operator_graph
from tg_intrinsic.transforms._batching import GraphTransform


@functional_transform('harmonic_precompute')
class HarmonicPrecompute(GraphTransform):
    r"""Precomputes the parameter-free part of every circular-harmonic filter
    of Harmonic Surface Networks per edge, ring and order (functional name:
    :obj:`harmonic_precompute`). It computes

    .. math::
        h_{(j \to i), q, m} = \frac{w_j}{\sum_{k \in \mathcal{N}(i)} w_k}
        \, \mu_q(r_{ij})\, e^{i m \theta_{ij}},

    with :math:`w` the point areas, :math:`\mu_q` the linear interpolation
    weights of :math:`Q` rings on :math:`[0, \epsilon]` and :math:`m \neq 0`
    terms zero at :math:`r = 0`. Reads ``edge_index``, ``logmap``, ``area``
    and ``logmap_radius`` (written by :class:`LogMap`) and writes
    ``harmonic``; with :obj:`levels` the same for every pooling level
    ``_l`` of :class:`MultiscaleSupports`. Per-edge, so batching needs
    nothing special.

    Args:
        rings (int, optional): Rings :math:`Q`. (default: :obj:`6`)
        max_order (int, optional): Highest order :math:`m`.
            (default: :obj:`1`)
        levels (int, optional): Number of pooling levels to precompute
            besides level 0; :obj:`None` for all that are present.
            (default: :obj:`None`)

    Shapes:
        - **output:** ``harmonic`` complex :math:`(E, Q, \text{max\_order}
          + 1)`, ``harmonic_l`` likewise on level :math:`l`
    """
    def __init__(self, rings: int = 6, max_order: int = 1,
                 levels: Optional[int] = None):
        self.rings = check_positive_int(rings, 'rings')
        self.max_order = check_positive_int(max_order, 'max_order',
                                            minimum=0)
        self.levels = (None if levels is None else
                       check_positive_int(levels, 'levels', minimum=0))

    def forward(self, data: Data) -> Data:
        check_operator_graph(data, 'logmap', 'LogMap')
        data = data.clone()
        level = 0
        while True:
            suffix = '' if level == 0 else f'_{level}'
            if level > 0 and (getattr(data, f'logmap{suffix}', None) is None
                              or (self.levels is not None
                                  and level > self.levels)):
                break
            for key in ('edge_index', 'logmap', 'area', 'logmap_radius'):
                if getattr(data, key + suffix, None) is None:
                    raise ValueError(
                        f"HarmonicPrecompute needs 'data.{key}{suffix}'; run "
                        f"LogMap (and MultiscaleSupports for levels) first")
            area = data[f'area{suffix}']
            data[f'harmonic{suffix}'] = harmonic_terms(
                data[f'edge_index{suffix}'], data[f'logmap{suffix}'], area,
                float(data[f'logmap_radius{suffix}'].reshape(-1)[0]),
                self.rings, self.max_order, num_nodes=area.numel())
            level += 1
        return data

    def __repr__(self) -> str:
        return (f'{self.__class__.__name__}(rings={self.rings}, '
                f'max_order={self.max_order})')

