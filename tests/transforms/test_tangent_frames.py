from torch_geometric.data import Data

from tg_intrinsic.transforms import TangentFrames
from tests.conftest import icosphere


def test_mesh_normals_and_frames_without_mutating_input():
    pos, face = icosphere(2)
    data = Data(pos=pos, face=face)
    out = TangentFrames()(data)
    assert 'frame' not in data and 'normal' not in data
    assert out.frame.shape == (pos.size(0), 3, 3)
    radial = pos / pos.norm(dim=-1, keepdim=True)
    assert ((out.frame[:, 2] * radial).sum(-1) > 0.99).all()
    assert repr(TangentFrames(k=7)) == 'TangentFrames(k=7)'
