import math

import numpy as np
import pytest
import torch
from torch_geometric.data import Data
from torch_geometric.transforms import SamplePoints

from tg_intrinsic.datasets import SyntheticModelNet, SyntheticSHREC
from tg_intrinsic.geometry import estimate_normals, tangent_frames

from tests.conftest import fibonacci_sphere


@pytest.mark.parametrize('dtype', [torch.float32, torch.float64])
def test_sphere_normals_are_radial_and_outward_off_centre(dtype):
    unit = fibonacci_sphere(2000, dtype)
    centre = torch.tensor([10., -4., 3.], dtype=dtype)  # not at the origin
    normal = estimate_normals(2.0 * unit + centre, k=12)
    assert normal.dtype == dtype
    cos = (normal * unit).sum(-1)
    assert cos.min() > 0.99  # all outward, not only up to sign


def test_plane_normals_consistent():
    g = torch.linspace(-1, 1, 30, dtype=torch.float64)
    u, v = torch.meshgrid(g, g, indexing='ij')
    pos = torch.stack([u.flatten(), v.flatten(), torch.zeros(900,
                                                             dtype=g.dtype)], 1)
    tilt = torch.tensor([[1., 0, 0], [0, 0.6, -0.8], [0, 0.8, 0.6]],
                        dtype=g.dtype)
    pos = pos @ tilt.t() + 5
    normal = estimate_normals(pos, k=8)
    expected = tilt[:, 2]
    cos = normal @ expected
    # One consistent side: all +1 or all -1.
    assert (cos.abs() > 1 - 1e-10).all()
    assert (cos > 0).all() or (cos < 0).all()


def test_batched_normals_match_per_example():
    a = fibonacci_sphere(500)
    b = 0.5 * fibonacci_sphere(700) + torch.tensor([0.2, 0.1, 0.0],
                                                   dtype=torch.float64)
    pos = torch.cat([a, b])
    batch = torch.cat([torch.zeros(500), torch.ones(700)]).long()
    together = estimate_normals(pos, k=10, batch=batch)
    apart = torch.cat([estimate_normals(a, k=10), estimate_normals(b, k=10)])
    # The two spheres overlap in space, so crossing examples would be visible.
    assert torch.allclose(together, apart)
    assert ((together[500:] * b.sub(b.mean(0))).sum(-1) > 0).all()


def test_unoriented_normals_are_still_normals():
    unit = fibonacci_sphere(800)
    normal = estimate_normals(unit, k=10, orient=False)
    assert ((normal * unit).sum(-1).abs() > 0.99).all()


def test_degenerate_neighbourhoods_raise():
    line = torch.stack([torch.linspace(0, 1, 50), torch.zeros(50),
                        torch.zeros(50)], 1)
    with pytest.raises(ValueError, match='degenerate'):
        estimate_normals(line, k=5)
    dup = torch.cat([fibonacci_sphere(100).float(),
                     torch.ones(12, 3)])  # 12 copies of one point
    with pytest.raises(ValueError, match='degenerate'):
        estimate_normals(dup, k=10)


@pytest.mark.parametrize('dtype', [torch.float32, torch.float64])
def test_tangent_frames_orthonormal_right_handed(dtype):
    torch.manual_seed(0)
    normal = torch.randn(1000, 3, dtype=dtype)
    normal = torch.cat([normal, torch.eye(3, dtype=dtype),
                        -torch.eye(3, dtype=dtype)])
    frame = tangent_frames(normal)
    assert frame.shape == (1006, 3, 3)
    eye = torch.eye(3, dtype=dtype).expand(1006, 3, 3)
    tol = 1e-5 if dtype == torch.float32 else 1e-12
    assert torch.allclose(frame @ frame.transpose(1, 2), eye, atol=tol)
    assert torch.allclose(torch.linalg.cross(frame[:, 0], frame[:, 1]),
                          frame[:, 2], atol=tol)
    unit = normal / normal.norm(dim=-1, keepdim=True)
    assert torch.allclose(frame[:, 2], unit, atol=tol)


def test_tangent_frames_bad_input():
    with pytest.raises(ValueError, match='zero length'):
        tangent_frames(torch.zeros(2, 3))
    with pytest.raises(ValueError, match=r'\[N, 3\]'):
        tangent_frames(torch.ones(3))


@pytest.mark.parametrize('shape', ['cloud', 'plane', 'anisotropic'])
def test_compiled_pca_matches_torch_eigh(shape):
    from tg_intrinsic.geometry.pointcloud.frames import _pca_numba, _pca_torch
    from tg_intrinsic.geometry.pointcloud.neighbors import knn
    gen = torch.Generator().manual_seed(0)
    pos = torch.randn(1500, 3, dtype=torch.float64, generator=gen)
    if shape == 'plane':  # far from the origin: tests the centring
        pos[:, 2] = 0
        pos = pos * 1e3 + 5
    elif shape == 'anisotropic':
        pos = pos * torch.tensor([1.0, 1e-2, 1e-5], dtype=torch.float64)
    neighbours = knn(pos, 10, loop=False)[0].view(-1, 10)
    evals, normal = _pca_numba(pos.numpy(), neighbours.numpy())
    ref_evals, ref_normal = _pca_torch(pos, neighbours)
    scale = ref_evals[:, 2:].abs()
    assert ((torch.from_numpy(evals) - ref_evals).abs() <= 1e-12 * scale).all()
    cosine = (torch.from_numpy(normal) * ref_normal).sum(-1).abs()
    assert (cosine > 1 - 1e-9).all()


# ---------------------------------------------------------------------------
# Orientation: agreement in sign with known outward normals.
# ---------------------------------------------------------------------------
def agreement(normal, truth):
    """Fraction of points whose normal points to the same side as the truth
    (sign of the dot product), the measure of benchmarks/normals.py."""
    return float(((normal.double() * truth.double()).sum(-1) > 0).double()
                 .mean())


def torus(num, big=1.0, small=0.3, seed=0):
    gen = torch.Generator().manual_seed(seed)
    u, v = 2 * math.pi * torch.rand(2, num, dtype=torch.float64,
                                    generator=gen)
    normal = torch.stack([torch.cos(v) * torch.cos(u),
                          torch.cos(v) * torch.sin(u), torch.sin(v)], 1)
    ring = torch.stack([torch.cos(u), torch.sin(u), torch.zeros_like(u)], 1)
    return big * ring + small * normal, normal


def u_prism(num, width=1.0, length=1.0, wall=0.04, height=1.0, seed=0):
    """A closed, non-convex prism over a U-shaped outline whose walls are
    thinner than twice the sample spacing, so that k-nn neighbourhoods
    reach the other side: points and outward normals, uniform by area."""
    outline = np.array([[0, 0], [width, 0], [width, length],
                        [width - wall, length], [width - wall, wall],
                        [wall, wall], [wall, length], [0, length]])  # ccw
    rects = []  # (origin, edge u, edge v, outward normal)
    for a, b in zip(outline, np.roll(outline, -1, 0)):
        d = b - a
        rects.append(([a[0], a[1], 0], [d[0], d[1], 0], [0, 0, height],
                      np.array([d[1], -d[0], 0]) / np.hypot(*d)))
    for x0, y0, sx, sy in [(0, 0, width, wall), (0, wall, wall, length - wall),
                           (width - wall, wall, wall, length - wall)]:
        rects.append(([x0, y0, height], [sx, 0, 0], [0, sy, 0], [0, 0, 1]))
        rects.append(([x0, y0, 0], [sx, 0, 0], [0, sy, 0], [0, 0, -1]))
    origin, eu, ev, normal = (np.array([r[i] for r in rects], dtype=float)
                              for i in range(4))
    area = np.linalg.norm(np.cross(eu, ev), axis=1)
    rng = np.random.default_rng(seed)
    pick = rng.choice(len(rects), size=num, p=area / area.sum())
    s, t = rng.random((2, num, 1))
    pos = origin[pick] + s * eu[pick] + t * ev[pick]
    return torch.tensor(pos), torch.tensor(normal[pick])


def test_u_prism_is_thin_for_its_sampling():
    # The walls must really be thinner than the neighbourhoods (otherwise
    # the thin-part test below tests nothing): most points have a neighbour
    # on the other side of their wall among their 10 nearest.
    from tg_intrinsic.geometry.pointcloud.neighbors import knn
    pos, normal = u_prism(2000)
    nb = knn(pos, 10)[0].view(-1, 10)
    opposite = ((normal[nb] * normal[:, None]).sum(-1) < -0.9).any(1)
    assert opposite.double().mean() > 0.8


def rotate_and_shift(pos, normal):
    rot = torch.tensor([[0.8, -0.6, 0], [0.6, 0.8, 0], [0, 0, 1.0]],
                       dtype=torch.float64)
    return pos @ rot.t() + 3.0, normal @ rot.t()


def test_orientation_of_a_torus():
    pos, normal = rotate_and_shift(*torus(3000))
    assert agreement(estimate_normals(pos, k=10), normal) >= 0.97


def test_orientation_of_a_non_convex_shape_with_thin_walls():
    pos, normal = rotate_and_shift(*u_prism(2000))
    estimate = estimate_normals(pos, k=10)
    # Where the walls are as thin as the neighbourhoods, PCA itself mixes
    # the two sides and returns tilted normals, whose sign says little;
    # where the unoriented normal is right (within 30 degrees), the side
    # must be right too (0.99 over random rotations, 0.95 for all points;
    # the MST + flux orientation this replaced scored 0.53).
    fitted = (estimate * normal).sum(-1).abs() > math.cos(math.pi / 6)
    assert fitted.double().mean() > 0.5
    assert agreement(estimate[fitted], normal[fitted]) >= 0.97
    assert agreement(estimate, normal) >= 0.93


def test_two_components_each_outward():
    # Separate closed shapes in one example are each oriented outward on
    # their own, also when they nearly touch: there the k-nn graph links
    # them with antiparallel normals, which sign propagation would follow.
    torus_pos, torus_normal = torus(2000)
    sphere = fibonacci_sphere(600)
    pos = torch.cat([torus_pos, 0.4 * sphere + torch.tensor(
        [3.0, 0.5, 0.2], dtype=torch.float64)])
    normal = estimate_normals(pos, k=10)
    assert agreement(normal[:2000], torus_normal) >= 0.97
    assert agreement(normal[2000:], sphere) == 1.0
    big = fibonacci_sphere(2000)
    pos = torch.cat([big, 0.5 * sphere + torch.tensor(
        [1.55, 0.0, 0.0], dtype=torch.float64)])  # a gap of 0.05
    normal = estimate_normals(pos, k=10)
    assert agreement(normal[:2000], big) >= 0.97
    assert agreement(normal[2000:], sphere) >= 0.97


@pytest.mark.parametrize('up', [1.0, -1.0])
def test_open_hemisphere_gets_its_convex_side(up):
    # An open surface has no inside; the documented rule gives the side
    # seen from more directions, for a spherical cap its convex side.
    unit = fibonacci_sphere(3000)
    cap = unit[unit[:, 2] * up > 0.05]
    normal = estimate_normals(0.5 * cap + torch.tensor(
        [1.0, -2.0, 0.5], dtype=torch.float64), k=10)
    assert agreement(normal, cap) == 1.0


def test_open_wavy_sheet_is_consistent():
    g = torch.linspace(-1, 1, 40, dtype=torch.float64)
    u, v = torch.meshgrid(g, g, indexing='ij')
    u, v = u.flatten(), v.flatten()
    pos = torch.stack([u, v, 0.3 * torch.sin(2 * u) * torch.cos(v)], 1)
    up = torch.stack([-0.6 * torch.cos(2 * u) * torch.cos(v),
                      0.3 * torch.sin(2 * u) * torch.sin(v),
                      torch.ones_like(u)], 1)
    cos = (estimate_normals(pos, k=10) * up).sum(-1)
    assert (cos > 0).all() or (cos < 0).all()


@pytest.fixture(scope='module')
def synthetic_modelnet(tmp_path_factory):
    root = tmp_path_factory.mktemp('modelnet')
    return SyntheticModelNet(str(root), 'test', num_points=1024,
                             num_per_class=(1, 1), log=False)


@pytest.fixture(scope='module')
def synthetic_shrec_clouds(tmp_path_factory):
    root = tmp_path_factory.mktemp('shrec')
    meshes = SyntheticSHREC(str(root), 'test', num_per_class=2,
                            num_train_per_class=1, num_vertices=(500, 700),
                            log=False)
    clouds = []
    for i, mesh in enumerate(meshes):
        torch.manual_seed(i)
        cloud = SamplePoints(1024, include_normals=True)(
            Data(pos=mesh.pos, face=mesh.face))
        clouds.append((meshes.classes[int(mesh.y)], cloud.pos, cloud.normal))
    return clouds


def test_orientation_on_synthetic_modelnet(synthetic_modelnet):
    score = {synthetic_modelnet.classes[int(d.y)]:
             agreement(estimate_normals(d.pos, k=10), d.normal)
             for d in synthetic_modelnet}
    # Shapes made of smooth or thick parts are oriented almost everywhere.
    for name in ['bottle', 'cup', 'guitar', 'lamp', 'monitor']:
        assert score[name] >= 0.97, (name, score[name])
    # Thin walls (cup, bookshelf, headboards) and narrow slots between
    # parts (sofa cushions) leave some points wrong; the MST + flux
    # orientation this replaced scored 0.65 on average here.
    assert sum(score.values()) / len(score) >= 0.9, score
    assert min(score.values()) >= 0.8, score


def test_orientation_on_synthetic_shrec(synthetic_shrec_clouds):
    score = {name: agreement(estimate_normals(pos, k=10), normal)
             for name, pos, normal in synthetic_shrec_clouds}
    assert sum(s >= 0.97 for s in score.values()) >= 9, score
    assert sum(score.values()) / len(score) >= 0.97, score
    assert min(score.values()) >= 0.93, score


def test_orientation_batched_equals_unbatched(synthetic_modelnet):
    clouds = [torus(1500)[0], u_prism(1200)[0] - 0.5,
              synthetic_modelnet[0].pos.double(),
              0.5 * fibonacci_sphere(700)]
    batch = torch.cat([torch.full((c.size(0), ), i)
                       for i, c in enumerate(clouds)])
    together = estimate_normals(torch.cat(clouds), k=10, batch=batch)
    apart = torch.cat([estimate_normals(c, k=10) for c in clouds])
    # The clouds overlap in space: sharing anything would show.
    assert torch.equal(together, apart)


def test_orientation_is_deterministic():
    pos = torch.cat([u_prism(1500)[0], torus(1500)[0] + 2.5])
    first = estimate_normals(pos, k=10)
    assert torch.equal(first, estimate_normals(pos.clone(), k=10))
    float32 = estimate_normals(pos.float(), k=10)
    assert ((float32.double() * first).sum(-1) > 0).double().mean() > 0.99
