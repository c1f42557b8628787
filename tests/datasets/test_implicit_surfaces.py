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
