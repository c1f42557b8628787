import numpy as np
import pytest
import scipy.sparse as sp
import torch
from scipy.sparse.csgraph import dijkstra

from tg_intrinsic.geometry import knn
from tg_intrinsic.geometry.voronoi import graph_voronoi


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
    with pytest.raises(ValueError, match="must index the 6 points"):
        graph_voronoi(pos, edge_index, torch.tensor([9]))
