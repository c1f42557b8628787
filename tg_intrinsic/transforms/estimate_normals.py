from torch_geometric.data import Data
from torch_geometric.data.datapipes import functional_transform

from tg_intrinsic.geometry.checks import check_positive_int
from tg_intrinsic.surface_attributes import (computed_normals,
                                             resolve_normals)
from tg_intrinsic.transforms._batching import GraphTransform


@functional_transform('estimate_normals')
class EstimateNormals(GraphTransform):
    r"""Writes unit normals to ``data.normal`` (functional name:
    :obj:`estimate_normals`).

    Meshes (``data.face`` present) get area-weighted vertex normals; point
    clouds get PCA normals of the :obj:`k` nearest neighbours, oriented
    consistently (see :func:`tg_intrinsic.geometry.estimate_normals`):

    .. math::
        n_i = \operatorname{argmin}_{\|n\| = 1} n^\top C_i n .

    Args:
        k (int, optional): Neighbours for point clouds. (default: :obj:`10`)
        overwrite (bool, optional): Replace normals that are already present
            (``data.frame``, ``data.normal`` or ``data.norm``, see
            :func:`~tg_intrinsic.surface_attributes.resolve_normals`).
            (default: :obj:`False`)
    """
    def __init__(self, k: int = 10, overwrite: bool = False):
        self.k = check_positive_int(k, 'k', minimum=2)
        self.overwrite = overwrite

    def forward(self, data: Data) -> Data:
        if getattr(data, 'pos', None) is None:
            raise ValueError("EstimateNormals needs 'data.pos'")
        data = data.clone()
        data.normal = (computed_normals(data, self.k) if self.overwrite
                       else resolve_normals(data, self.k))
        return data

    def __repr__(self) -> str:
        return (f'{self.__class__.__name__}(k={self.k}, '
                f'overwrite={self.overwrite})')
