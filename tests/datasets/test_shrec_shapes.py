"""The articulated shapes of SyntheticSHREC: rotations and frames against
scipy, bone chains, every class's primitives (deterministic per seed,
posed by rigid bones), the mesh helpers (topology, normals, relaxation,
noise, random rotations) and whole shapes: closed genus-0 meshes of the
requested size, unit area, centred."""
import numpy as np
import pytest
import torch
import trimesh
from scipy.spatial.transform import Rotation

from tg_intrinsic.datasets import implicit_surfaces as imp
from tg_intrinsic.datasets import shrec_shapes as shapes
from tg_intrinsic.datasets.quadric_decimation import decimate
from tests.datasets.conftest import (assert_closed_manifold,
                                     self_intersecting_pairs)

O = imp.NUM_HEAD
CLASSES = sorted(shapes.CLASSES)


def mesh_of(tm):
    return np.asarray(tm.vertices, np.float64), np.asarray(tm.faces,
                                                           np.int64)


def triangle_quality(V, F):
    """1 for an equilateral triangle, 0 for a degenerate one."""
    a, b, c = V[F[:, 0]], V[F[:, 1]], V[F[:, 2]]
    twice_area = np.linalg.norm(np.cross(b - a, c - a), axis=1)
    squares = ((b - a) ** 2 + (c - b) ** 2 + (a - c) ** 2).sum(1)
    return 2 * np.sqrt(3) * twice_area / squares


# --- rotations and frames ----------------------------------------------------


def test_rot_is_the_rotation_about_the_axis():
    rng = np.random.default_rng(0)
    for _ in range(20):
        axis, angle = rng.standard_normal(3), rng.uniform(-7, 7)
        expected = Rotation.from_rotvec(axis / np.linalg.norm(axis) * angle)
        assert np.allclose(shapes.rot(axis * 3.0, angle),
                           expected.as_matrix(), atol=1e-12)


@pytest.mark.parametrize('d,up', [([1.0, 0.2, -0.3], (0, 0, 1)),
                                  ([0, 0, -2.0], (0, 0, 1)),  # along up
                                  ([0.3, 0.1, 5.0], (0, 0, 1)),
                                  ([1.0, 0, 0], (1.0, 0, 0))])
def test_frame_from(d, up):
    frame = shapes.frame_from(d, up)
    assert np.allclose(frame @ frame.T, np.eye(3), atol=1e-12)
    assert np.linalg.det(frame) == pytest.approx(1.0)
    assert np.allclose(frame[0], np.asarray(d) / np.linalg.norm(d))
    up = np.asarray(up, float)
    if abs(frame[0] @ up) < 0.95 * np.linalg.norm(up):
        # the second row is up, made perpendicular to d
        assert np.linalg.det(np.stack([frame[0], frame[1], up])) == \
            pytest.approx(0.0, abs=1e-12)
        assert frame[1] @ up > 0


# --- bone chains ---------------------------------------------------------------


def test_a_straight_chain_and_a_bent_one():
    b = shapes.Builder(blend=0.5)
    frame = shapes.frame_from([1.0, 0, 0])
    end, out = b.chain([0, 0, 1.0], frame, [0.5, 0.3, 0.2],
                       [0.2, 0.15, 0.1, 0.05], [2, 3, 4])
    rows = b.array()
    assert rows.shape == (3, imp.NUM_COLS) and rows[:, 1].tolist() == [2, 3,
                                                                        4]
    assert np.allclose(end, [1.0, 0, 1.0]) and np.allclose(out, frame)
    # consecutive bones share their joints, radii run along the chain
    assert np.allclose(rows[:, O:O + 3], [[0, 0, 1], [0.5, 0, 1],
                                          [0.8, 0, 1]])
    assert np.allclose(rows[:, O + 3:O + 6], [[0.5, 0, 1], [0.8, 0, 1],
                                              [1.0, 0, 1]])
    assert rows[:, O + 6].tolist() == [0.2, 0.15, 0.1]
    assert rows[:, O + 7].tolist() == [0.15, 0.1, 0.05]
    assert np.allclose(rows[:, 2], 0.5 * np.minimum(rows[:, O + 6],
                                                    rows[:, O + 7]))
    # a quarter turn about the hinge before the second bone
    b = shapes.Builder()
    end, out = b.chain(np.zeros(3), frame, [1.0, 1.0], [0.1] * 3, 0,
                       alphas=np.array([0, np.pi / 2]))
    first, second = (r[O + 3:O + 6] - r[O:O + 3] for r in b.array())
    assert abs(first @ second) < 1e-12  # perpendicular
    assert abs(second @ frame[1]) < 1e-12  # turned about the hinge
    assert np.allclose(end, first + second)
    assert np.allclose(out @ out.T, np.eye(3), atol=1e-12)
    assert np.allclose(out[0], second)


# --- the classes -----------------------------------------------------------------


@pytest.mark.parametrize('name', CLASSES)
def test_a_class_is_deterministic_and_posed_by_rigid_bones(name):
    build = shapes.CLASSES[name]
    rest = build(np.random.default_rng(5), 0.0)
    posed = build(np.random.default_rng(5), 1.0)
    assert np.array_equal(posed, build(np.random.default_rng(5), 1.0))
    other = build(np.random.default_rng(6), 1.0)
    assert other.shape != posed.shape or not np.allclose(other, posed)
    assert rest.shape[1] == imp.NUM_COLS
    assert set(rest[:, 0]) <= {imp.CONE, imp.ELLIPSOID}
    labels = set(rest[:, 1].astype(int))
    assert labels <= set(range(len(shapes.PART_NAMES))) and len(labels) > 1
    # the same instance in another pose: the same parts and sizes, moved
    assert posed.shape == rest.shape
    assert np.array_equal(posed[:, :3], rest[:, :3])  # kind, label, blend
    assert not np.allclose(posed[:, 3:6], rest[:, 3:6])
    cone = rest[:, 0] == imp.CONE
    assert np.allclose(posed[cone, O + 6:O + 8], rest[cone, O + 6:O + 8])
    assert np.allclose(posed[~cone, O + 3:O + 6], rest[~cone, O + 3:O + 6])


def bone_lengths(rows):
    cone = rows[:, 0] == imp.CONE
    return np.linalg.norm(rows[cone, O + 3:O + 6] - rows[cone, O:O + 3],
                          axis=1)


RIGIDITY = {
    'dinosaur': "the knee is offset by a fixed world vector (0.08, 0, 0) "
                "that does not swing with the thigh: up to 13 % longer or "
                "shorter",
    'human': "the neck cone ends at neck + 0.08 hd, so nodding the head "
             "changes its length by up to 3 %"}


@pytest.mark.parametrize('name', [
    pytest.param(name, marks=pytest.mark.xfail(reason=RIGIDITY[name],
                                                strict=True))
    if name in RIGIDITY else name for name in CLASSES])
def test_every_bone_keeps_its_length_in_every_pose(name):
    # 'Bones are rigid, so a new pose bends the surface at the joints
    # only: poses of one instance are near-isometric.'
    for seed in range(5):
        rest = shapes.CLASSES[name](np.random.default_rng(seed), 0.0)
        for pose in (0.5, 1.0):
            posed = shapes.CLASSES[name](np.random.default_rng(seed), pose)
            assert np.allclose(bone_lengths(posed), bone_lengths(rest),
                               rtol=1e-9, atol=0)


# --- mesh helpers --------------------------------------------------------------


def test_mesh_topology():
    V, F = mesh_of(trimesh.creation.icosphere(1))
    assert shapes.mesh_topology(V, F) == (1, 2)
    two = (np.concatenate([V, V + 3]), np.concatenate([F, F + len(V)]))
    assert shapes.mesh_topology(*two) == (2, 4)
    torus = mesh_of(trimesh.creation.torus(1.0, 0.3))
    assert shapes.mesh_topology(*torus) == (1, 0)


def test_vertex_normals_point_out_of_a_sphere():
    V, F = mesh_of(trimesh.creation.icosphere(2))
    normal = shapes.vertex_normals_np(V, F)
    assert np.allclose(np.linalg.norm(normal, axis=1), 1)
    assert ((normal * V).sum(1) > 0.99).all()  # radial
    assert np.allclose(shapes.vertex_normals_np(V, F[:, ::-1]), -normal)


def test_relax_improves_triangles_and_stays_on_the_surface():
    P = np.stack([imp.ellipsoid(np.zeros(3), [0.5, 0.4, 0.3], np.eye(3), 0,
                                0.1)])
    V, F = decimate(*shapes.extract_surface(P, 1500), 200, 0)
    normal = shapes.vertex_normals_np(V, F)
    jitter = 0.02 * np.random.default_rng(0).standard_normal(V.shape)
    W = V + jitter - (jitter * normal).sum(1, keepdims=True) * normal
    R = shapes.relax(W, F, P)
    moved = np.linalg.norm(R - W, axis=1) > 0
    assert moved.mean() > 0.5
    # moved vertices are back on the zero set (a Newton step each
    # iteration), the others were held to keep triangles from flipping
    assert np.abs(imp.eval_points(P, R[moved])).max() < 1e-6
    assert np.median(np.abs(imp.eval_points(P, W))) > 1e-3
    assert triangle_quality(R, F).mean() > triangle_quality(W, F).mean() \
        + 0.05
    before = np.cross(W[F[:, 1]] - W[F[:, 0]], W[F[:, 2]] - W[F[:, 0]])
    after = np.cross(R[F[:, 1]] - R[F[:, 0]], R[F[:, 2]] - R[F[:, 0]])
    assert ((before * after).sum(1) > 0).all()


def test_normal_noise_moves_along_normals_by_the_local_edge_length():
    V, F = mesh_of(trimesh.creation.icosphere(2))
    V = V * [1.0, 1.0, 0.5]  # edges of different lengths
    assert shapes.add_normal_noise(V, F, 0.0, None) is V
    moved = shapes.add_normal_noise(V, F, 0.1, np.random.default_rng(0))
    again = shapes.add_normal_noise(V, F, 0.1, np.random.default_rng(0))
    other = shapes.add_normal_noise(V, F, 0.1, np.random.default_rng(1))
    assert np.array_equal(moved, again) and not np.allclose(moved, other)
    step = moved - V
    normal = shapes.vertex_normals_np(V, F)
    assert np.abs(np.cross(step, normal)).max() < 1e-12
    edges = np.concatenate([F[:, [0, 1]], F[:, [1, 2]], F[:, [2, 0]]])
    length = np.linalg.norm(V[edges[:, 0]] - V[edges[:, 1]], axis=1)
    shortest = np.full(len(V), np.inf)
    np.minimum.at(shortest, edges[:, 0], length)
    np.minimum.at(shortest, edges[:, 1], length)
    size = np.linalg.norm(step, axis=1) / (0.1 * shortest)
    assert size.max() <= 2.5 + 1e-9  # clipped normal samples
    assert 0.6 < np.sqrt((size ** 2).mean()) < 1.2  # about unit variance


def test_random_rotations_are_rotations_spread_over_so3():
    rng = np.random.default_rng(0)
    R = np.stack([shapes.random_rotation(rng) for _ in range(2000)])
    assert np.allclose(R @ R.transpose(0, 2, 1), np.eye(3), atol=1e-12)
    assert np.allclose(np.linalg.det(R), 1)
    assert np.abs(R.mean(0)).max() < 0.05  # the Haar mean is zero
    assert np.array_equal(shapes.random_rotation(np.random.default_rng(3)),
                          shapes.random_rotation(np.random.default_rng(3)))


# --- whole shapes ----------------------------------------------------------------


@pytest.mark.parametrize('name', ['hand', 'snake', 'octopus'])
def test_make_shape(name):
    V, F, labels = shapes.make_shape(name, np.random.default_rng(0), 150,
                                     fine_vertices=450)
    assert V.shape == (150, 3) and F.shape == (296, 3)
    r = assert_closed_manifold(torch.tensor(V), torch.tensor(F).t())
    assert r['area'] == pytest.approx(1.0)  # unit total area
    area = 0.5 * np.linalg.norm(np.cross(V[F[:, 1]] - V[F[:, 0]],
                                         V[F[:, 2]] - V[F[:, 0]]), axis=1)
    centroid = (area[:, None] * V[F].mean(1)).sum(0)
    assert np.abs(centroid).max() < 1e-12
    assert self_intersecting_pairs(torch.tensor(V), torch.tensor(F).t()) == 0
    assert labels.shape == (150, ) and labels.dtype == np.int64
    assert 0 <= labels.min() and labels.max() < len(shapes.PART_NAMES)
    assert len(np.unique(labels)) > 1
    same = shapes.make_shape(name, np.random.default_rng(0), 150,
                             fine_vertices=450)
    assert all(np.array_equal(a, b) for a, b in zip(same, (V, F, labels)))
    other = shapes.make_shape(name, np.random.default_rng(1), 150,
                              fine_vertices=450)
    assert not np.allclose(other[0], V)
    # without the final random rotation: the same shape, turned
    upright, F2, labels2 = shapes.make_shape(
        name, np.random.default_rng(0), 150, fine_vertices=450,
        rotate=False)
    assert np.array_equal(F2, F) and np.array_equal(labels2, labels)
    assert not np.allclose(upright, V)
    assert np.allclose(upright @ upright.T, V @ V.T, atol=1e-12)
