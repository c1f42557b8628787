"""The implicit shapes of SyntheticSHREC: the primitives' fields against
their analytic distances, the banded grid against the full one, and
marching tetrahedra against analytic level sets."""
import numpy as np
import pytest
import torch

from tg_intrinsic.datasets import implicit_surfaces as imp
from tg_intrinsic.datasets import shrec_shapes as shapes
from tests.datasets.conftest import assert_closed_manifold


def test_marching_tetrahedra_sphere_matches_analytic():
    h, n = 0.05, 50
    lo = np.full(3, -1.25)
    x = lo[0] + h * np.arange(n)
    X, Y, Z = np.meshgrid(x, x, x, indexing='ij')
    f = np.sqrt(X ** 2 + Y ** 2 + Z ** 2) - 0.8
    V, F = imp.marching_tetrahedra(f, lo, h)
    r = assert_closed_manifold(torch.tensor(V), torch.tensor(F).t())
    assert r['volume'] == pytest.approx(4 / 3 * np.pi * 0.8 ** 3, rel=1e-2)
    assert np.abs(np.linalg.norm(V, axis=1) - 0.8).max() < 0.01


def test_banded_grid_has_the_signs_of_the_full_grid():
    rng = np.random.default_rng(4)
    P = shapes.CLASSES['octopus'](rng, 1.0)
    lo = (P[:, 3:6] - P[:, 6:7]).min(0) - 0.1
    full = imp.eval_grid(P, lo, 0.04, 40, 41, 30)
    band = imp.eval_grid_banded(P, lo, 0.04, 40, 41, 30, 3, 1.1)
    assert np.array_equal(full < 0, band < 0)
    near = np.abs(full) < 0.1
    assert np.array_equal(full[near], band[near])


def test_field_is_negative_inside_parts():
    P = np.stack([imp.cone([0, 0, 0], [1, 0, 0], 0.2, 0.1, 2, 0.05),
                  imp.ellipsoid(np.array([0, 0, 0.0]), [0.3, 0.3, 0.3],
                                np.eye(3), 0, 0.1)])
    pts = np.array([[0.5, 0, 0], [0, 0, 0.0], [0.5, 0.5, 0], [2.0, 0, 0]])
    val = imp.eval_points(P, pts)
    assert val[0] < 0 and val[1] < 0 and val[2] > 0 and val[3] > 0
    # exact distance to the round cone's tip sphere
    assert val[3] == pytest.approx(0.9, abs=1e-9)
    assert imp.part_labels(P, pts[[0, 1]]).tolist() == [2, 0]


# --- the primitives' fields against independent formulas ----------------


def test_round_cone_is_the_distance_to_a_union_of_spheres():
    # outside, the distance to the union of the spheres swept along the
    # segment (radius interpolated linearly) is min_t |p - c(t)| - r(t)
    rng = np.random.default_rng(0)
    a, b = np.array([0.1, -0.2, 0.3]), np.array([0.9, 0.4, -0.1])
    ra, rb = 0.3, 0.15
    P = imp.cone(a, b, ra, rb, 1, 0.1)[None]
    pts = rng.uniform(-1, 2, (500, 3))
    field = imp.eval_points(P, pts)
    t = np.linspace(0, 1, 2001)
    centres = a + t[:, None] * (b - a)
    radius = ra + t * (rb - ra)
    union = (np.linalg.norm(pts[:, None] - centres[None], axis=2)
             - radius).min(1)
    assert np.array_equal(field > 0, union > 0)
    outside = field > 0
    assert outside.sum() > 300
    assert np.abs(field[outside] - union[outside]).max() < 1e-5
    # equal radii: a capsule, exactly the distance to the segment minus r
    P = imp.cone(a, b, 0.2, 0.2, 1, 0.1)[None]
    s = np.clip((pts - a) @ (b - a) / ((b - a) @ (b - a)), 0, 1)
    capsule = np.linalg.norm(pts - (a + s[:, None] * (b - a)), axis=1) - 0.2
    assert np.allclose(imp.eval_points(P, pts), capsule, atol=1e-12)


def test_cone_radii_are_kept_valid_and_rows_carry_their_bounds():
    # |ra - rb| must stay below the length; the smaller radius is raised
    row = imp.cone([0, 0, 0], [0.1, 0, 0], 0.5, 0.1, 3, 0.05)
    o = imp.NUM_HEAD
    assert row[o + 6] == 0.5 and row[o + 7] == pytest.approx(0.5 - 0.095)
    assert row[:3].tolist() == [imp.CONE, 3, 0.05]
    # the bounding sphere holds the cone
    rng = np.random.default_rng(1)
    for row in (imp.cone([0, 0, 0], [1, 0.5, 0], 0.3, 0.1, 0, 0.1),
                imp.ellipsoid(np.array([0.2, 0, 0]), [0.5, 0.2, 0.1],
                              np.eye(3), 0, 0.1)):
        centre, bound = row[3:6], row[6]
        pts = centre + rng.uniform(-1.5 * bound, 1.5 * bound, (20000, 3))
        inside = pts[imp.eval_points(row[None], pts) < 0]
        assert len(inside) > 100
        assert np.linalg.norm(inside - centre, axis=1).max() <= bound


def test_rotated_ellipsoid_has_its_surface_where_the_formula_says():
    from scipy.spatial.transform import Rotation
    rng = np.random.default_rng(2)
    R = Rotation.random(random_state=1).as_matrix()  # columns: the axes
    radii, centre = np.array([0.5, 0.3, 0.2]), np.array([0.2, 0.1, -0.3])
    P = imp.ellipsoid(centre, radii, R, 0, 0.1)[None]
    u = rng.standard_normal((500, 3))
    u /= np.linalg.norm(u, axis=1, keepdims=True)
    for scale, check in ((1.0, lambda f: np.abs(f) < 1e-12),
                         (0.9, lambda f: f < 0), (1.1, lambda f: f > 0)):
        assert check(imp.eval_points(P, centre + scale * (u * radii) @ R.T
                                     )).all()
    # along a principal axis the field is the true distance
    axis = R[:, 0]
    for d in (0.05, 0.4):
        p = centre + (radii[0] + d) * axis
        assert imp.eval_points(P, p[None])[0] == pytest.approx(d, rel=1e-9)


def test_the_field_is_the_smooth_union_of_the_parts_in_order():
    # the bounding-sphere culling skips only parts that cannot change the
    # result: the same as folding the polynomial smooth minimum over all
    rng = np.random.default_rng(3)
    P = shapes.CLASSES['ant'](np.random.default_rng(3), 1.0)
    pts = rng.uniform(-1.5, 1.5, (3000, 3))
    each = np.stack([imp.eval_points(P[i:i + 1], pts) for i in range(len(P))])
    acc = each[0].copy()
    for i in range(1, len(P)):
        k, d = P[i, 2], each[i]
        h = np.maximum(k - np.abs(acc - d), 0) / k
        acc = np.minimum(acc, d) - h * h * k / 4
    field = imp.eval_points(P, pts)
    assert np.allclose(field, acc, rtol=0, atol=1e-12)
    assert (field <= each.min(0) + 1e-12).all()  # blending only adds
    # and on a grid
    lo = np.array([-1.0, -0.6, 0.0])
    grid = imp.eval_grid(P, lo, 0.1, 4, 5, 6)
    x = lo + 0.1 * np.stack(np.meshgrid(np.arange(4), np.arange(5),
                                        np.arange(6), indexing='ij'), -1)
    assert np.allclose(grid, imp.eval_points(P, x.reshape(-1, 3)
                                             ).reshape(4, 5, 6), atol=1e-12)


# --- marching tetrahedra ----------------------------------------------------


def ellipsoid_mesh(h=0.04):
    from scipy.spatial.transform import Rotation
    R = Rotation.from_euler('xyz', [0.3, -0.5, 0.8]).as_matrix()
    radii, centre = np.array([0.6, 0.4, 0.3]), np.array([0.05, -0.02, 0.03])
    P = imp.ellipsoid(centre, radii, R, 0, 0.1)[None]
    lo, n = np.full(3, -0.8), int(round(1.6 / h)) + 1
    f = imp.eval_grid(P, lo, h, n, n, n)
    V, F = imp.marching_tetrahedra(f, lo, h)
    return P, V, F, lo, radii


def gradient(P, x, step=1e-6):
    """Normalised central differences of the field."""
    g = np.stack([(imp.eval_points(P, x + step * e)
                   - imp.eval_points(P, x - step * e)) / (2 * step)
                  for e in np.eye(3)], 1)
    return g / np.linalg.norm(g, axis=1, keepdims=True)


def test_marching_tetrahedra_of_an_ellipsoid():
    P, V, F, lo, radii = ellipsoid_mesh()
    r = assert_closed_manifold(torch.tensor(V), torch.tensor(F).t())
    assert r['volume'] == pytest.approx(4 / 3 * np.pi * radii.prod(),
                                        rel=0.01)
    # vertices on the zero level set, up to the linear interpolation
    assert np.abs(imp.eval_points(P, V)).max() < 0.04 ** 2
    # the normals are the field's gradient: every triangle faces outwards
    edges = np.cross(V[F[:, 1]] - V[F[:, 0]], V[F[:, 2]] - V[F[:, 0]])
    area = np.linalg.norm(edges, axis=1)
    dots = (edges / area[:, None] * gradient(P, V[F].mean(1))).sum(1)
    assert dots.min() > 0
    assert (area * dots).sum() / area.sum() > 0.999
    vertex = shapes.vertex_normals_np(V, F)
    dots = (vertex * gradient(P, V)).sum(1)
    assert dots.min() > 0.8 and np.quantile(dots, 0.01) > 0.99


def test_vertices_lie_on_tetrahedron_edges_away_from_the_nodes():
    # a vertex sits on the grid edge i0 -> i0 + step (step in {0, 1}^3):
    # every coordinate is a node's, or the same fraction w of the way,
    # with w clamped to [tclamp, 1 - tclamp]
    _, V, _, lo, _ = ellipsoid_mesh()
    g = (V - lo) / 0.04
    frac = g - np.floor(g + 1e-9)
    frac[frac < 1e-9] = 0
    moving = frac > 0
    assert moving.any(1).all()
    w = np.where(moving, frac, np.nan)
    assert np.allclose(np.nanmax(w, 1), np.nanmin(w, 1), atol=1e-9)
    assert np.nanmin(w) >= 0.02 - 1e-9 and np.nanmax(w) <= 0.98 + 1e-9
    assert (moving.sum(1) > 1).any()  # the split's diagonals are used


def test_a_level_set_through_grid_nodes_is_still_closed():
    # nodes with f == 0 exactly are moved off the level set
    i = np.arange(21) - 10.0
    X, Y, Z = np.meshgrid(i, i, i, indexing='ij')
    f = 0.1 * np.sqrt(X ** 2 + Y ** 2 + Z ** 2) - 0.5
    assert (f == 0).sum() == 30
    V, F = imp.marching_tetrahedra(f, np.zeros(3), 0.1)
    assert_closed_manifold(torch.tensor(V), torch.tensor(F).t())
    assert np.abs(np.linalg.norm(V - 1.0, axis=1) - 0.5).max() < 0.02
    # marching_tetrahedra does not change its input
    assert (f == 0).sum() == 30


def test_two_blobs_give_two_closed_components():
    P = np.stack([imp.ellipsoid(np.array([-0.5, 0, 0]), [0.3] * 3,
                                np.eye(3), 0, 0.05),
                  imp.ellipsoid(np.array([0.5, 0, 0]), [0.3] * 3,
                                np.eye(3), 1, 0.05)])
    lo = np.array([-1.0, -0.5, -0.5])
    f = imp.eval_grid(P, lo, 0.05, 41, 21, 21)
    V, F = imp.marching_tetrahedra(f, lo, 0.05)
    assert shapes.mesh_topology(V, F) == (2, 4)
    labels = imp.part_labels(P, V)
    assert np.array_equal(labels, (V[:, 0] > 0).astype(int))
