"""Rendered photographs of a mesh (the SVBRDF scenes' capture): the
background and back-facing views, the base colour at every pixel's hit
point under a constant sky, determinism and the seed, and bad input
named."""
import pytest
import torch

from tg_intrinsic.datasets.capture import render_images
from tg_intrinsic.geometry.appearance.raster import rasterize
from tests.geometry.appearance.scenes import (D64, camera, material,
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


@pytest.fixture(scope='module')
def ball_scene():
    """An icosphere with a base colour whose red channel follows z, two
    cameras on opposite sides, a constant (grey) sky."""
    import trimesh
    from tg_intrinsic.geometry.appearance.cameras import look_at_cameras
    ico = trimesh.creation.icosphere(subdivisions=2)
    V = torch.tensor(ico.vertices, dtype=D64)
    F = torch.tensor(ico.faces).t().contiguous()
    normal = V / V.norm(dim=1, keepdim=True)
    base = torch.stack([0.5 + 0.4 * V[:, 2], torch.full_like(V[:, 0], 0.5),
                        torch.full_like(V[:, 0], 0.3)], 1)
    metallic = torch.zeros(len(V), dtype=D64)
    roughness = torch.full((len(V), ), 0.6, dtype=D64)
    K, E = look_at_cameras(torch.tensor([[0.0, -3.0, 0.5],
                                         [2.0, 1.0, -1.0]], dtype=D64),
                           fov_degrees=50.0, image_size=(24, 24))
    env = torch.full((16, 32, 3), 2.0, dtype=D64)
    args = (V, F, normal, base, metallic, roughness, K, E, 24, 24, env)
    return args, render_images(*args)


def test_a_constant_sky_lights_the_base_colour_per_pixel(ball_scene):
    # a dielectric's specular reflection has R0 = 0.04 on every channel,
    # so channel differences are the diffuse part's: L (b_c - b_c'), with
    # the base colour interpolated at the pixel's hit point
    args, images = ball_scene
    V, F, _, _, _, _, K, E, height, width, _ = args
    for v in range(2):
        face_id, bary, _ = rasterize(V, F, K[v], E[v], height, width)
        hit = face_id >= 0
        assert 0.2 < hit.double().mean() < 0.9
        z = (bary[hit][..., None] * V[F.t()[face_id[hit]]]).sum(1)[:, 2]
        pixels = images[v][hit].double()
        torch.testing.assert_close(pixels[:, 0] - pixels[:, 1],
                                   2.0 * 0.4 * z, rtol=0, atol=1e-4)
        torch.testing.assert_close(pixels[:, 1] - pixels[:, 2],
                                   torch.full_like(z, 2.0 * 0.2), rtol=0,
                                   atol=1e-4)
        # what is left is a small, positive specular reflection
        specular = pixels[:, 2] - 2.0 * 0.3
        assert specular.min() > 0 and specular.max() < 0.3 * 2.0
        assert bool((images[v][~hit] == 0).all())


def test_determinism_seed_and_normals_facing_away(ball_scene):
    args, images = ball_scene
    torch.testing.assert_close(render_images(*args), images, rtol=0,
                               atol=0)
    other = render_images(*args, seed=1)
    assert not torch.equal(other, images)  # other specular noise
    torch.testing.assert_close(other[..., 0] - other[..., 1],
                               images[..., 0] - images[..., 1], rtol=0,
                               atol=1e-5)
    V, F, normal, *rest = args
    flipped = render_images(V, F, -normal, *rest)
    assert bool((flipped == 0).all())  # every normal faces away


@pytest.mark.parametrize('change,match', [
    (dict(base=2.0), r"'base_color' must lie in \[0, 1\], got values in "
                     r"\[.*\]; clamp it first"),
    (dict(metallic=-1.0), r"'metallic' must lie in \[0, 1\]"),
    (dict(drop='roughness'), r"'roughness' must have shape \[162\], got "
                             r"\[161\]"),
    (dict(zero_normal=True), "'vertex_normals' has zero-length"),
    (dict(height=0), "'height' must be at least 1, got 0"),
])
def test_bad_input_names_the_argument(ball_scene, change, match):
    args, _ = ball_scene
    V, F, normal, base, metallic, roughness, K, E, height, width, env = \
        args
    if 'base' in change:
        base = base * change['base']
    if 'metallic' in change:
        metallic = metallic + change['metallic']
    if change.get('drop') == 'roughness':
        roughness = roughness[:-1]
    if change.get('zero_normal'):
        normal = normal.clone()
        normal[5] = 0
    height = change.get('height', height)
    with pytest.raises(ValueError, match=match):
        render_images(V, F, normal, base, metallic, roughness, K, E, height,
                      width, env)
