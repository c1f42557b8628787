from torch_geometric.data import Data
from torch_geometric.data.datapipes import functional_transform
from torch_geometric.transforms import BaseTransform

from tg_intrinsic.geometry import tangent_frames
from tg_intrinsic.transforms.estimate_normals import EstimateNormals


@functional_transform('tangent_frames')
class TangentFrames(BaseTransform):
    r"""Writes an orthonormal, right-handed tangent frame per point to
    ``data.frame`` (functional name: :obj:`tangent_frames`).

    Rows are :math:`(e_u, e_v, n)` with :math:`e_u \times e_v = n`; a tangent
    vector :math:`(a, b)` is :math:`a e_u + b e_v`. Normals come from
    ``data.normal`` (or ``data.norm``), else they are estimated with
    :class:`EstimateNormals`. An existing ``data.frame`` is kept.

    Args:
        k (int, optional): Neighbours for normal estimation on point clouds
            without normals. (default: :obj:`10`)

    Shapes:
        - **output:** ``data.frame`` :math:`(N, 3, 3)`
    """
    def __init__(self, k: int = 10):
        self.k = k

    def forward(self, data: Data) -> Data:
        if getattr(data, 'frame', None) is not None:
            return data
        data = EstimateNormals(self.k)(data)
        data.frame = tangent_frames(data.normal)
        return data

    def __repr__(self) -> str:
        return f'{self.__class__.__name__}(k={self.k})'
