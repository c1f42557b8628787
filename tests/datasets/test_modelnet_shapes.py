"""The rigid objects of SyntheticModelNet: samples on their triangles
with those triangles' outward normals, hidden and contact samples
removed."""
import numpy as np

from tg_intrinsic.datasets import modelnet_shapes as shapes


def test_sampled_normals_are_triangle_normals():
    rng = np.random.default_rng(0)
    parts = shapes.CLASSES['chair'](rng)
    V, F, _ = shapes.shape_mesh(parts)
    pts, nrm, fid = shapes.sample_surface(parts, 2000, rng)
    a, b, c = V[F[fid, 0]], V[F[fid, 1]], V[F[fid, 2]]
    # on the plane of the triangle it came from, inside the triangle
    assert np.abs(((pts - a) * nrm).sum(1)).max() < 1e-9
    assert np.abs((nrm * (b - a)).sum(1)).max() < 1e-9
    assert np.abs((nrm * (c - a)).sum(1)).max() < 1e-9
    n = np.cross(b - a, c - a)
    for p, q in ((a, b), (b, c), (c, a)):
        assert (np.einsum('ij,ij->i', np.cross(q - p, pts - p), n)
                >= -1e-12).all()


def test_normals_of_known_primitives():
    rng = np.random.default_rng(1)
    # a sphere: outward, close to radial (facet normals of the UV sphere)
    c = np.array([0.3, -0.2, 0.5])
    pts, nrm, _ = shapes.sample_surface([shapes.ellipsoid(c, [0.7] * 3)],
                                        3000, rng)
    radial = (pts - c) / np.linalg.norm(pts - c, axis=1, keepdims=True)
    assert (np.abs(np.linalg.norm(pts - c, axis=1) - 0.7) < 0.03).all()
    assert ((radial * nrm).sum(1) > 0.97).all()
    # a rotated box: normals are +- its axes, outward
    box = shapes.box([0, 0, 1.0], [1.0, 2.0, 0.5], yaw=0.4)
    pts, nrm, _ = shapes.sample_surface([box], 3000, rng)
    local = (pts - box.t) @ np.linalg.inv(box.A).T
    lnrm = nrm @ box.A  # axes of the box frame (up to scale)
    lnrm /= np.linalg.norm(lnrm, axis=1, keepdims=True)
    axis = np.abs(lnrm).argmax(1)
    assert np.allclose(np.abs(lnrm).max(1), 1.0, atol=1e-9)
    on_face = np.abs(local[np.arange(len(pts)), axis])
    assert np.allclose(on_face, 1.0, atol=1e-9)
    assert (np.sign(local[np.arange(len(pts)), axis])
            == np.sign(lnrm[np.arange(len(pts)), axis])).all()
    # a cup's inner wall faces the axis, the outer wall away from it
    cup = shapes.tube([0, 0, 0], 1.0, 0.8, 1.0)
    pts, nrm, _ = shapes.sample_surface([cup], 3000, rng)
    rho = np.linalg.norm(pts[:, :2], axis=1)
    radial = (pts[:, :2] * nrm[:, :2]).sum(1) / rho
    side = np.abs(nrm[:, 2]) < 0.5
    assert (radial[side & (rho > 0.9)] > 0.97).all()
    assert (radial[side & (rho < 0.9)] < -0.97).all()


def test_hidden_samples_are_removed():
    rng = np.random.default_rng(2)
    a = shapes.box([0, 0, 0], [2.0, 2.0, 2.0])
    b = shapes.box([1.0, 0, 0], [2.0, 1.0, 1.0])
    pts, _, _ = shapes.sample_surface([a, b], 4000, rng)
    inside_a = (np.abs(pts) < 1 - 1e-6).all(1)
    inside_b = (np.abs(pts - [1.0, 0, 0]) < [1 - 1e-6, 0.5 - 1e-6,
                                             0.5 - 1e-6]).all(1)
    assert not inside_a.any() and not inside_b.any()


def test_contact_faces_between_touching_parts_are_removed():
    # A box standing on another (like a mattress on a bed base): the top
    # of the lower and the bottom of the upper box coincide where they
    # touch; both faces are inside the union and must not be sampled, while
    # the uncovered rest of the lower box's top and flush side faces stay.
    rng = np.random.default_rng(3)
    base = shapes.box([0, 0, 0.5], [2.0, 2.0, 1.0])
    top = shapes.box([0.25, 0, 1.25], [1.0, 1.0, 0.5])
    flush = shapes.box([-1.5, 0, 0.5], [1.0, 2.0, 1.0])  # side to side
    pts, nrm, _ = shapes.sample_surface([base, top, flush], 6000, rng)
    on_contact = (np.abs(pts[:, 2] - 1.0) < 1e-9) \
        & (np.abs(pts[:, 0] - 0.25) < 0.5) & (np.abs(pts[:, 1]) < 0.5)
    assert not on_contact.any()
    on_wall = (np.abs(pts[:, 0] + 1.0) < 1e-9) & (pts[:, 2] < 1.0)
    assert not on_wall.any()
    # the rest of the base's top face and the top box's sides remain
    uncovered = (np.abs(pts[:, 2] - 1.0) < 1e-9) & (pts[:, 0] > 0.8)
    assert uncovered.sum() > 20 and (nrm[uncovered, 2] > 0.99).all()
    sides = (np.abs(pts[:, 1] - 0.5) < 1e-9) & (pts[:, 2] > 1.0)
    assert sides.sum() > 20
    # no two samples with opposite normals coincide anywhere
    from scipy.spatial import cKDTree
    pairs = cKDTree(pts).query_pairs(1e-3, output_type='ndarray')
    assert ((nrm[pairs[:, 0]] * nrm[pairs[:, 1]]).sum(1) > -0.5).all()
