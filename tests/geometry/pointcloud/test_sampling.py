"""Surface sampling: points lie on their triangles at their barycentric
coordinates, triangles are drawn in proportion to their area (chi-squared
against the exact probabilities), farthest point sampling spreads the points
more evenly than uniform draws, normals are the triangles', a generator
makes it repeatable, and bad input."""
import numpy as np
import pytest
import torch
from scipy.spatial import cKDTree
from scipy.stats import chisquare

from tg_intrinsic.geometry import face_areas
from tg_intrinsic.geometry.pointcloud.sampling import sample_surface

from tests.conftest import icosphere


def two_triangles():
    """Two separate triangles of areas 1/2 and 3/2 (ratio 1 : 3)."""
    pos = torch.tensor([[0, 0, 0], [1, 0, 0], [0, 1, 0],
                        [0, 0, 1], [0, 3, 1], [1, 0, 1.0]],
                       dtype=torch.float64)
    face = torch.tensor([[0, 1, 2], [3, 4, 5]]).t()
    return pos, face


def test_points_lie_at_their_barycentric_coordinates():
    pos, face = icosphere(1)
    g = torch.Generator().manual_seed(0)
    points, normals, index, bary = sample_surface(pos, face, 300,
                                                  generator=g)
    assert points.shape == (300, 3) and index.shape == (300, )
    assert (bary >= -1e-12).all()
    torch.testing.assert_close(bary.sum(1), torch.ones(300, dtype=pos.dtype))
    corners = pos[face[:, index].t()]
    torch.testing.assert_close((bary.unsqueeze(-1) * corners).sum(1), points)
    # the normal is the triangle's (outward on the icosphere)
    true = torch.linalg.cross(corners[:, 1] - corners[:, 0],
                              corners[:, 2] - corners[:, 0])
    torch.testing.assert_close(normals, true / true.norm(dim=1, keepdim=True))
    assert ((normals * points).sum(1) > 0).all()


def test_uniform_draws_follow_the_areas():
    pos, face = two_triangles()
    area = face_areas(pos, face)
    assert torch.allclose(area, torch.tensor([0.5, 1.5], dtype=pos.dtype))
    g = torch.Generator().manual_seed(1)
    _, _, index, bary = sample_surface(pos, face, 4000, oversample=1,
                                       generator=g)
    counts = np.bincount(index.numpy(), minlength=2)
    assert chisquare(counts, 4000 * np.array([0.25, 0.75])).pvalue > 1e-3
    # uniform inside a triangle: the first barycentric coordinate,
    # 1 - sqrt(r), has mean 1/3
    assert abs(float(bary[:, 0].mean()) - 1 / 3) < 0.02


def test_farthest_point_sampling_spreads_the_points():
    pos, face = icosphere(3)
    spacing = {}
    for oversample in (1, 8):
        g = torch.Generator().manual_seed(2)
        points = sample_surface(pos, face, 500, oversample=oversample,
                                generator=g)[0].numpy()
        dist, _ = cKDTree(points).query(points, k=2)
        spacing[oversample] = dist[:, 1].min()
    # uniform samples clump; the kept farthest points do not
    assert spacing[8] > 3 * spacing[1]


def test_generator_makes_it_repeatable_and_more_points_than_vertices():
    pos, face = two_triangles()
    a = sample_surface(pos, face, 50, generator=torch.Generator()
                       .manual_seed(3))
    b = sample_surface(pos, face, 50, generator=torch.Generator()
                       .manual_seed(3))
    c = sample_surface(pos, face, 50, generator=torch.Generator()
                       .manual_seed(4))
    for x, y in zip(a, b):
        assert torch.equal(x, y)
    assert not torch.equal(a[0], c[0])
    assert a[0].dtype == torch.float64
    assert sample_surface(pos.float(), face, 5)[0].dtype == torch.float32


def test_triangles_that_repeat_a_vertex_are_never_drawn():
    pos, face = two_triangles()
    face = torch.cat([face, torch.tensor([[0], [0], [4]])], 1)
    g = torch.Generator().manual_seed(5)
    index = sample_surface(pos, face, 200, oversample=1, generator=g)[2]
    assert set(index.tolist()) == {0, 1}


def test_bad_input():
    pos, face = two_triangles()
    with pytest.raises(ValueError, match='num_points'):
        sample_surface(pos, face, 0)
    with pytest.raises(ValueError, match='oversample'):
        sample_surface(pos, face, 10, oversample=0)
    with pytest.raises(ValueError, match='face'):
        sample_surface(pos, face.t(), 10)
    with pytest.raises(ValueError, match='no surface area'):
        sample_surface(pos, torch.tensor([[0], [0], [1]]), 10)
    with pytest.raises(ValueError, match='pos'):
        sample_surface(pos[:, :2], face, 10)
