"""Quadric edge-collapse decimation: the vertex count reached, a closed
manifold of the same topology, determinism, and the self-intersection
count against a brute-force check."""
import numpy as np
import pytest
import torch
import trimesh

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


def mesh_of(tm):
    return np.asarray(tm.vertices, dtype=np.float64), \
        np.asarray(tm.faces, dtype=np.int64)


def test_a_decimated_sphere_stays_a_sphere_and_the_seed_decides():
    V, F = mesh_of(trimesh.creation.icosphere(3))  # 642 vertices
    V2, F2 = decimate(V, F, 100, 0)
    assert V2.shape == (100, 3) and F2.shape == (196, 3)  # F = 2 V - 4
    r = assert_closed_manifold(torch.tensor(V2), torch.tensor(F2).t())
    radius = np.linalg.norm(V2, axis=1)
    assert np.abs(radius - 1).max() < 0.05
    assert r['volume'] == pytest.approx(4 / 3 * np.pi, rel=0.05)
    again = decimate(V, F, 100, 0)  # deterministic for a seed
    assert np.array_equal(again[0], V2) and np.array_equal(again[1], F2)
    other = decimate(V, F, 100, 1)
    assert len(other[0]) == 100 and not np.array_equal(other[0], V2)
    # the input arrays are not changed
    V0, F0 = mesh_of(trimesh.creation.icosphere(3))
    assert np.array_equal(V, V0) and np.array_equal(F, F0)


def test_against_fast_simplification():
    fast = pytest.importorskip('fast_simplification')
    V, F = mesh_of(trimesh.creation.icosphere(3))
    ours = decimate(V, F, 100, 0)
    Vf, Ff = fast.simplify(V.astype(np.float32), F.astype(np.int32),
                           target_count=196)
    theirs = (np.asarray(Vf, np.float64), np.asarray(Ff, np.int64))
    assert len(theirs[0]) == len(ours[0]) == 100
    volume = [manifold_report(torch.tensor(v), torch.tensor(f).t())[
        'volume'] for v, f in (ours, theirs)]
    assert volume[0] == pytest.approx(volume[1], rel=0.01)
    error = [np.abs(np.linalg.norm(v, axis=1) - 1).max()
             for v, _ in (ours, theirs)]
    assert error[0] < 2 * error[1]  # about as close to the sphere


def test_flat_faces_and_corners_stay_exactly_where_they_are():
    # each vertex's quadric holds the planes of its faces: on a face the
    # optimum stays in that plane, on an edge on both, a corner is fixed
    V, F = mesh_of(trimesh.creation.box().subdivide().subdivide()
                   .subdivide())  # 386 vertices on the unit cube
    V2, F2 = decimate(V, F, 40, 0)
    assert len(V2) == 40
    assert np.abs(np.abs(V2).max(1) - 0.5).max() < 1e-12  # on the surface
    r = assert_closed_manifold(torch.tensor(V2), torch.tensor(F2).t())
    assert r['volume'] == pytest.approx(1.0, abs=1e-12)
    assert r['area'] == pytest.approx(6.0, abs=1e-12)
    corners = {tuple(c) for c in V2 if (np.abs(np.abs(c) - 0.5) < 1e-12)
               .all()}
    assert len(corners) == 8


def test_the_genus_is_kept():
    V, F = mesh_of(trimesh.creation.torus(1.0, 0.3, major_sections=48,
                                          minor_sections=16))
    V2, F2 = decimate(V, F, 200, 0)
    r = manifold_report(torch.tensor(V2), torch.tensor(F2).t())
    assert len(V2) == 200 and r['euler'] == 0 and r['components'] == 1
    assert r['edges_in_two_faces'] and r['vertex_manifold']
    assert self_intersections(V2, F2) == 0


def test_a_target_at_or_above_the_vertex_count_changes_nothing():
    V, F = mesh_of(trimesh.creation.icosphere(2))
    for target in (len(V), 10 * len(V)):
        V2, F2 = decimate(V, F, target, 0)
        assert np.array_equal(V2, V) and np.array_equal(F2, F)
    # a tetrahedron cannot lose a vertex and stay closed
    tet = mesh_of(trimesh.creation.icosphere(0))[0][:4]
    face = np.array([[0, 2, 1], [0, 1, 3], [1, 2, 3], [0, 3, 2]])
    assert len(decimate(tet, face, 1, 0)[0]) == 4


def test_self_intersections_agree_with_brute_force_on_two_spheres():
    V, F = mesh_of(trimesh.creation.icosphere(2))
    for offset, crossing in ((0.6, True), (2.5, False)):
        W = np.concatenate([V, V + [offset, 0.1, 0.05]])
        G = np.concatenate([F, F + len(V)])
        count = self_intersections(W, G)
        assert (count > 0) == crossing
        assert count == self_intersecting_pairs(torch.tensor(W),
                                                torch.tensor(G).t())
