"""Gravo MG hierarchies: the sampling sweep, coarse triangles and the
closest-point projection against brute force, the prolongation's
properties on meshes, boundaries, point clouds and several components,
and exact interpolation of linear functions on a plane."""
import itertools

import numpy as np
import pytest
import scipy.sparse as sp
import torch
import trimesh
from scipy.sparse.csgraph import dijkstra

from tg_intrinsic.geometry.multigrid.gravo import (GravoLevel,
                                                   _closest_on_triangle, _csr,
                                                   _triangles,
                                                   gravo_hierarchy,
                                                   gravo_level)

from tests.conftest import grid_mesh


def face_edges(face):
    return np.concatenate([face[:, [0, 1]], face[:, [1, 2]],
                           face[:, [2, 0]]]).T


def sphere(subdivisions=4):
    mesh = trimesh.creation.icosphere(subdivisions=subdivisions)
    return np.asarray(mesh.vertices), np.asarray(mesh.faces, dtype=np.int64)


def knn_edges(points, k=8):
    from scipy.spatial import cKDTree
    _, nbr = cKDTree(points).query(points, k=k + 1)
    return np.stack([nbr[:, 1:].reshape(-1),
                     np.repeat(np.arange(points.shape[0]), k)])


def numpy_level(level):
    return GravoLevel(*(value.numpy() for value in level))


def numpy_levels(levels):
    return [numpy_level(level) for level in levels]


def check_prolongation(level, num_fine):
    rows, cols = level.prolong_index
    assert np.bincount(rows, minlength=num_fine).max() <= 3
    assert (level.prolong_weight > 0).all()
    assert np.abs(np.bincount(rows, level.prolong_weight, num_fine)
                  - 1).max() < 1e-12
    assert np.unique(cols).size == level.sample.size  # every coarse point
    assert np.array_equal(np.unique(rows), np.arange(num_fine))


@pytest.mark.parametrize('case', ['sphere', 'boundary', 'cloud',
                                  'components'])
def test_prolongation_rows_are_partitions_of_unity(case):
    if case == 'sphere':
        pos, face = sphere(5)
        edges = face_edges(face)
    elif case == 'boundary':
        p, f = grid_mesh(60, jitter=0.3)
        pos, edges = p.numpy(), face_edges(f.t().numpy())
    elif case == 'cloud':
        rng = np.random.default_rng(0)
        pos = rng.normal(size=(6000, 3))
        pos /= np.linalg.norm(pos, axis=1, keepdims=True)
        edges = knn_edges(pos)
    else:
        pos, face = sphere(4)
        pos = np.concatenate([pos, pos + 3.0])
        edges = face_edges(np.concatenate([face, face + pos.shape[0] // 2]))
    levels = numpy_levels(gravo_hierarchy(pos, edges, lower_bound=100))
    assert len(levels) >= 1
    num = pos.shape[0]
    for level in levels:
        check_prolongation(level, num)
        # Each level shrinks by roughly the ratio (8).
        assert 4 < num / level.sample.size < 14
        num = level.sample.size
    if case == 'components':
        # Cells and coarse edges never cross between the two spheres.
        half = pos.shape[0] // 2
        first = levels[0]
        side = first.sample >= half
        assert np.array_equal(side[first.cluster], np.arange(pos.shape[0])
                              >= half)
        a, b = first.edge_index
        assert np.array_equal(side[a], side[b])


def test_sampling_sweep_keeps_samples_apart():
    # Brute force over the rule: no sample lies within path length r of an
    # earlier sample along one or two edges (r = 2 x mean edge for ratio 8).
    pos, face = sphere(4)
    edges = face_edges(face)
    level = numpy_level(gravo_level(pos, edges, ratio=8.0))
    n = pos.shape[0]
    indptr, indices = _csr(edges, n)
    length = lambda a, b: np.linalg.norm(pos[a] - pos[b])  # noqa: E731
    r = 2.0 * np.mean([length(a, b) for a, b in edges.T])
    is_sample = np.zeros(n, dtype=bool)
    is_sample[level.sample] = True
    claimed = np.zeros(n, dtype=bool)
    for v in level.sample:
        assert not claimed[v]
        for u in indices[indptr[v]:indptr[v + 1]]:
            if length(v, u) < r:
                claimed[u] = True
                for w in indices[indptr[u]:indptr[u + 1]]:
                    if length(v, u) + length(u, w) < r and w != v:
                        claimed[w] = True
    # ... and every point was claimed or is a sample: none was skipped.
    assert (claimed | is_sample).all()
    assert 5 < n / level.sample.size < 12


def test_sweep_cells_are_a_partial_correction_of_the_exact_ones():
    # voronoi='sweep' keeps the sweep's claims unless the Dijkstra from the
    # samples improves them: same samples, cells that differ from the
    # exact graph Voronoi on a few points (one in 6000 on this cloud; none
    # on icospheres), and a valid prolongation.
    rng = np.random.default_rng(5)
    pos = rng.normal(size=(6000, 3))
    pos /= np.linalg.norm(pos, axis=1, keepdims=True)
    edges = knn_edges(pos)
    exact = numpy_level(gravo_level(pos, edges, voronoi='exact'))
    sweep = numpy_level(gravo_level(pos, edges, voronoi='sweep'))
    assert np.array_equal(exact.sample, sweep.sample)
    differ = np.mean(exact.cluster != sweep.cluster)
    assert 0 < differ < 0.01
    check_prolongation(sweep, pos.shape[0])
    # The exact cells are the closest along the graph; the sweep's are
    # never closer.
    n = pos.shape[0]
    indptr, indices = _csr(edges, n)
    weights = np.linalg.norm(pos[np.repeat(np.arange(n), np.diff(indptr))]
                             - pos[indices], axis=1)
    graph = sp.csr_matrix((weights, indices, indptr), shape=(n, n))
    dist = dijkstra(graph, indices=exact.sample)
    nearest = dist.min(0)
    assert np.allclose(dist[exact.cluster, np.arange(n)], nearest)
    assert (dist[sweep.cluster, np.arange(n)] >= nearest - 1e-12).all()


def test_coarse_triangles_are_all_three_cliques():
    rng = np.random.default_rng(1)
    n = 30
    a, b = np.triu_indices(n, 1)
    pick = rng.random(a.size) < 0.2
    indptr, indices = _csr(np.stack([a[pick], b[pick]]), n)
    found = {tuple(t) for t in _triangles(indptr, indices)}
    adj = np.zeros((n, n), dtype=bool)
    adj[a[pick], b[pick]] = adj[b[pick], a[pick]] = True
    brute = {t for t in itertools.combinations(range(n), 3)
             if adj[t[0], t[1]] and adj[t[1], t[2]] and adj[t[0], t[2]]}
    assert found == brute and len(brute) > 0


def test_closest_point_on_triangle_against_brute_force():
    rng = np.random.default_rng(2)
    s = np.linspace(0, 1, 301)
    u, v = np.meshgrid(s, s, indexing='ij')
    inside = u + v <= 1
    u, v = u[inside], v[inside]
    for _ in range(30):
        a, b, c, p = rng.normal(size=(4, 3))
        p = p * 2
        w = _closest_on_triangle(p, a, b, c)
        q = w[0] * a + w[1] * b + w[2] * c
        grid = (1 - u - v)[:, None] * a + u[:, None] * b + v[:, None] * c
        best = np.linalg.norm(grid - p, axis=1).min()
        assert min(w) >= 0 and abs(sum(w) - 1) < 1e-12
        assert np.linalg.norm(q - p) <= best + 1e-9


def test_linear_functions_are_interpolated_exactly_on_a_plane():
    # Barycentric weights reproduce linear functions wherever the point
    # projects into a coarse triangle, which on a plane is nearly
    # everywhere away from the rim.
    p, f = grid_mesh(70, jitter=0.3, seed=1)
    pos, edges = p.numpy(), face_edges(f.t().numpy())
    level = numpy_level(gravo_level(pos, edges, ratio=8.0, shift=False))
    linear = lambda x: 0.3 + 2.0 * x[:, 0] - 1.5 * x[:, 1]  # noqa: E731
    rows, cols = level.prolong_index
    P = sp.csr_matrix((level.prolong_weight, (rows, cols)),
                      shape=(pos.shape[0], level.sample.size))
    err = np.abs(P @ linear(level.pos) - linear(pos))
    interior = ((pos[:, :2] > 0.1) & (pos[:, :2] < 0.9)).all(1)
    assert np.mean(err[interior] < 1e-12) > 0.95
    # Inverse distance weights are smooth but not exact.
    idw = numpy_level(gravo_level(pos, edges, ratio=8.0, shift=False,
                                  weighting='inverse_distance'))
    rows, cols = idw.prolong_index
    P = sp.csr_matrix((idw.prolong_weight, (rows, cols)),
                      shape=(pos.shape[0], idw.sample.size))
    assert np.mean(np.abs(P @ linear(idw.pos) - linear(pos))[interior]
                   < 1e-12) < 0.5


def test_bad_arguments():
    pos, face = sphere(2)
    with pytest.raises(ValueError, match='weighting'):
        gravo_level(pos, face_edges(face), weighting='linear')
    with pytest.raises(ValueError, match='voronoi'):
        gravo_hierarchy(pos, face_edges(face), voronoi='approximate')
    with pytest.raises(ValueError, match=r"'edge_index' holds indices in "
                                          r"\[1, 162\], outside \[0, 162\)"):
        gravo_level(pos, face_edges(face) + 1)
    with pytest.raises(ValueError, match='NaN'):
        gravo_level(np.full_like(pos, np.nan), face_edges(face))
    with pytest.raises(ValueError, match='no edges'):
        gravo_level(pos, np.zeros((2, 0), dtype=np.int64))
    with pytest.raises(ValueError, match='above 1'):
        gravo_hierarchy(pos, face_edges(face), ratio=1.0)
    assert gravo_hierarchy(pos, face_edges(face), lower_bound=1000) == []


def test_isolated_points_stay_their_own_coarse_point():
    # A point on no edge cannot be interpolated from anything else: it is
    # kept as its own coarse point on every level (weight 1).
    pos, face = sphere(4)
    pos = np.concatenate([pos, [[5.0, 5.0, 5.0]]])
    levels = numpy_levels(gravo_hierarchy(pos, face_edges(face),
                                          lower_bound=30))
    assert len(levels) == 2
    num = pos.shape[0]
    for level in levels:
        check_prolongation(level, num)
        lonely = level.cluster[num - 1]
        assert np.bincount(level.cluster)[lonely] == 1
        rows, cols = level.prolong_index
        assert level.prolong_weight[rows == num - 1].tolist() == [1.0]
        num = level.sample.size


def test_tensors_in_tensors_out():
    pos, face = sphere(4)
    edges = torch.from_numpy(face_edges(face))
    for dtype in (torch.float32, torch.float64):
        levels = gravo_hierarchy(torch.from_numpy(pos).to(dtype), edges,
                                 lower_bound=30)
        assert len(levels) == 2
        for level in levels:
            assert level.pos.dtype == level.prolong_weight.dtype == dtype
            for index in (level.sample, level.cluster, level.edge_index,
                          level.prolong_index):
                assert index.dtype == torch.long
    # the same hierarchy from numpy arrays and from float64 tensors
    ref = gravo_hierarchy(pos, face_edges(face), lower_bound=30)
    for a, b in zip(ref, levels):
        for x, y in zip(a, b):
            assert torch.equal(x, y)
