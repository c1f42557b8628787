import math

import pytest
import torch

from tg_intrinsic.geometry import estimate_normals, tangent_frames


def fibonacci_sphere(n, dtype=torch.float64):
    i = torch.arange(n, dtype=dtype) + 0.5
    phi = torch.acos(1 - 2 * i / n)
    theta = math.pi * (1 + 5 ** 0.5) * i
    return torch.stack([torch.cos(theta) * torch.sin(phi),
                        torch.sin(theta) * torch.sin(phi), torch.cos(phi)], 1)


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
    from tg_intrinsic.geometry.frames import _pca_numba, _pca_torch
    from tg_intrinsic.geometry.neighbors import knn
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
