from torch_geometric.data import Data
from torch_geometric.data.datapipes import functional_transform

from tg_intrinsic.geometry.checks import check_positive_int
from tg_intrinsic.surface_attributes import given_normals, resolve_frames
from tg_intrinsic.transforms._batching import GraphTransform


@functional_transform('tangent_frames')
class TangentFrames(GraphTransform):
    r"""Writes an orthonormal, right-handed tangent frame per point to
    ``data.frame`` (functional name: :obj:`tangent_frames`).

    Rows are :math:`(e_u, e_v, n)` with :math:`e_u \times e_v = n`; a tangent
    vector :math:`(a, b)` is :math:`a e_u + b e_v`. An existing
    ``data.frame`` is kept (and validated); otherwise the frames are built
    on the normals found by :func:`~tg_intrinsic.surface_attributes.
    resolve_normals` (``data.normal``, else mesh vertex normals, else
    estimated), which are also written to ``data.normal`` if it was
    empty.

    Args:
        k (int, optional): Neighbours for normal estimation on point clouds
            without normals. (default: :obj:`10`)

    Shapes:
        - **output:** ``data.frame`` :math:`(N, 3, 3)`
    """
    def __init__(self, k: int = 10):
        self.k = check_positive_int(k, 'k', minimum=2)

    def forward(self, data: Data) -> Data:
        data = data.clone()
        missing = given_normals(data) is None
        data.frame = resolve_frames(data, self.k)
        if missing:
            data.normal = data.frame[:, 2]
        return data

    def __repr__(self) -> str:
        return f'{self.__class__.__name__}(k={self.k})'
