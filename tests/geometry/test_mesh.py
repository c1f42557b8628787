import math

import numpy as np
import pytest
import robust_laplacian
import torch
import trimesh

from tg_intrinsic.geometry import (cotan_laplacian,
                                   edge_face_counts, face_areas, face_normals,
                                   is_closed_manifold,
                                   lumped_mass, mesh_edges, normalize_area,
                                   remove_unreferenced_vertices, to_scipy,
                                   vertex_normals, weld_vertices)
from tests.conftest import grid_mesh, icosphere


def brute_force_cotan(pos, face):
    """Per-triangle dense assembly from angles computed with arccos."""
    p = pos.numpy()
    n = p.shape[0]
    S = np.zeros((n, n))
    for tri in face.t().numpy():
        for c in range(3):
            o, i, j = tri[c], tri[(c + 1) % 3], tri[(c + 2) % 3]
            a, b = p[i] - p[o], p[j] - p[o]
            angle = math.acos(np.dot(a, b) / np.linalg.norm(a) /
                              np.linalg.norm(b))
            w = 0.5 / math.tan(angle)
            S[i, j] -= w
            S[j, i] -= w
            S[i, i] += w
            S[j, j] += w
    return S


def test_cotan_matches_brute_force_on_irregular_mesh():
    pos, face = grid_mesh(7, jitter=0.6, seed=3)
    pos[:, 2] = 0.3 * torch.sin(3 * pos[:, 0]) * pos[:, 1]  # curve it
    S = cotan_laplacian(pos, face)
    assert S.is_coalesced()
    np.testing.assert_allclose(S.to_dense().numpy(),
                               brute_force_cotan(pos, face), atol=1e-12)


def test_cotan_matches_robust_laplacian_on_delaunay_mesh(sphere_mesh):
    pos, face = sphere_mesh
    L, M = robust_laplacian.mesh_laplacian(pos.numpy(), face.t().numpy(),
                                           mollify_factor=0.0)
    S = to_scipy(cotan_laplacian(pos, face))
    assert abs(S - L).max() < 1e-10
    np.testing.assert_allclose(lumped_mass(pos, face).numpy(), M.diagonal(),
                               rtol=1e-10)


@pytest.mark.parametrize('dtype', [torch.float32, torch.float64])
def test_cotan_properties(dtype):
    pos, face = icosphere(2, dtype)
    S = cotan_laplacian(pos, face)
    assert S.dtype == dtype
    dense = S.to_dense().double()
    tol = 1e-5 if dtype == torch.float32 else 1e-12
    assert torch.allclose(dense, dense.t(), atol=tol)
    ones = torch.ones(pos.size(0), dtype=torch.float64)
    assert (dense @ ones).abs().max() < tol  # constants in the kernel
    evals = torch.linalg.eigvalsh(dense)
    assert evals.min() > -tol  # positive semi-definite
    assert (evals < 1e-6).sum() == 1  # connected: one-dimensional kernel


def test_laplacian_of_linear_function_on_flat_mesh_is_zero_inside():
    pos, face = grid_mesh(8, jitter=0.5, seed=1)
    S = cotan_laplacian(pos, face).to_dense()
    f = 2 * pos[:, 0] - 3 * pos[:, 1]
    inner = ((pos[:, 0] > 0) & (pos[:, 0] < 1) & (pos[:, 1] > 0)
             & (pos[:, 1] < 1))
    assert (S @ f)[inner].abs().max() < 1e-12


def test_dirichlet_energy_on_sphere_converges():
    # x^T S x = int |grad x|^2; for f = z on the unit sphere
    # |grad z|^2 = 1 - z^2, so the integral is 4 pi - 4 pi / 3 = 8 pi / 3.
    errors = []
    for level in (2, 3, 4):
        pos, face = icosphere(level)
        S = cotan_laplacian(pos, face)
        z = pos[:, 2]
        energy = z @ torch.sparse.mm(S, z[:, None]).squeeze()
        errors.append(abs(energy.item() - 8 * math.pi / 3))
    # Second-order convergence: halving the edge length quarters the error.
    assert errors[0] / errors[1] > 3.5 and errors[1] / errors[2] > 3.5
    assert errors[2] < 0.02


def test_lumped_mass_sums_to_area(sphere_mesh):
    pos, face = sphere_mesh
    mass = lumped_mass(pos, face)
    assert mass.shape == (pos.size(0), )
    assert (mass > 0).all()
    assert torch.isclose(mass.sum(), face_areas(pos, face).sum())
    # And the polyhedral area approaches 4 pi.
    assert abs(mass.sum().item() - 4 * math.pi) < 0.1


def test_face_areas_right_triangle():
    pos = torch.tensor([[0., 0, 0], [2, 0, 0], [0, 3, 0]])
    face = torch.tensor([[0], [1], [2]])
    assert face_areas(pos, face).item() == pytest.approx(3.0)
    assert torch.allclose(face_normals(pos, face), torch.tensor([[0., 0, 1]]))


def test_vertex_normals_on_sphere_point_outwards(sphere_mesh):
    pos, face = sphere_mesh
    normal = vertex_normals(pos, face)
    radial = pos / pos.norm(dim=-1, keepdim=True)
    assert ((normal * radial).sum(-1) > 0.999).all()
    assert torch.allclose(normal.norm(dim=-1), torch.ones(pos.size(0),
                                                          dtype=pos.dtype))


def test_mesh_edges_and_manifold_checks(sphere_mesh):
    pos, face = sphere_mesh
    edge_index = mesh_edges(face, pos.size(0))
    num_edges = 3 * face.size(1) // 2
    assert edge_index.size(1) == 2 * num_edges
    # Sorted by centre, both directions present.
    assert (edge_index[1].diff() >= 0).all()
    flipped = set(map(tuple, edge_index.flip(0).t().tolist()))
    assert flipped == set(map(tuple, edge_index.t().tolist()))
    # Euler characteristic of a sphere.
    assert pos.size(0) - num_edges + face.size(1) == 2
    assert is_closed_manifold(face, pos.size(0))
    _, counts = edge_face_counts(face, pos.size(0))
    assert (counts == 2).all()


def test_manifold_check_detects_defects(sphere_mesh):
    pos, face = sphere_mesh
    n = pos.size(0)
    assert not is_closed_manifold(face[:, 1:], n)  # a hole
    flipped = face.clone()
    flipped[[1, 2], 0] = flipped[[2, 1], 0]
    assert not is_closed_manifold(flipped, n)  # inconsistent orientation
    # Two spheres glued at a single vertex: edge-manifold, not vertex-manifold.
    shift = face + n
    shift[shift == n] = 0
    bowtie = torch.cat([face, shift], dim=1)
    assert not is_closed_manifold(bowtie, 2 * n)
    _, grid_face = grid_mesh(4)
    assert not is_closed_manifold(grid_face, 16)  # boundary


def test_remove_unreferenced_and_normalize_area(sphere_mesh):
    pos, face = sphere_mesh
    extra = torch.cat([pos, torch.tensor([[5., 5, 5]], dtype=pos.dtype)])
    with pytest.raises(ValueError, match='not referenced'):
        lumped_mass(extra, face)
    kept, kept_face, index = remove_unreferenced_vertices(extra, face)
    assert torch.equal(kept, pos) and torch.equal(kept_face, face)
    assert torch.equal(index, torch.arange(pos.size(0)))
    moved = normalize_area(3 * pos + 7, face, area=2.0)
    assert face_areas(moved, face).sum().item() == pytest.approx(2.0)
    assert moved.mean(0).abs().max() < 1e-3


def test_degenerate_and_malformed_faces_raise():
    pos = torch.tensor([[0., 0, 0], [1, 0, 0], [2, 0, 0], [0, 1, 0]])
    collinear = torch.tensor([[0], [1], [2]])
    with pytest.raises(ValueError, match='zero-area'):
        cotan_laplacian(pos, collinear)
    with pytest.raises(ValueError, match='zero-area'):
        face_normals(pos, collinear)
    with pytest.raises(ValueError, match='repeat a vertex'):
        cotan_laplacian(pos, torch.tensor([[0], [0], [3]]))
    # areas are defined: a triangle that repeats a vertex has none
    assert face_areas(pos, torch.tensor([[0], [0], [3]])).tolist() == [0.0]
    with pytest.raises(ValueError, match='only 4 vertices'):
        cotan_laplacian(pos, torch.tensor([[0], [1], [4]]))
    with pytest.raises(ValueError, match=r'pass face.t\(\)'):
        cotan_laplacian(pos, torch.tensor([[0, 1, 3], [1, 3, 0]]))
    with pytest.raises(ValueError, match='torch.long'):
        cotan_laplacian(pos, torch.tensor([[0.], [1], [3]]))
    with pytest.raises(ValueError, match='NaN'):
        cotan_laplacian(pos * float('nan'), torch.tensor([[0], [1], [3]]))
    with pytest.raises(ValueError, match='float32 or float64'):
        lumped_mass(pos.long(), torch.tensor([[0], [1], [3]]))
    with pytest.raises(ValueError, match='no triangles'):
        cotan_laplacian(pos, torch.zeros(3, 0, dtype=torch.long))


def test_zero_area_triangles_raise_wherever_areas_are_used():
    from tg_intrinsic.solvers import poisson, smooth, stiffness_and_mass
    from tg_intrinsic.transforms import NormalizeArea
    from torch_geometric.data import Data
    pos, face = icosphere(1)
    # a sliver: a vertex on the midpoint of an edge, in a triangle of its own
    a, b = int(face[0, 0]), int(face[1, 0])
    pos = torch.cat([pos, 0.5 * (pos[a] + pos[b])[None]])
    face = torch.cat([face, torch.tensor([[a], [b], [pos.size(0) - 1]])], 1)
    areas = face_areas(pos, face)  # reports the sliver as 0, to find it
    assert float(areas[-1]) < 1e-15 and bool((areas[:-1] > 0).all())
    data = Data(pos=pos, face=face, x=torch.ones(pos.size(0), 1,
                                                 dtype=pos.dtype))
    for call in (lambda: face_normals(pos, face),
                 lambda: vertex_normals(pos, face),
                 lambda: lumped_mass(pos, face),
                 lambda: cotan_laplacian(pos, face),
                 lambda: normalize_area(pos, face),
                 lambda: NormalizeArea()(data),
                 lambda: stiffness_and_mass(data, robust=False),
                 lambda: smooth(data, 1e-2, robust=False),
                 lambda: poisson(data, 1.0, robust=False)):
        with pytest.raises(ValueError, match='zero-area'):
            call()
    # the robust Laplacian is built for such meshes (intrinsic Delaunay)
    S, m = stiffness_and_mass(data, robust=True)
    assert np.isfinite(S.data).all() and bool((m > 0).all())


def test_laplacian_spectrum_of_the_sphere_and_its_invariances():
    # unit sphere: lambda * area = 4 pi l (l + 1), multiplicity 2l + 1
    from tg_intrinsic.geometry import laplacian_spectrum
    pos, face = icosphere(4)
    spectrum = laplacian_spectrum(pos, face, 15)
    exact = torch.tensor([4 * math.pi * l * (l + 1) for l in (1, 2, 3)
                          for _ in range(2 * l + 1)], dtype=torch.float64)
    assert torch.allclose(spectrum, exact, rtol=0.02)
    # scale and rigid motion leave it unchanged
    g = torch.Generator().manual_seed(0)
    Q, _ = torch.linalg.qr(torch.randn(3, 3, dtype=torch.float64,
                                       generator=g))
    moved = laplacian_spectrum(3.0 * pos @ Q.T + 1.0, face, 15)
    assert torch.allclose(moved, spectrum, rtol=1e-6)
    with pytest.raises(ValueError, match='at most'):
        laplacian_spectrum(*icosphere(0), 11)  # 12 vertices


def triangle_soup():
    """An icosphere as a triangle soup: every face its own 3 vertices."""
    m = trimesh.creation.icosphere(subdivisions=1)
    pos = torch.from_numpy(np.asarray(m.vertices)[np.asarray(m.faces)]
                           .reshape(-1, 3))
    face = torch.arange(pos.size(0)).view(-1, 3).t()
    return pos, face, m


def test_weld_a_triangle_soup():
    pos, face, m = triangle_soup()
    new_pos, new_face, inverse = weld_vertices(pos, face)
    # independent count: trimesh's exact merge
    ref = trimesh.Trimesh(pos.numpy(), face.t().numpy(), process=False)
    ref.merge_vertices(merge_tex=True, merge_norm=True, digits_vertex=12)
    assert new_pos.size(0) == len(ref.vertices) == len(m.vertices) == 42
    assert new_face.shape == face.shape
    assert torch.equal(new_face, inverse[face])
    assert torch.equal(new_pos[inverse], pos)  # every vertex kept its spot
    # faces now share vertices: a closed mesh, each edge in two faces
    welded = trimesh.Trimesh(new_pos.numpy(), new_face.t().numpy(),
                             process=False)
    assert welded.is_watertight
    # new vertices are numbered in order of first occurrence
    first = [int((inverse == k).nonzero()[0]) for k in range(42)]
    assert first == sorted(first)


def test_weld_without_duplicates_is_identity():
    m = trimesh.creation.icosphere(subdivisions=1)
    pos = torch.from_numpy(np.asarray(m.vertices)).float()
    face = torch.from_numpy(np.asarray(m.faces)).t().contiguous()
    new_pos, new_face, inverse = weld_vertices(pos, face)
    assert torch.equal(new_pos, pos) and torch.equal(new_face, face)
    assert torch.equal(inverse, torch.arange(pos.size(0)))
    assert new_pos.dtype == torch.float32


def test_weld_tolerance_and_signed_zero():
    pos, face, _ = triangle_soup()
    gen = torch.Generator().manual_seed(0)
    noisy = pos + 1e-9 * torch.randn(pos.shape, dtype=pos.dtype,
                                     generator=gen)
    assert weld_vertices(noisy, face)[0].size(0) == pos.size(0)
    assert weld_vertices(noisy, face, tolerance=1e-6)[0].size(0) == 42
    # -0.0 and 0.0 are the same position
    p = torch.tensor([[0., 0, 0], [1, 0, 0], [0, 1, 0], [-0., 0, 0]])
    f = torch.tensor([[0, 1, 2], [3, 2, 1]]).t()
    assert weld_vertices(p, f)[2].tolist() == [0, 1, 2, 0]


def test_weld_bad_input():
    pos, face, _ = triangle_soup()
    with pytest.raises(ValueError, match=r'\[3, F\]'):
        weld_vertices(pos, face.t())
    with pytest.raises(ValueError, match='tolerance'):
        weld_vertices(pos, face, tolerance=-1)
