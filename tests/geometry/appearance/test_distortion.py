"""Lens distortion against OpenCV (an independent implementation) and the
formula written out here."""
import numpy as np
import pytest
import torch

from tg_intrinsic.geometry.appearance.distortion import (distort,
                                                         undistort_image)

cv2 = pytest.importorskip('cv2')

K = np.array([[80.0, 0.0, 41.3], [0.0, 84.0, 29.7], [0.0, 0.0, 1.0]])
COEFFICIENTS = [(-0.21, 0.05, 0.0, 0.0), (0.1, -0.02, 0.003, -0.002),
                (0.0, 0.0, 0.0, 0.0)]


def written_out(x, y, k1, k2, p1, p2):
    r2 = x ** 2 + y ** 2
    radial = 1 + k1 * r2 + k2 * r2 ** 2
    return (x * radial + 2 * p1 * x * y + p2 * (r2 + 2 * x ** 2),
            y * radial + p1 * (r2 + 2 * y ** 2) + 2 * p2 * x * y)


@pytest.mark.parametrize('coefficients', COEFFICIENTS)
def test_distort_is_opencvs_projection(coefficients):
    rng = np.random.default_rng(0)
    points = np.concatenate([rng.uniform(-0.6, 0.6, (50, 2)),
                             np.ones((50, 1))], 1) * rng.uniform(1, 3,
                                                                 (50, 1))
    expected, _ = cv2.projectPoints(points, np.zeros(3), np.zeros(3), K,
                                    np.array(coefficients))
    xy = torch.from_numpy(points[:, :2] / points[:, 2:])
    moved = distort(xy, coefficients).numpy()
    assert np.allclose(moved @ K[:2, :2].T + K[:2, 2], expected[:, 0],
                       rtol=0, atol=1e-9)
    assert np.allclose(moved, np.stack(written_out(
        xy[:, 0].numpy(), xy[:, 1].numpy(), *coefficients), 1), atol=1e-15)


def test_undistort_image_matches_opencv_remap():
    # a smooth image, so that bilinear sampling is nearly exact
    height, width = 60, 84
    row, col = np.mgrid[0:height, 0:width]
    image = np.stack([np.sin(col / 9.0) + 1.5, np.cos(row / 7.0) + 1.5,
                      (row + col) / 100.0], -1).astype(np.float32)
    coefficients = (-0.21, 0.05, 0.003, -0.002)
    ours = undistort_image(torch.from_numpy(image), torch.from_numpy(K),
                           coefficients).numpy()
    # OpenCV puts pixel centres at integers: its K is ours less half a pixel
    K_cv = K.copy()
    K_cv[:2, 2] -= 0.5
    map_x, map_y = cv2.initUndistortRectifyMap(
        K_cv, np.array(coefficients), None, K_cv, (width, height),
        cv2.CV_32FC1)
    theirs = cv2.remap(image, map_x, map_y, cv2.INTER_LINEAR,
                       borderMode=cv2.BORDER_CONSTANT, borderValue=np.nan)
    inside = ~np.isnan(ours).any(-1) & ~np.isnan(theirs).any(-1)
    assert inside.mean() > 0.8
    # OpenCV interpolates with 5-bit weights: 1/32 of a pixel's step
    assert np.abs(ours - theirs)[inside].max() < 0.02
    # and the source coordinates agree to float32 round-off
    expected_x = map_x + 0.5  # back to half-integer centres
    u = np.arange(width) + 0.5
    v = np.arange(height) + 0.5
    uu, vv = np.meshgrid(u, v)
    x = (uu - K[0, 2]) / K[0, 0]
    y = (vv - K[1, 2]) / K[1, 1]
    xd, yd = written_out(x, y, *coefficients)
    assert np.abs(K[0, 0] * xd + K[0, 2] - expected_x).max() < 1e-3
    assert np.abs(K[1, 1] * yd + K[1, 2] - (map_y + 0.5)).max() < 1e-3


def test_no_distortion_returns_the_image_and_bad_coefficients_are_refused():
    image = torch.rand(8, 10, 3)
    assert undistort_image(image, torch.from_numpy(K), (0, 0, 0, 0)) is image
    with pytest.raises(ValueError, match='4 coefficients'):
        undistort_image(image, torch.from_numpy(K), (0.1, 0.2))
    with pytest.raises(ValueError, match='NaN or infinite'):
        distort(torch.zeros(3, 2), (float('nan'), 0, 0, 0))
    with pytest.raises(ValueError, match=r'\[H, W, C\]'):
        undistort_image(torch.zeros(8, 10, dtype=torch.uint8),
                        torch.from_numpy(K), (0.1, 0, 0, 0))
