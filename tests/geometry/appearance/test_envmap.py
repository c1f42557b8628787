import math

import pytest
import torch

from tg_intrinsic.geometry.appearance.envmap import (downsample_envmap,
                                                     envmap_to_sh,
                                                     equirect_directions,
                                                     equirect_lookup,
                                                     equirect_solid_angles,
                                                     filter_envmap, irradiance,
                                                     sh_to_envmap,
                                                     sun_sky_envmap)
from tg_intrinsic.geometry.appearance.sh import (brdf_filter, fibonacci_sphere,
                                      num_coefficients, real_sh, sh_index)

DEVICES = ['cpu'] + (['cuda'] if torch.cuda.is_available() else [])


def integral(envmap):
    height, width = envmap.shape[:2]
    omega = equirect_solid_angles(height, width, envmap.dtype, envmap.device)
    return (envmap * omega[..., None]).sum((0, 1))


def band_limited(l_max=4, seed=0, dc=6.0, dtype=torch.float64):
    """Random coefficients up to ``l_max`` with a DC term large enough for
    the function to stay positive."""
    g = torch.Generator().manual_seed(seed)
    c = 0.3 * torch.randn(num_coefficients(l_max), 3, generator=g,
                          dtype=dtype)
    c[0] = dc
    return c


# ------------------------------------------------------ spherical harmonics
def test_sh_to_envmap_evaluates_the_expansion():
    c = band_limited(5, dc=0.0)
    envmap = sh_to_envmap(c, 24, 40)
    direct = real_sh(equirect_directions(24, 40), 5) @ c
    torch.testing.assert_close(envmap, direct, rtol=0, atol=1e-12)
    scalar = sh_to_envmap(c[:, 1], 24, 40)
    torch.testing.assert_close(scalar, direct[..., 1], rtol=0, atol=1e-12)


def test_envmap_to_sh_is_the_pixel_quadrature():
    envmap = torch.rand(16, 32, 3, dtype=torch.float64,
                        generator=torch.Generator().manual_seed(1))
    omega = equirect_solid_angles(16, 32)
    basis = real_sh(equirect_directions(16, 32), 7)
    direct = torch.einsum('hwk,hw,hwc->kc', basis, omega, envmap)
    torch.testing.assert_close(envmap_to_sh(envmap, 7), direct, rtol=0,
                               atol=1e-12)


def test_projection_recovers_known_coefficients():
    c = band_limited(4, dc=0.5)
    envmap = sh_to_envmap(c, 256, 512)  # signed: the projection allows it
    recovered = envmap_to_sh(envmap, 8)
    k = num_coefficients(4)
    assert (recovered[:k] - c).abs().max() < 1e-3
    assert recovered[k:].abs().max() < 1e-3
    # and back: the round trip of a band-limited map
    again = sh_to_envmap(recovered[:k], 256, 512)
    assert (again - envmap).abs().max() < 2e-3


def test_float32_and_devices():
    for device in DEVICES:
        c = band_limited(3).float().to(device)
        envmap = sh_to_envmap(c, 64, 128)
        assert envmap.dtype == torch.float32 and envmap.device.type == device
        back = envmap_to_sh(envmap, 3)
        assert back.dtype == torch.float32
        assert (back - c).abs().max() < 1e-2


# ----------------------------------------------------------------- filter
def test_filter_multiplies_coefficients_by_the_lobe_filter():
    alpha = 0.2
    c = band_limited(6, seed=3, dc=15.0)
    envmap = sh_to_envmap(c, 256, 512)
    assert bool((envmap > 0).all())
    filtered = filter_envmap(envmap, alpha, out_height=128)
    assert filtered.shape == (128, 256, 3)
    expected = c * brdf_filter(6, torch.tensor(alpha, dtype=c.dtype))[:, None]
    measured = envmap_to_sh(filtered, 6)
    # relative to each degree's own size (the DC term dominates otherwise)
    for l in range(1, 7):  # noqa: E741
        band = slice(sh_index(l, -l), sh_index(l, l) + 1)
        error = (measured[band] - expected[band]).norm()
        assert error < 1e-2 * expected[band].norm(), l
    assert abs(measured[0] - expected[0]).max() < 1e-3 * c[0].abs().max()


def test_filter_default_grid_and_properties():
    sky = sun_sky_envmap(128, 256, dtype=torch.float64)
    alpha = 0.25
    filtered = filter_envmap(sky, alpha)
    degree = math.ceil(3.5 / alpha)
    assert filtered.shape == (2 * degree, 4 * degree, 3)
    assert bool((filtered >= 0).all())
    # the sun is spread out: far dimmer peak, nearly the same total power
    assert filtered.max() < 0.05 * sky.max()
    torch.testing.assert_close(integral(filtered), integral(sky), rtol=1e-2,
                               atol=0)
    # Fejer's row weights: a constant stays constant at any resolution
    for height in (16, 128):
        constant = torch.full((height, 2 * height, 3), 2.5,
                              dtype=torch.float64)
        torch.testing.assert_close(filter_envmap(constant, 0.5),
                                   torch.full((16, 32, 3), 2.5,
                                              dtype=torch.float64),
                                   rtol=1e-12, atol=0)


def test_filter_is_exact_on_a_coarse_band_limited_map():
    # degree 4 on 16 rows, no downsampling (4 L > 16): the projection with
    # Fejer's weights is exact, so the filter is exactly the lobe filter
    alpha = 0.9
    c = band_limited(4, seed=4, dc=20.0)
    filtered = filter_envmap(sh_to_envmap(c, 16, 32), alpha, out_height=16)
    expected = c * brdf_filter(4, torch.tensor(alpha, dtype=c.dtype))[:, None]
    torch.testing.assert_close(filtered, sh_to_envmap(expected, 16, 32),
                               rtol=1e-10, atol=1e-10)


def test_filter_float32_keeps_dtype_and_device():
    for device in DEVICES:
        sky = sun_sky_envmap(64, 128, device=device)
        out = filter_envmap(sky, 0.3, out_height=20)
        assert out.dtype == torch.float32 and out.shape == (20, 40, 3)
        assert out.device.type == device


# ------------------------------------------------------------- downsample
def test_downsample_preserves_the_integral():
    envmap = torch.rand(48, 96, 3, dtype=torch.float64,
                        generator=torch.Generator().manual_seed(2)) ** 4 * 50
    for factor in (2, 3, 4, 8):
        small = downsample_envmap(envmap, factor)
        assert small.shape == (48 // factor, 96 // factor, 3)
        torch.testing.assert_close(integral(small), integral(envmap),
                                   rtol=1e-10, atol=0)
    assert torch.equal(downsample_envmap(envmap, 1), envmap)
    constant = torch.full((8, 16, 3), 3.0)
    torch.testing.assert_close(downsample_envmap(constant, 4),
                               torch.full((2, 4, 3), 3.0))


# ------------------------------------------------------------- irradiance
def test_irradiance_of_a_constant_map_is_pi_l():
    envmap = torch.full((64, 128, 3), 2.0, dtype=torch.float64)
    poles = torch.tensor([[0, 0, 1.0], [0, 0, -3.0]], dtype=torch.float64)
    # the horizon of +-z runs along pixel edges: exact
    torch.testing.assert_close(irradiance(envmap, poles),
                               torch.full((2, 3), 2 * math.pi,
                                          dtype=torch.float64),
                               rtol=1e-12, atol=0)
    normals = fibonacci_sphere(200)
    coarse = irradiance(envmap, normals)
    fine = irradiance(envmap, normals, resolution=64)
    assert ((coarse - 2 * math.pi).abs() < 5e-3 * 2 * math.pi).all()
    assert (fine - 2 * math.pi).abs().max() < \
        0.5 * (coarse - 2 * math.pi).abs().max()
    assert bool((coarse <= 2 * math.pi * (1 + 1e-12)).all())  # one-sided


def test_irradiance_matches_the_clamped_cosine_in_sh():
    # Ramamoorthi and Hanrahan: E = sum A_l c_lm Y_lm(n), A = (pi, 2pi/3,
    # pi/4) for l = 0, 1, 2, for a map band-limited to degree 2
    c = band_limited(2, seed=5, dc=3.0)
    envmap = sh_to_envmap(c, 256, 512)
    normals = fibonacci_sphere(300)
    a = torch.tensor([math.pi] + [2 * math.pi / 3] * 3 + [math.pi / 4] * 5,
                     dtype=torch.float64)
    expected = real_sh(normals, 2) @ (a[:, None] * c)
    scale = expected.abs().max()
    assert (irradiance(envmap, normals) - expected).abs().max() < 5e-3 * scale
    assert (irradiance(envmap, normals, resolution=128) - expected
            ).abs().max() < 5e-4 * scale


def test_irradiance_dtypes_and_sun():
    sky = sun_sky_envmap(64, 128)  # float32
    sun = torch.tensor([[1.0, 0.0, 1.0]], dtype=torch.float64)
    out = irradiance(sky, sun)
    assert out.dtype == torch.float64 and out.shape == (1, 3)
    out32 = irradiance(sky, sun.float())
    assert out32.dtype == torch.float32
    # the sun (power 25 at normal incidence) dominates
    assert 25 < float(out32[0, 0]) < 30
    for device in DEVICES:
        out = irradiance(sky.to(device), sun.float().to(device))
        assert out.device.type == device


# ---------------------------------------------------------------- sun sky
def test_sun_sky_integral_matches_its_documented_power():
    power = torch.tensor([25.0, 23.5, 21.0], dtype=torch.float64)
    zenith = torch.tensor([0.25, 0.45, 1.0], dtype=torch.float64)
    horizon = torch.tensor([0.9, 0.9, 1.0], dtype=torch.float64)
    ground = torch.tensor([0.15, 0.13, 0.1], dtype=torch.float64)
    sky_power = 2 * math.pi * (ground + horizon + 2 / 3 * (zenith - horizon))
    for height in (64, 255):
        sky = sun_sky_envmap(height, 2 * height, dtype=torch.float64)
        torch.testing.assert_close(integral(sky), power + sky_power,
                                   rtol=1e-12, atol=0)
        no_sun = sun_sky_envmap(height, 2 * height, sun_power=(0, 0, 0),
                                dtype=torch.float64)
        torch.testing.assert_close(integral(sky - no_sun), power,
                                   rtol=1e-12, atol=0)
    assert torch.equal(sun_sky_envmap(32, 64), sun_sky_envmap(32, 64))


def test_sun_disc_is_where_it_should_be():
    direction = torch.tensor([-0.3, 0.5, 0.4], dtype=torch.float64)
    direction = direction / direction.norm()
    sky = sun_sky_envmap(128, 256, direction, dtype=torch.float64)
    brightest = equirect_directions(128, 256).reshape(-1, 3)[
        sky[..., 0].argmax()]
    assert float(brightest @ direction) > math.cos(0.03)
    assert equirect_lookup(sky, direction[None])[0, 0] > 1000
    # a point-like sun is widened to one pixel, so it is still resolved
    dot = sun_sky_envmap(16, 32, direction, sun_angular_radius=0.0,
                         dtype=torch.float64)
    assert equirect_lookup(dot, direction[None])[0, 0] > 10
    # sky gradient: zenith bluer than the horizon, ground dim
    assert sky[0, 0, 2] > sky[0, 0, 0] and sky[-1, 0].max() < 0.2


# -------------------------------------------------------------- bad input
def test_bad_inputs_raise():
    good = torch.ones(8, 16, 3)
    for bad in (torch.ones(8, 16), torch.ones(8, 16, 4)):
        for call in (lambda m: envmap_to_sh(m, 2),
                     lambda m: filter_envmap(m, 0.2),
                     lambda m: downsample_envmap(m, 2),
                     lambda m: irradiance(m, torch.ones(2, 3))):
            with pytest.raises(ValueError, match=r'\[H, W, 3\]'):
                call(bad)
    nan = good.clone()
    nan[2, 3, 1] = float('nan')
    with pytest.raises(ValueError, match='NaN'):
        envmap_to_sh(nan, 2)
    with pytest.raises(ValueError, match='NaN'):
        filter_envmap(nan, 0.2)
    with pytest.raises(ValueError, match='negative'):
        filter_envmap(-good, 0.2)
    with pytest.raises(ValueError, match='float'):
        envmap_to_sh(torch.ones(8, 16, 3, dtype=torch.long), 2)
    for alpha in (0.0, -0.1, float('nan'), float('inf')):
        with pytest.raises(ValueError, match='alpha'):
            filter_envmap(good, alpha)
    with pytest.raises(ValueError, match='l_max'):
        envmap_to_sh(good, -1)
    with pytest.raises(ValueError, match=r'\(l_max \+ 1\)\^2'):
        sh_to_envmap(torch.ones(5, 3), 8, 16)
    with pytest.raises(ValueError, match='divisible'):
        downsample_envmap(torch.ones(9, 16, 3), 2)
    with pytest.raises(ValueError, match='fewer than 2 rows'):
        downsample_envmap(good, 8)
    with pytest.raises(ValueError, match='zero vector'):
        irradiance(good, torch.zeros(2, 3))
    with pytest.raises(ValueError, match=r'\[N, 3\]'):
        irradiance(good, torch.ones(2, 2))
    with pytest.raises(ValueError, match='sun_direction'):
        sun_sky_envmap(8, 16, (0, 0, 0))
    with pytest.raises(ValueError, match='sun_direction'):
        sun_sky_envmap(8, 16, (0, 1))
    with pytest.raises(ValueError, match='ground'):
        sun_sky_envmap(8, 16, ground=(-1, 0, 0))
    with pytest.raises(ValueError, match='sun_angular_radius'):
        sun_sky_envmap(8, 16, sun_angular_radius=-0.1)
    with pytest.raises(ValueError, match='height'):
        sun_sky_envmap(1, 16)


def test_compiled_lookup_matches_the_differentiable_one():
    # the rendering kernels inline the same per-sample rule (env_coords,
    # bilinear_rgb) as the compiled lookup
    g = torch.Generator().manual_seed(0)
    env = torch.rand(7, 12, 3, dtype=torch.float64, generator=g)
    d = torch.randn(2000, 3, dtype=torch.float64, generator=g)
    d = d / d.norm(dim=-1, keepdim=True)
    poles = torch.tensor([[0, 0, 1.0], [0, 0, -1.0], [-1.0, 0, 0],
                          [-1.0, -1e-17, 0]], dtype=torch.float64)
    d = torch.cat([d, poles]).view(2, 1002, 3)
    compiled = equirect_lookup(env, d)
    differentiable = equirect_lookup(env, d.clone().requires_grad_())
    assert differentiable.requires_grad and not compiled.requires_grad
    assert compiled.shape == (2, 1002, 3)
    torch.testing.assert_close(compiled, differentiable.detach(), rtol=0,
                               atol=1e-13)
    assert equirect_lookup(env.float(), d).dtype == torch.float32


def test_rotate_envmap_turns_the_light_about_z():
    from tg_intrinsic.geometry.appearance.envmap import rotate_envmap
    envmap = torch.rand(16, 32, 3, dtype=torch.float64)
    directions = fibonacci_sphere(200, dtype=torch.float64)
    for degrees in (90.0, 33.75, -101.25):  # whole and fractional columns
        turned = rotate_envmap(envmap, degrees)
        a = math.radians(degrees)
        rotation = torch.tensor([[math.cos(a), -math.sin(a), 0],
                                 [math.sin(a), math.cos(a), 0], [0, 0, 1]],
                                dtype=torch.float64)
        # what came from d now comes from R d
        expected = equirect_lookup(envmap, directions)
        got = equirect_lookup(turned, directions @ rotation.T)
        step = 360 / 32
        if degrees % step == 0:
            assert torch.allclose(got, expected, atol=1e-12)
        else:  # interpolated twice: close, not exact
            assert (got - expected).abs().mean() < 0.1
    assert torch.equal(rotate_envmap(envmap, 360.0), envmap)


def test_blender_envmap_follows_cycles_equirectangular_lookup():
    """Cycles: u = (atan2(y, x) - pi) / (-2 pi), v = (acos(z) - pi) / (-pi)
    with v = 1 at the top row (written out from its kernel, not ours)."""
    from tg_intrinsic.geometry.appearance.envmap import blender_envmap
    height, width = 8, 16
    blender = torch.rand(height, width, 3, dtype=torch.float64)
    directions = fibonacci_sphere(300, dtype=torch.float64)
    x, y, z = directions.unbind(-1)
    u = (torch.atan2(y, x) - math.pi) / (-2 * math.pi)
    v = (torch.acos(z.clamp(-1, 1)) - math.pi) / (-math.pi)
    # the pixel a direction falls in (nearest lookup: no interpolation
    # question between the two conventions)
    col = (u * width).floor().long().clamp(0, width - 1)
    row = ((1 - v) * height).floor().long().clamp(0, height - 1)
    ours = blender_envmap(blender)
    from tg_intrinsic.geometry.appearance.envmap import direction_to_equirect
    r, c = direction_to_equirect(directions, height, width)
    got = ours[r.floor().long().clamp(0, height - 1),
               c.floor().long().clamp(0, width - 1)]
    inside = ((u * width - (u * width).round()).abs() > 1e-6)
    assert torch.equal(got[inside], blender[row, col][inside])
    assert torch.equal(blender_envmap(ours), blender)
