"""Pinhole cameras against the OpenCV conventions they document."""
import math

import pytest
import torch

from tg_intrinsic.geometry.appearance.cameras import (camera_centers,
                                                      look_at_cameras,
                                                      project, sample_images,
                                                      splat_depth)
from tg_intrinsic.geometry.checks import check_cameras

D64 = torch.float64


def test_look_at_cameras_see_their_target_upright():
    positions = torch.tensor([[3.0, 0, 0], [0, -2, 1], [1, 1, 5]],
                             dtype=D64)
    target = (0.2, -0.1, 0.3)
    K, E = look_at_cameras(positions, target, fov_degrees=60,
                           image_size=(120, 160))
    check_cameras(K, E)  # valid pinhole matrices and rotations
    torch.testing.assert_close(camera_centers(E), positions)
    uv, depth = project(torch.tensor([target], dtype=D64), K, E)
    # the target is at the principal point, in front, at its distance
    torch.testing.assert_close(uv[:, 0], torch.tensor([[80.0, 60.0]] * 3,
                                                      dtype=D64))
    torch.testing.assert_close(
        depth[:, 0], (positions - torch.tensor(target, dtype=D64)).norm(
            dim=1))
    # world +z is up on screen: smaller v (rows grow downwards)
    above = torch.tensor([[0.2, -0.1, 0.4]], dtype=D64)
    assert bool((project(above, K, E)[0][:2, 0, 1] < 60).all())
    # the vertical field of view spans the image height
    half = math.tan(math.radians(30))
    edge = torch.tensor([[0.0, 0.0, 3 * half]], dtype=D64)
    K1, E1 = look_at_cameras(torch.tensor([[3.0, 0, 0]], dtype=D64),
                             fov_degrees=60, image_size=(120, 160))
    torch.testing.assert_close(project(edge, K1, E1)[0][0, 0, 1],
                               torch.tensor(0.0, dtype=D64), atol=1e-9,
                               rtol=0)


def test_project_is_the_pinhole_formula():
    g = torch.Generator().manual_seed(0)
    pos = torch.randn(20, 3, generator=g, dtype=D64)
    K = torch.tensor([[[200.0, 1.5, 64], [0, 180, 40], [0, 0, 1]]],
                     dtype=D64)
    R = torch.linalg.qr(torch.randn(3, 3, generator=g, dtype=D64))[0]
    R = R * torch.linalg.det(R)  # a rotation
    E = torch.cat([R, torch.tensor([[0.1], [0.2], [6.0]], dtype=D64)],
                  1)[None]
    uv, depth = project(pos, K, E)
    cam = pos @ R.T + E[0, :, 3]
    pix = cam @ K[0].T
    torch.testing.assert_close(uv[0], pix[:, :2] / pix[:, 2:])
    torch.testing.assert_close(depth[0], cam[:, 2])


def test_sampling_and_splatting():
    image = torch.arange(12, dtype=D64).reshape(1, 3, 4, 1)
    # pixel centres are at integers + 0.5: sampling there returns pixels
    uv = torch.tensor([[[0.5, 0.5], [3.5, 2.5], [2.0, 1.5]]], dtype=D64)
    values, nan = sample_images(image, uv)
    torch.testing.assert_close(values[0, :, 0],
                               torch.tensor([0.0, 11.0, 5.5], dtype=D64))
    assert not bool(nan.any())
    image[0, 0, 0, 0] = float('nan')
    assert bool(sample_images(image, uv)[1][0, 0])
    depth = splat_depth(uv, torch.tensor([[2.0, 1.0, 3.0]], dtype=D64),
                        torch.ones(1, 3, dtype=torch.bool),
                        torch.zeros(1, 3, dtype=torch.long), 3, 4)
    assert depth.shape == (1, 3, 4)
    assert float(depth[0, 0, 0]) == 2.0 and float(depth[0, 2, 3]) == 1.0
    assert math.isinf(float(depth[0, 0, 3]))


def test_compiled_splatting_is_the_vectorised_one():
    """The CPU's compiled splat gives the torch loop's buffer exactly."""
    from tg_intrinsic.geometry.appearance.cameras import _splat_depth_torch
    g = torch.Generator().manual_seed(0)
    uv = torch.rand(3, 400, 2, generator=g, dtype=D64) * torch.tensor(
        [40.0, 30.0], dtype=D64) - 2
    depth = 1 + torch.rand(3, 400, generator=g, dtype=D64)
    valid = torch.rand(3, 400, generator=g) > 0.2
    radius = torch.randint(0, 4, (3, 400), generator=g)
    compiled = splat_depth(uv, depth, valid, radius, 28, 36)
    plain = _splat_depth_torch(uv, depth, valid, radius, 28, 36)
    assert torch.equal(compiled, plain)
    assert torch.isfinite(compiled).float().mean() > 0.5


@pytest.mark.parametrize('K, E, match', [
    (torch.eye(3)[None], torch.eye(3, 4)[None].repeat(2, 1, 1), 'views'),
    (torch.tensor([[[1.0, 0, 0], [1, 1, 0], [0, 0, 1]]]),
     torch.eye(3, 4)[None], 'pinhole'),
    (torch.eye(3)[None], 2 * torch.eye(3, 4)[None], 'rotation'),
    (torch.eye(3)[None], torch.full((1, 3, 4), float('nan')), 'finite'),
])
def test_bad_cameras(K, E, match):
    with pytest.raises(ValueError, match=match):
        check_cameras(K, E)
