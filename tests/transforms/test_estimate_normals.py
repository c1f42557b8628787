import torch
from torch_geometric.data import Data

from tg_intrinsic.transforms import EstimateNormals
from tests.conftest import icosphere


def test_existing_normals_are_kept_and_norm_alias_read():
    pos, _ = icosphere(1)
    given = -pos / pos.norm(dim=-1, keepdim=True)  # inward on purpose
    out = EstimateNormals()(Data(pos=pos, norm=given))
    assert torch.equal(out.normal, given)
    out = EstimateNormals(k=6, overwrite=True)(Data(pos=pos, normal=given))
    assert ((out.normal * given).sum(-1) < -0.95).all()  # re-estimated
    assert repr(EstimateNormals(k=6, overwrite=True)) == \
        'EstimateNormals(k=6, overwrite=True)'
