"""Rendered photographs of a mesh (the SVBRDF scenes' capture): the
background and back-facing views, agreement with the renderer per
pixel, determinism, and bad input."""
import pytest
import torch

from tg_intrinsic.datasets.capture import render_images
from tg_intrinsic.geometry.appearance.raster import rasterize
from tests.geometry.appearance.test_lighting import (D64, camera, material,
                                                     sky_with_sun)


def test_render_images_background_and_bad_input():
    import trimesh
    ico = trimesh.creation.icosphere(subdivisions=2)
    V = torch.tensor(ico.vertices, dtype=D64)
    F = torch.tensor(ico.faces).t().contiguous()
    n = V.clone()
    K, E = camera([0.0, -3.0, 0.5], focal=25.0, size=(24, 24))
    K2, E2 = camera([0.0, 3.0, 0.0], target=(0.0, 6.0, 0.0), size=(24, 24))
    env = sky_with_sun(16, 32)
    bc, m, r = material(len(V), 0.0, 0.6)
    img = render_images(V, F, n, bc, m, r, torch.stack([K, K2]),
                        torch.stack([E, E2]), 24, 24, env)
    assert img.shape == (2, 24, 24, 3) and img.dtype == torch.float32
    face_id, _, _ = rasterize(V, F, K, E, 24, 24)
    assert bool((img[0][face_id < 0] == 0).all())
    assert bool((img[0][face_id >= 0].sum(-1) > 0).float().mean() > 0.95)
    assert bool((img[1] == 0).all())  # looks away: an empty image
    with pytest.raises(ValueError, match='extrinsics'):
        bad = E.clone()
        bad[:, :3] *= 2
        render_images(V, F, n, bc, m, r, K[None], bad[None], 24, 24, env)
    with pytest.raises(ValueError, match='faces|face'):
        rasterize(V, F.t(), K, E, 24, 24)
    with pytest.raises(ValueError, match='intrinsics'):
        rasterize(V, F, K[:2], E, 24, 24)
