"""splat_index: the nearest point wins its pixels, points behind the
camera or outside the image are skipped (the figures test the views)."""
import numpy as np
import torch

from tg_intrinsic.geometry.appearance.cameras import look_at_cameras
from tg_intrinsic.geometry.appearance.splat import splat_index


def test_splat_index_keeps_the_nearer_of_two_points_and_skips_the_rest():
    K, E = look_at_cameras(torch.tensor([[0.0, 0.0, 5.0]]),
                           fov_degrees=40.0, image_size=(32, 32))
    # two points on the optical axis, and one to the side for the spacing
    pos = torch.tensor([[0.0, 0.0, -1.0], [0.0, 0.0, 1.0], [0.3, 0.0, 0.0]],
                       dtype=torch.float64)
    index = splat_index(pos, K[0], E[0], (32, 32))
    assert index[16, 16] == 1  # z = 1 is nearer to the camera at z = 5
    assert set(np.unique(index)) == {-1, 1, 2}
    behind = torch.tensor([[0.0, 0.0, 6.0], [0.1, 0.0, 7.0]],
                          dtype=torch.float64)
    assert (splat_index(behind, K[0], E[0], (32, 32)) == -1).all()
    outside = torch.tensor([[40.0, 0.0, 0.0]], dtype=torch.float64)
    assert (splat_index(outside, K, E, (32, 32)) == -1).all()
