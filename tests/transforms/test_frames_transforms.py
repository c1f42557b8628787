import pytest
import torch
from torch_geometric.data import Data

from tg_intrinsic.transforms import EstimateNormals, MLSOperators, TangentFrames
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


def test_mls_operators_refuse_neighbourhoods_too_small_to_fit():
    # k = 1 (the point alone) used to give all-zero weights silently
    from tg_intrinsic.geometry import build_mls_operators
    for k in (1, 2):
        with pytest.raises(ValueError, match="'k' must be at least 3"):
            MLSOperators(k=k)
        with pytest.raises(ValueError, match="'k' must be at least 3"):
            build_mls_operators(torch.randn(20, 3), k)
    with pytest.raises(ValueError, match="'regularizer' must be positive"):
        MLSOperators(regularizer=0)
    with pytest.raises(ValueError, match="'kernel_width' must be finite"):
        MLSOperators(kernel_width=float('nan'))
    out = MLSOperators(k=3)(Data(pos=torch.randn(20, 3,
                                                 dtype=torch.float64)))
    assert bool((out.grad_weight.abs().sum(1) > 0).any())
