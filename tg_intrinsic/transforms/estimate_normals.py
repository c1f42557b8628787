from torch_geometric.data import Data
from torch_geometric.data.datapipes import functional_transform
from torch_geometric.transforms import BaseTransform

from tg_intrinsic.geometry import estimate_normals, vertex_normals


@functional_transform('estimate_normals')
class EstimateNormals(BaseTransform):
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
            in ``data.normal`` or ``data.norm``. (default: :obj:`False`)
    """
    def __init__(self, k: int = 10, overwrite: bool = False):
        self.k = k
        self.overwrite = overwrite

    def forward(self, data: Data) -> Data:
        if getattr(data, 'pos', None) is None:
            raise ValueError("EstimateNormals needs 'data.pos'")
        data = data.clone()
        existing = getattr(data, 'normal', None)
        if existing is None:
            existing = getattr(data, 'norm', None)
        if existing is not None and not self.overwrite:
            data.normal = existing
            return data
        if getattr(data, 'face', None) is not None:
            data.normal = vertex_normals(data.pos, data.face)
        else:
            data.normal = estimate_normals(data.pos, self.k,
                                           getattr(data, 'batch', None))
        return data

    def __repr__(self) -> str:
        return (f'{self.__class__.__name__}(k={self.k}, '
                f'overwrite={self.overwrite})')
