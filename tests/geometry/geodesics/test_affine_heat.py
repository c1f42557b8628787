"""The affine vector heat back end of log_map(method='vector_heat') on
meshes: the multi-column sparse solves against scipy, the intrinsic
Delaunay triangulation against flat geometry, and the whole method against
potpourri3d's (geometry-central's) global per-vertex solves."""
import importlib.util

import numpy as np
import pytest
import scipy.sparse as sp
import torch
from scipy.sparse.linalg import spsolve

from tg_intrinsic.geometry import (geodesic_neighbourhoods, log_map,
                                   tangent_frames, vertex_normals)
from tg_intrinsic.geometry.geodesics import vector_heat as _vector_heat
from tg_intrinsic.geometry.geodesics.affine_heat import (AffineHeatPatch,
                                                MeshTangentData, SparseLU)

from tests.conftest import grid_mesh, icosphere
from tests.geometry.geodesics.test_logmap import sphere_truth


def wrap(angle):
    return np.mod(angle + np.pi, 2 * np.pi) - np.pi


def jittered_sphere(subdivisions=3, jitter=0.1, bumps=True, seed=0):
    """An icosphere whose vertices are pushed along the surface, so that
    many triangles are obtuse (negative cotan weights); with smooth radial
    bumps, or on the unit sphere."""
    pos, face = icosphere(subdivisions)
    g = torch.Generator().manual_seed(seed)
    step = jitter * 2.0 / 2 ** subdivisions
    pos = pos + step * torch.randn(pos.shape, generator=g, dtype=pos.dtype)
    pos = pos / pos.norm(dim=1, keepdim=True)
    if not bumps:
        return pos, face
    x, y, z = pos.unbind(-1)
    bump = 1 + 0.15 * torch.sin(3 * x) * torch.cos(2 * y + z)
    return pos * bump[:, None], face


def tangent_data(pos, face, delaunay=True):
    frame = tangent_frames(vertex_normals(pos, face))
    return MeshTangentData(pos.numpy(), face.t().contiguous().numpy(),
                           frame.numpy(), delaunay=delaunay)


@pytest.mark.parametrize('dtype', [np.float64, np.complex128])
def test_sparse_lu_solves_blocks_like_scipy(dtype):
    rng = np.random.default_rng(0)
    n = 300
    a = sp.random(n, n, density=0.02, random_state=0, format='csr')
    if dtype == np.complex128:
        a = a + 1j * sp.random(n, n, density=0.02, random_state=1)
    a = (a + sp.diags(np.full(n, 4.0))).astype(dtype).tocsc()
    rhs = rng.normal(size=(n, 7)).astype(dtype)
    if dtype == np.complex128:
        rhs = rhs + 1j * rng.normal(size=(n, 7))
    ours = SparseLU(a).solve(rhs)
    assert np.abs(ours - spsolve(a, rhs)).max() < 1e-12


def test_intrinsic_delaunay_on_a_flat_mesh_is_straight():
    # On a flat mesh every intrinsic edge is a straight segment of the
    # plane: its length and direction (in the frame e_u = x, e_v = y) are
    # those of the chord between its end points.
    pos, face = grid_mesh(12, jitter=0.45, seed=3)
    frame = np.broadcast_to(np.eye(3), (pos.size(0), 3, 3)).copy()
    data = MeshTangentData(pos.numpy(), face.t().contiguous().numpy(), frame)
    assert data.flips > 0
    v, b = data.face.reshape(-1), np.roll(data.face, -1, axis=1).reshape(-1)
    chord = (pos[b] - pos[v]).numpy()
    assert np.abs(data.length_first - np.linalg.norm(chord, axis=1)).max() \
        < 1e-12
    ours = data.offset[v] + data.sign[v] * np.angle(data.dir_first)
    assert np.abs(wrap(ours - np.arctan2(chord[:, 1], chord[:, 0]))).max() \
        < 1e-10
    # Flips keep the area, and leave no negative cotan weight.
    assert abs(data.mass.sum() - 1.0) < 1e-12
    row, col, weight, _, _ = data.edge_terms(np.arange(data.face.shape[0]))
    n = pos.size(0)
    edge_weight = np.bincount(row * n + col, weights=weight)
    boundary = np.zeros(n, dtype=bool)
    on = (pos[:, 0] == 0) | (pos[:, 0] == 1) | (pos[:, 1] == 0) \
        | (pos[:, 1] == 1)
    boundary[on.numpy()] = True
    interior = ~(boundary[np.arange(edge_weight.size) // n]
                 & boundary[np.arange(edge_weight.size) % n])
    assert edge_weight[interior & (edge_weight != 0)].min() > -1e-12
    # Without the flips this mesh has negative weights.
    plain = MeshTangentData(pos.numpy(), face.t().contiguous().numpy(),
                            frame, delaunay=False)
    _, _, weight, _, _ = plain.edge_terms(np.arange(face.size(1)))
    assert weight.min() < 0 and plain.flips == 0


def test_signposts_agree_around_every_vertex():
    # Each directed intrinsic edge is the first edge of one corner and the
    # second edge of the next one around its tail: both give one direction.
    # (Intrinsic triangulations may hold two edges between one pair of
    # vertices; those are left out of the lookup.)
    pos, face = jittered_sphere()
    data = tangent_data(pos, face)
    assert data.flips > 0
    f = data.face
    n = pos.size(0)
    first = f[:, [0, 1, 2]].reshape(-1) * n + f[:, [1, 2, 0]].reshape(-1)
    second = f[:, [0, 1, 2]].reshape(-1) * n + f[:, [2, 0, 1]].reshape(-1)
    keys, count = np.unique(first, return_counts=True)
    single = np.isin(second, keys[count == 1])
    assert single.mean() > 0.95
    order = np.argsort(first)
    at = order[np.searchsorted(first[order], second[single])]
    assert np.array_equal(first[at], second[single])
    assert np.abs(data.dir_first[at] - data.dir_second[single]).max() < 1e-9
    assert np.abs(data.length_first[at]
                  - data.length_second[single]).max() < 1e-12
    # The tangent spaces close up: directions turn by 2 pi around a vertex.
    total = np.bincount(f.reshape(-1), weights=np.angle(
        data.dir_second / data.dir_first) % (2 * np.pi), minlength=n)
    assert np.abs(total - 2 * np.pi).max() < 1e-9


def test_patch_is_the_whole_mesh_solve_restricted():
    # Heat from a source decays fast: a patch of the triangles near it
    # gives nearly the whole-mesh answer there, and the whole set of
    # triangles gives exactly the same as one big patch.
    pos, face = jittered_sphere()
    data = tangent_data(pos, face)
    time = data.mean_edge ** 2
    everything = AffineHeatPatch(data, np.arange(data.face.shape[0]), time)
    edge_index, _ = geodesic_neighbourhoods(pos, 0.3, face=face,
                                            centers=torch.tensor([5, 77]))
    j, i = edge_index.numpy()
    ptr = np.array([0, int((i == 5).sum()), i.size])
    whole = everything.solve(np.array([5, 77]), ptr, j)
    threaded = everything.solve(np.array([5, 77]), ptr, j, threads=2)
    for a, b in zip(whole, threaded):
        assert np.array_equal(a, b)
    near = np.linalg.norm(pos.numpy() - pos[[5, 77]].numpy()[:, None],
                          axis=2).min(0) < 0.9
    faces = np.flatnonzero(near[data.face].all(1))
    local = AffineHeatPatch(data, faces, time).solve(np.array([5, 77]),
                                                      ptr, j)
    off = i != j  # the angle of the centre itself is undefined
    assert np.abs(local[0] - whole[0]).max() < 1e-3 * 0.3
    assert np.abs(wrap(local[1] - whole[1]))[off].max() < 1e-3
    assert np.abs(wrap(local[2] - whole[2]))[off].max() < 1e-3


@pytest.mark.skipif(importlib.util.find_spec('potpourri3d') is None,
                    reason='compares with potpourri3d')
def test_matches_potpourri3d_global_solves():
    # The original approach: geometry-central's AffineLocal log map and
    # vector transport, one global solve per centre, on its intrinsic
    # Delaunay triangulation. On a jittered unit sphere (obtuse triangles,
    # edge flips) the radii agree to round-off, and both are as close to
    # the analytic answer. (The angles differ by which direction each
    # vertex's tangent space calls 0: we align it with all its edges,
    # geometry-central with one.)
    import potpourri3d as pp3d
    pos, face = jittered_sphere(bumps=False)
    assert tangent_data(pos, face).flips > 0
    frame = tangent_frames(pos)
    eps = 0.5
    edge_index, _ = geodesic_neighbourhoods(pos, eps, face=face)
    ours = [t.numpy() for t in log_map(pos, edge_index, frame, face=face,
                                       method='vector_heat', workers=1)]
    V, F = pos.numpy(), face.t().contiguous().numpy()
    j, i = edge_index.numpy()
    centres, start = np.unique(i, return_index=True)
    solver = pp3d.MeshVectorHeatSolver(V, F)
    basis_x, _, basis_n = solver.get_tangent_frames()
    conv = _vector_heat._mesh_conversion(V, F, np.arange(V.shape[0]),
                                         frame.numpy(), basis_x, basis_n)
    theirs = _vector_heat._solve_centres(
        solver, conv, _vector_heat._log_map_kwargs(), centres, j,
        np.append(start, i.size), np.zeros(i.size))
    assert np.abs(ours[0] - theirs[0]).max() < 1e-8 * eps
    truth = [t.numpy() for t in sphere_truth(pos, frame, edge_index)]
    off = i != j
    for k in (1, 2):
        err_ours = np.abs(wrap(ours[k] - truth[k]))[off]
        err_theirs = np.abs(wrap(theirs[k] - truth[k]))[off]
        assert np.quantile(err_ours, 0.99) < 1.1 * np.quantile(err_theirs,
                                                               0.99)
        assert err_ours.max() < 1.1 * err_theirs.max()
        assert err_ours.max() < 1e-2
