import pytest
import torch
from torch_geometric.data import Data

from tg_intrinsic.transforms import EstimateNormals
from tests.conftest import fibonacci_sphere, icosphere
from tests.symmetry import random_rotation


def random_sphere(n, seed=0):
    """Points on the unit sphere without tied neighbour distances."""
    g = torch.Generator().manual_seed(seed)
    pos = torch.randn(n, 3, generator=g, dtype=torch.float64)
    return pos / pos.norm(dim=1, keepdim=True)


def test_existing_normals_are_kept_and_norm_alias_read():
    pos, _ = icosphere(1)
    given = -pos / pos.norm(dim=-1, keepdim=True)  # inward on purpose
    out = EstimateNormals()(Data(pos=pos, norm=given))
    assert torch.equal(out.normal, given)
    out = EstimateNormals(k=6, overwrite=True)(Data(pos=pos, normal=given))
    assert ((out.normal * given).sum(-1) < -0.95).all()  # re-estimated
    assert repr(EstimateNormals(k=6, overwrite=True)) == \
        'EstimateNormals(k=6, overwrite=True)'


def test_normals_of_the_icosahedron_are_radial():
    # every vertex and its five neighbours are symmetric about the radius,
    # so both the PCA normal of the cloud and the vertex normal of the
    # mesh are exactly pos / |pos|, outward
    pos, face = icosphere(0)
    radial = pos / pos.norm(dim=1, keepdim=True)
    cloud = EstimateNormals(k=5)(Data(pos=pos))
    assert torch.allclose(cloud.normal, radial, atol=1e-12)
    mesh = EstimateNormals()(Data(pos=pos, face=face))
    assert torch.allclose(mesh.normal, radial, atol=1e-12)


def test_sphere_cloud_normals_are_unit_outward_and_near_radial():
    pos = fibonacci_sphere(1000)
    data = Data(pos=pos, y=torch.arange(1000))
    out = EstimateNormals()(data)
    assert out.normal.shape == (1000, 3) and out.normal.dtype == pos.dtype
    assert torch.allclose(out.normal.norm(dim=1),
                          torch.ones(1000, dtype=pos.dtype), atol=1e-12)
    assert ((out.normal - pos).norm(dim=1) < 0.1).all()
    # nothing else is written or changed, the input is not mutated
    assert set(out.keys()) == {'pos', 'y', 'normal'}
    assert 'normal' not in data and torch.equal(out.y, data.y)


def test_plane_normals_are_exact_and_consistent():
    g = torch.Generator().manual_seed(0)
    uv = torch.rand(80, 2, generator=g, dtype=torch.float64)
    tangent = torch.tensor([[1.0, 0.0, 1.0], [0.0, 1.0, -0.5]],
                           dtype=torch.float64)
    want = torch.linalg.cross(tangent[0], tangent[1])
    want = want / want.norm()
    out = EstimateNormals(k=8)(Data(pos=uv @ tangent + 3.0))
    side = torch.sign((out.normal @ want)[0])
    assert torch.allclose(out.normal, side * want.expand(80, 3), atol=1e-12)


def test_rigid_motions_move_the_normals_along():
    pos = random_sphere(300)
    r = random_rotation(seed=1)
    shift = torch.tensor([2.0, -1.0, 0.5], dtype=torch.float64)
    a = EstimateNormals()(Data(pos=pos)).normal
    b = EstimateNormals()(Data(pos=pos @ r.T + shift)).normal
    assert torch.allclose(b, a @ r.T, atol=1e-9)


def test_examples_of_a_batch_are_estimated_alone():
    a, b = random_sphere(150, seed=2), 0.7 * random_sphere(120, seed=3)
    b = b + torch.tensor([1.2, 0.0, 0.0], dtype=torch.float64)  # overlaps
    batch = torch.cat([torch.zeros(150), torch.ones(120)]).long()
    out = EstimateNormals()(Data(pos=torch.cat([a, b]), batch=batch))
    alone = torch.cat([EstimateNormals()(Data(pos=a)).normal,
                       EstimateNormals()(Data(pos=b)).normal])
    assert torch.allclose(out.normal, alone, atol=1e-12)
    together = EstimateNormals()(Data(pos=torch.cat([a, b]))).normal
    assert not torch.allclose(together, alone, atol=1e-3)


def test_overwrite_recomputes_mesh_normals_and_float32_stays_float32():
    pos, face = icosphere(0)
    pos = pos.float()
    stale = torch.tensor([[0.0, 0.0, 1.0]]).repeat(pos.size(0), 1)
    out = EstimateNormals(overwrite=True)(Data(pos=pos, face=face,
                                               normal=stale))
    assert out.normal.dtype == torch.float32
    radial = pos / pos.norm(dim=1, keepdim=True)
    assert torch.allclose(out.normal, radial, atol=1e-6)
    kept = EstimateNormals()(Data(pos=pos, face=face, normal=stale))
    assert torch.equal(kept.normal, stale)


def test_bad_input():
    pos = random_sphere(20)
    with pytest.raises(ValueError, match="needs 'data.pos'"):
        EstimateNormals()(Data(x=pos))
    with pytest.raises(ValueError, match="'k' must be at least 2"):
        EstimateNormals(k=1)
    with pytest.raises(ValueError, match='NaN'):
        EstimateNormals()(Data(pos=torch.full((20, 3), float('nan'))))
    with pytest.raises(ValueError, match="'data.normal' has 19 rows"):
        EstimateNormals()(Data(pos=pos, normal=pos[:19]))
    line = torch.linspace(0, 1, 20, dtype=torch.float64)[:, None] \
        * torch.tensor([1.0, 2.0, 3.0], dtype=torch.float64)
    with pytest.raises(ValueError, match='degenerate'):
        EstimateNormals(k=4)(Data(pos=line))
    assert repr(EstimateNormals()) == 'EstimateNormals(k=10, overwrite=False)'
