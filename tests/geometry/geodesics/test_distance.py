import numpy as np
import pytest
import scipy.sparse as sp
import torch
from scipy.sparse.csgraph import dijkstra

from tg_intrinsic.geometry.geodesics.distance import geodesic_distances
from tests.conftest import grid_mesh, icosphere


def edge_dijkstra(pos, face):
    """Shortest paths along the edges (scipy): an upper bound."""
    F = face.t().numpy()
    e = np.concatenate([F[:, [0, 1]], F[:, [1, 2]], F[:, [2, 0]]])
    w = np.linalg.norm(pos.numpy()[e[:, 0]] - pos.numpy()[e[:, 1]], axis=1)
    n = pos.size(0)
    graph = sp.coo_matrix((w, (e[:, 0], e[:, 1])), shape=(n, n)).tocsr()
    return torch.from_numpy(dijkstra(graph, directed=False))


def test_sphere_matches_great_circles():
    pos, face = icosphere(3)
    dist = geodesic_distances(pos, face)
    exact = torch.arccos((pos @ pos.t()).clamp(-1, 1))
    assert dist.shape == (642, 642)
    far = exact > 0.3
    assert ((dist - exact).abs() / exact)[far].max() < 0.04
    assert dist.diagonal().abs().max() == 0
    # shorter than paths along edges, longer than chords
    assert (dist <= edge_dijkstra(pos, face) + 1e-9).all()
    chord = (pos[:, None] - pos[None]).norm(dim=-1)
    assert (dist >= chord - 1e-9).all()
    # better than the edge graph: the oracle would not pass the 4 % bound
    edge = edge_dijkstra(pos, face)
    assert ((edge - exact).abs() / exact)[far].max() > 0.04


def test_plane_is_euclidean_and_sources_select_rows():
    pos, face = grid_mesh(7)
    sources = torch.tensor([10, 3, 40])
    dist = geodesic_distances(pos, face, sources)
    assert dist.shape == (3, 49)
    assert torch.allclose(dist, torch.cdist(pos[sources], pos), atol=1e-9)


def test_disconnected_mesh_is_refused():
    pos, face = icosphere(1)
    pos2 = torch.cat([pos, pos + 3])
    face2 = torch.cat([face, face + pos.size(0)], 1)
    with pytest.raises(ValueError, match='not connected'):
        geodesic_distances(pos2, face2)


def test_bad_faces_are_explained():
    pos, face = icosphere(1)
    with pytest.raises(ValueError, match=r"must have shape \[3, F\]"):
        geodesic_distances(pos, face.t())
    with pytest.raises(ValueError, match="indexes vertices"):
        geodesic_distances(pos, face + 100)
