import math

import pytest
import torch

from tg_intrinsic.geometry.sphere_images import (disc_to_hemisphere,
                                                 disc_to_square,
                                                 hemisphere_to_disc,
                                                 sample_image_on_sphere,
                                                 square_to_disc)

F64 = torch.float64


def square_points(n=500, seed=0):
    g = torch.Generator().manual_seed(seed)
    return torch.rand(n, 2, dtype=F64, generator=g) * 2 - 1


def test_square_to_disc_matches_the_elliptical_formula():
    xy = square_points()
    x, y = xy.unbind(1)
    expected = torch.stack([x * torch.sqrt(1 - y ** 2 / 2),
                            y * torch.sqrt(1 - x ** 2 / 2)], 1)
    assert torch.allclose(square_to_disc(xy), expected, atol=1e-15)
    # corners and edge midpoints land on the circle
    corners = torch.tensor([[1., 1.], [-1., 1.], [1., 0.], [0., -1.]],
                           dtype=F64)
    uv = square_to_disc(corners)
    assert torch.allclose(uv.norm(dim=1), torch.ones(4, dtype=F64))
    assert torch.allclose(uv[0], torch.full((2, ), 0.5 ** 0.5, dtype=F64))
    # every point of an edge goes to the circle, interior points inside
    t = torch.linspace(-1, 1, 41, dtype=F64)
    edge = torch.stack([torch.ones_like(t), t], 1)
    assert torch.allclose(square_to_disc(edge).norm(dim=1),
                          torch.ones_like(t))
    assert (square_to_disc(0.99 * xy).norm(dim=1) < 1).all()


def test_disc_to_square_inverts_the_mapping():
    xy = square_points()
    assert torch.allclose(disc_to_square(square_to_disc(xy)), xy,
                          atol=1e-12)
    g = torch.Generator().manual_seed(1)
    angle = torch.rand(300, dtype=F64, generator=g) * 2 * math.pi
    radius = torch.rand(300, dtype=F64, generator=g).sqrt()
    uv = torch.stack([radius * angle.cos(), radius * angle.sin()], 1)
    assert torch.allclose(square_to_disc(disc_to_square(uv)), uv,
                          atol=1e-12)
    # the circle goes to the square's boundary
    circle = torch.stack([angle.cos(), angle.sin()], 1)
    assert torch.allclose(disc_to_square(circle).abs().max(1).values,
                          torch.ones(300, dtype=F64), atol=1e-7)


def test_hemisphere_map_is_azimuthal_equidistant():
    xy = square_points()
    uv = square_to_disc(xy)
    pos = disc_to_hemisphere(uv)
    assert torch.allclose(pos.norm(dim=1), torch.ones(len(pos), dtype=F64))
    # geodesic distance from the pole = pi / 2 * disc radius, same azimuth
    assert torch.allclose(torch.arccos(pos[:, 2].clamp(-1, 1)),
                          0.5 * math.pi * uv.norm(dim=1), atol=1e-7)
    assert torch.allclose(torch.atan2(pos[:, 1], pos[:, 0]),
                          torch.atan2(uv[:, 1], uv[:, 0]), atol=1e-12)
    assert torch.allclose(hemisphere_to_disc(pos), uv, atol=1e-12)
    centre = disc_to_hemisphere(torch.zeros(1, 2, dtype=F64))
    assert torch.equal(centre, torch.tensor([[0., 0., 1.]], dtype=F64))
    # the lower hemisphere goes beyond the unit disc (south pole: radius 2)
    south = torch.tensor([[1e-9, 0., -1.]], dtype=F64)
    assert torch.allclose(hemisphere_to_disc(south).norm(dim=1),
                          torch.tensor([2.], dtype=F64))


def pixel_point(r, c, h=8, w=8):
    """The sphere point of pixel (r, c)'s centre, by the documented
    formula."""
    xy = torch.tensor([[2 * (c + 1) / (w + 1) - 1,
                        1 - 2 * (r + 1) / (h + 1)]], dtype=F64)
    return disc_to_hemisphere(square_to_disc(xy))


def test_a_bright_pixel_lands_where_the_mapping_says():
    image = torch.zeros(8, 8, dtype=F64)
    image[2, 5] = 1.0
    assert sample_image_on_sphere(image, pixel_point(2, 5)).item() \
        == pytest.approx(1.0, abs=1e-12)
    for r, c in ((2, 4), (3, 5), (1, 6), (5, 2)):
        assert sample_image_on_sphere(image, pixel_point(r, c)).item() \
            == pytest.approx(0.0, abs=1e-12)
    # halfway between two pixel centres: half the value
    xy = torch.tensor([[(2 * 6 / 9 - 1 + 2 * 5 / 9 - 1) / 2, 1 - 6 / 9]],
                      dtype=F64)
    b = disc_to_hemisphere(square_to_disc(xy))
    assert sample_image_on_sphere(image, b).item() == pytest.approx(0.5)


def test_a_linear_ramp_is_reproduced_inside_the_pixel_centres():
    h, w = 8, 8
    x = 2 * (torch.arange(w, dtype=F64) + 1) / (w + 1) - 1
    y = 1 - 2 * (torch.arange(h, dtype=F64) + 1) / (h + 1)
    image = 0.3 + 2.0 * x[None, :] - 0.7 * y[:, None]  # a x + b y + c
    xy = square_points(400, seed=3) * (1 - 2 / (w + 1))  # inside the hull
    pos = disc_to_hemisphere(square_to_disc(xy))
    expected = 0.3 + 2.0 * xy[:, 0] - 0.7 * xy[:, 1]
    assert torch.allclose(sample_image_on_sphere(image, pos), expected,
                          atol=1e-10)
    # channels and the lower hemisphere
    both = sample_image_on_sphere(torch.stack([image, -image]), pos)
    assert both.shape == (400, 2)
    assert torch.allclose(both[:, 1], -expected, atol=1e-10)
    lower = pos * torch.tensor([1., 1., -1.], dtype=F64)
    assert sample_image_on_sphere(image, lower).abs().max() == 0


def test_the_signal_is_continuous_at_the_equator():
    image = torch.ones(8, 8, dtype=F64)
    angle = torch.linspace(0, 2 * math.pi, 50, dtype=F64)
    for z in (1e-9, -1e-9):
        pos = torch.stack([angle.cos(), angle.sin(),
                           torch.full_like(angle, z)], 1)
        assert sample_image_on_sphere(image, pos).abs().max() < 1e-6


def test_bad_input_is_explained():
    with pytest.raises(ValueError, match=r"must lie in the square"):
        square_to_disc(torch.tensor([[1.5, 0.]], dtype=F64))
    with pytest.raises(ValueError, match=r"must lie in the unit disc"):
        disc_to_square(torch.tensor([[0.9, 0.9]], dtype=F64))
    with pytest.raises(ValueError, match=r"must lie in the unit disc"):
        disc_to_hemisphere(torch.tensor([[0.9, 0.9]], dtype=F64))
    with pytest.raises(ValueError, match=r"NaN"):
        square_to_disc(torch.tensor([[math.nan, 0.]], dtype=F64))
    with pytest.raises(ValueError, match=r"shape \[N, 2\]"):
        square_to_disc(torch.zeros(3, 3, dtype=F64))
    with pytest.raises(ValueError, match=r"float32 or float64"):
        disc_to_square(torch.zeros(3, 2, dtype=torch.long))
    with pytest.raises(ValueError, match=r"origin"):
        hemisphere_to_disc(torch.zeros(1, 3, dtype=F64))
    with pytest.raises(ValueError, match=r"\[H, W\] or \[C, H, W\]"):
        sample_image_on_sphere(torch.zeros(8, dtype=F64),
                               torch.ones(1, 3, dtype=F64))
    with pytest.raises(ValueError, match=r"NaN or infinite"):
        sample_image_on_sphere(torch.full((8, 8), math.inf, dtype=F64),
                               torch.ones(1, 3, dtype=F64))
