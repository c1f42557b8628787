import numpy as np
import pytest
import scipy.sparse as sp
import torch
from scipy.sparse.csgraph import dijkstra

from tg_intrinsic.geometry import knn
from tg_intrinsic.geometry.multigrid.voronoi import graph_voronoi


def test_matches_scipy_multi_source_dijkstra():
    gen = torch.Generator().manual_seed(0)
    pos = torch.rand(3000, 3, dtype=torch.float64, generator=gen)
    edge_index = knn(pos, 6, loop=False)
    seeds = torch.randperm(3000, generator=gen)[:40]
    cell, dist = graph_voronoi(pos, edge_index, seeds)
    src, dst = edge_index.numpy()
    length = np.linalg.norm(pos.numpy()[src] - pos.numpy()[dst], axis=1)
    graph = sp.coo_matrix((length, (src, dst)), shape=(3000, 3000)).tocsr()
    ref, _, source = dijkstra(graph, directed=False, indices=seeds.numpy(),
                              min_only=True, return_predecessors=True)
    assert np.allclose(dist.numpy(), ref, rtol=1e-12, atol=1e-12)
    # the seed of every point is at its distance (ties may differ)
    seed_of = seeds.numpy()[cell.numpy()]
    assert (cell[seeds] == torch.arange(40)).all()
    agree = seed_of == source
    assert agree.mean() > 0.999


def test_unreachable_points_and_bad_input():
    pos = torch.rand(6, 3)
    edge_index = torch.tensor([[0, 1, 3, 4], [1, 2, 4, 5]])
    with pytest.raises(ValueError, match='cannot reach any seed'):
        graph_voronoi(pos, edge_index, torch.tensor([0]))
    cell, _ = graph_voronoi(pos, edge_index, torch.tensor([0, 5]))
    assert cell.tolist() == [0, 0, 0, 1, 1, 1]
    with pytest.raises(ValueError, match="'seeds' is empty"):
        graph_voronoi(pos, edge_index, torch.tensor([], dtype=torch.long))
    with pytest.raises(ValueError, match="'seeds' holds .*9"):
        graph_voronoi(pos, edge_index, torch.tensor([9]))
    with pytest.raises(ValueError, match="'edge_index' holds indices"):
        graph_voronoi(pos, edge_index + 3, torch.tensor([0]))


def _scipy_distances(src, dst, length, n, seeds):
    graph = sp.coo_matrix((length, (src, dst)), shape=(n, n)).tocsr()
    return dijkstra(graph, directed=False, indices=seeds, min_only=True)


@pytest.mark.parametrize('spread', [1.0, 1e9])
def test_bucket_queue_and_heap_fallback_match_scipy(spread):
    # Lengths within a small range take the bucket queue; a spread of 1e9
    # would need too many buckets and takes the heap.
    rng = np.random.default_rng(3)
    n = 2000
    src = rng.integers(0, n, 8000)
    dst = rng.integers(0, n, 8000)
    pairs = np.unique(np.sort(np.stack([src, dst], 1), 1), axis=0)
    src, dst = pairs[pairs[:, 0] != pairs[:, 1]].T  # scipy sums repeats
    length = rng.uniform(1.0, 2.0, src.size)
    length[::50] *= 1.0 / spread
    seeds = rng.choice(n, 30, replace=False)
    pos = torch.zeros(n, 3, dtype=torch.float64)
    _, dist = graph_voronoi(pos, torch.from_numpy(np.stack([src, dst])),
                            torch.from_numpy(seeds),
                            edge_length=torch.from_numpy(length))
    ref = _scipy_distances(src, dst, length, n, seeds)
    reach = np.isfinite(ref)
    assert reach.mean() > 0.9
    assert np.allclose(dist.numpy()[reach], ref[reach], rtol=1e-12)


def test_zero_length_edges_and_sweep_starting_distances():
    from tg_intrinsic.geometry.multigrid.voronoi import (_heap_dijkstra_from,
                                                         dijkstra_from)
    rng = np.random.default_rng(4)
    n = 500
    a = rng.integers(0, n, 3000)
    b = rng.integers(0, n, 3000)
    keep = a != b
    a, b = a[keep], b[keep]
    length = rng.uniform(0.5, 1.0, a.size)
    length[::7] = 0.0  # duplicate points
    order = np.argsort(np.concatenate([a, b]), kind='stable')
    indices = np.concatenate([b, a])[order]
    weights = np.concatenate([length, length])[order]
    indptr = np.zeros(n + 1, dtype=np.int64)
    np.cumsum(np.bincount(np.concatenate([a, b]), minlength=n),
              out=indptr[1:])
    seeds = rng.choice(n, 10, replace=False)
    for start in (np.full(n, np.inf), rng.uniform(0.0, 3.0, n)):
        results = []
        for kernel in (dijkstra_from, _heap_dijkstra_from):
            dist, cell = start.copy(), np.full(n, -1, dtype=np.int64)
            kernel(indptr, indices, weights, seeds, dist, cell)
            results.append(dist)
        assert np.array_equal(results[0], results[1])
