import torch
from torch_geometric.data import Data

from tg_intrinsic.transforms import EstimateNormals, TangentFrames
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


def test_existing_normals_are_kept_and_norm_alias_read():
    pos, _ = icosphere(1)
    given = -pos / pos.norm(dim=-1, keepdim=True)  # inward on purpose
    out = EstimateNormals()(Data(pos=pos, norm=given))
    assert torch.equal(out.normal, given)
    out = EstimateNormals(k=6, overwrite=True)(Data(pos=pos, normal=given))
    assert ((out.normal * given).sum(-1) < -0.95).all()  # re-estimated
    assert repr(EstimateNormals(k=6, overwrite=True)) == \
        'EstimateNormals(k=6, overwrite=True)'
