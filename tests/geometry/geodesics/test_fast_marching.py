"""Fast marching against exact geodesics: Euclidean distance on flat
meshes (regular and jittered, where the unfolding update must beat edge
Dijkstra) and great-circle distance on a fine sphere."""
import numpy as np
import pytest
from scipy.sparse.csgraph import dijkstra

from tg_intrinsic.geometry.geodesics.fast_marching import (march_from,
                                                           march_one,
                                                           surface_index)
from tests.conftest import grid_mesh, icosphere


def flat(n=25, jitter=0.0):
    pos, face = grid_mesh(n, jitter=jitter, seed=3)
    return pos.numpy(), np.ascontiguousarray(face.numpy().T)


def edge_dijkstra(pos, face, source):
    import scipy.sparse as sp
    edges = np.concatenate([face[:, [0, 1]], face[:, [1, 2]],
                            face[:, [2, 0]]])
    length = np.linalg.norm(pos[edges[:, 0]] - pos[edges[:, 1]], axis=1)
    graph = sp.coo_matrix((length, (edges[:, 0], edges[:, 1])),
                          shape=(len(pos), len(pos))).tocsr()
    return dijkstra(graph, directed=False, indices=source)


@pytest.mark.parametrize('jitter', [0.0, 0.3])
def test_flat_meshes_give_euclidean_distances(jitter):
    pos, face = flat(jitter=jitter)
    source = int(np.argmin(np.linalg.norm(pos - [0.5, 0.5, 0], axis=1)))
    vertex, dist = march_one(face, surface_index(pos, face), source, 0.4)
    exact = np.linalg.norm(pos[vertex] - pos[source], axis=1)
    error = np.abs(dist - exact)
    # exact on regular grids; within 2 % on strongly jittered ones
    assert np.all(error <= (1e-12 if jitter == 0 else 0.02 * exact + 1e-12))
    # truncation: the vertices closer than the limit, no others
    assert dist.max() < 0.4
    inside = np.flatnonzero(np.linalg.norm(pos - pos[source], axis=1)
                            < (0.4 if jitter == 0 else 0.39))
    assert set(inside) <= set(vertex)
    # plain Dijkstra on edges overestimates by up to ~8 % on grids
    graph = edge_dijkstra(pos, face, source)[vertex]
    assert (graph - exact).max() > 0.05 * 0.4 > error.max()


def test_sphere_gives_great_circle_distances():
    pos, face = icosphere(5)
    pos, face = pos.numpy(), np.ascontiguousarray(face.numpy().T)
    index = surface_index(pos, face)
    vertex, dist = march_one(face, index, 0, 1.0)
    exact = np.arccos(np.clip(pos[vertex] @ pos[0], -1, 1))
    far = exact > 0.2  # first order: relative error shrinks with distance
    assert np.abs(dist[far] - exact[far]).max() / exact[far].max() < 0.02
    # many sources at once equal one source at a time
    sources = np.array([0, 17, 400, 5000])
    ptr, nbr, many = march_from(face, index, sources, 0.3, cap=10 ** 6)
    for k, s in enumerate(sources):
        v, d = march_one(face, index, s, 0.3)
        order = np.argsort(v)
        got = np.argsort(nbr[ptr[k]:ptr[k + 1]])
        assert np.array_equal(nbr[ptr[k]:ptr[k + 1]][got], v[order])
        np.testing.assert_allclose(many[ptr[k]:ptr[k + 1]][got], d[order],
                                   rtol=0, atol=1e-12)
