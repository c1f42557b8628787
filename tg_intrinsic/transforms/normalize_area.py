from torch_geometric.data import Data
from torch_geometric.data.datapipes import functional_transform

from tg_intrinsic.geometry import normalize_area
from tg_intrinsic.transforms._batching import GraphTransform


@functional_transform('normalize_area')
class NormalizeArea(GraphTransform):
    r"""Centres a mesh at its area-weighted centroid and scales it to a
    given surface area (functional name: :obj:`normalize_area`). It maps

    .. math::
        p_i \leftarrow \sqrt{A^* / A}\, (p_i - c),

    so that radii such as Harmonic Surface Networks' :math:`\epsilon = 0.2`
    mean the same on every shape. Normals and frames are unchanged;
    per-edge geometry computed before must be recomputed.

    Args:
        area (float, optional): Target area :math:`A^*`.
            (default: :obj:`1.0`)

    Shapes:
        - **input:** ``pos`` :math:`(N, 3)`, ``face`` :math:`(3, F)`
        - **output:** ``pos`` :math:`(N, 3)`
    """
    def __init__(self, area: float = 1.0):
        self.area = area

    def forward(self, data: Data) -> Data:
        if getattr(data, 'face', None) is None:
            raise ValueError("NormalizeArea needs a mesh ('data.face'); for "
                             "point clouds use "
                             "torch_geometric.transforms.NormalizeScale")
        data = data.clone()
        data.pos = normalize_area(data.pos, data.face, self.area)
        return data

    def __repr__(self) -> str:
        return f'{self.__class__.__name__}(area={self.area})'
