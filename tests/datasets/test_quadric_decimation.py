"""Quadric edge-collapse decimation: the vertex count reached, a closed
manifold of the same topology, determinism, and the self-intersection
count against a brute-force check."""
import numpy as np
import torch

from tg_intrinsic.datasets import shrec_shapes as shapes
from tg_intrinsic.datasets.quadric_decimation import (decimate,
                                                      self_intersections)
from tests.datasets.conftest import (assert_closed_manifold, manifold_report,
                                     self_intersecting_pairs)


def test_manifold_checker_catches_defects():
    pos = torch.tensor(np.random.default_rng(0).normal(size=(4, 3)))
    face = torch.tensor([[0, 1, 2], [0, 3, 1], [1, 3, 2], [0, 2, 3]]).t()
    r = manifold_report(pos, face)
    assert r['edges_in_two_faces'] and r['vertex_manifold']
    assert r['euler'] == 2
    flipped = face.clone()
    flipped[[1, 2], 0] = flipped[[2, 1], 0]
    assert not manifold_report(pos, flipped)['every_edge_has_twin']
    # two tetrahedra glued at one vertex: edges fine, vertex not manifold
    pos2 = torch.cat([pos, pos[1:] + 5])
    face2 = torch.cat([face, torch.where(face == 0, 0, face + 3)], 1)
    r2 = manifold_report(pos2, face2)
    assert r2['edges_in_two_faces'] and not r2['vertex_manifold']


def test_decimate_keeps_manifold_and_reaches_target():
    rng = np.random.default_rng(0)
    P = shapes.CLASSES['human'](rng, 0.0)  # rest pose: contact free
    V, F = shapes.extract_surface(P)
    assert shapes.mesh_topology(V, F) == (1, 2) and len(V) > 3000
    for target in (500, 1234):
        V2, F2 = decimate(V, F, target, 3)
        assert len(V2) == target and len(F2) == 2 * target - 4
        assert_closed_manifold(torch.tensor(V2), torch.tensor(F2).t())
        again = decimate(V, F, target, 3)
        assert np.array_equal(again[0], V2) and np.array_equal(again[1], F2)


def test_self_intersection_checks():
    import trimesh
    m = trimesh.creation.icosphere(2)
    V, F = np.asarray(m.vertices), np.asarray(m.faces)
    assert self_intersections(V, F) == 0
    assert self_intersecting_pairs(torch.tensor(V), torch.tensor(F).t()) == 0
    # slide a vertex past its neighbour: its fan folds over the neighbour's
    n1 = F[(F == 0).any(1)][0]
    n1 = n1[n1 != 0][0]
    W = V.copy()
    W[0] = V[n1] + 0.8 * (V[n1] - V[0])
    assert self_intersections(W, F) > 0
    assert self_intersecting_pairs(torch.tensor(W), torch.tensor(F).t()) > 0
    # and push a vertex through the far side of the sphere
    W = V.copy()
    W[0] = -1.3 * V[0]
    assert self_intersections(W, F) > 0
    assert self_intersecting_pairs(torch.tensor(W), torch.tensor(F).t()) > 0
