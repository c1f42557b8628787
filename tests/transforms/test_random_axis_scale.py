import pytest
import torch
from torch_geometric.data import Data

from tg_intrinsic.transforms import RandomAxisScale


def test_normals_stay_normal_to_the_stretched_surface():
    # Points on a tilted plane; after any per-axis stretch the normal must
    # be orthogonal to the stretched in-plane directions (exact oracle).
    torch.manual_seed(0)
    tangent = torch.tensor([[1.0, 0.0, 0.5], [0.0, 1.0, -2.0]],
                           dtype=torch.float64)
    normal = torch.linalg.cross(tangent[0], tangent[1])
    normal = normal / normal.norm()
    uv = torch.rand(50, 2, dtype=torch.float64)
    data = Data(pos=uv @ tangent, normal=normal.expand(50, 3).clone(),
                grad_weight=torch.ones(3, 2), edge_index=torch.zeros(2, 3))
    out = RandomAxisScale((0.5, 2.0))(data)
    factor = out.pos[1:] / data.pos[1:]
    factor = factor[torch.isfinite(factor).all(1)][0]
    assert ((factor >= 0.5) & (factor <= 2.0)).all()
    stretched = tangent * factor
    assert torch.allclose(out.normal @ stretched.T,
                          torch.zeros(50, 2, dtype=torch.float64), atol=1e-12)
    assert torch.allclose(out.normal.norm(dim=1),
                          torch.ones(50, dtype=torch.float64))
    # Operators of the unstretched surface are stale: removed.
    assert 'grad_weight' not in out and 'edge_index' not in out
    assert 'grad_weight' in data   # the input is not mutated


def test_bad_input():
    with pytest.raises(ValueError, match='0 < low <= high'):
        RandomAxisScale((1.2, 0.8))
    with pytest.raises(ValueError, match="needs 'data.pos'"):
        RandomAxisScale((0.9, 1.1))(Data(x=torch.zeros(3, 1)))
    assert repr(RandomAxisScale((0.8, 1.25))) == \
        'RandomAxisScale(scales=(0.8, 1.25))'
