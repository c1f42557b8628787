"""The renderer against brute-force quadrature of the reflection integral,
analytic answers (constant environment, white furnace by an independent 2D
quadrature), rotation symmetry; bad input. The rasteriser's own tests
are in test_raster.py, rendered images in tests/datasets/test_capture.py."""
import math

import numpy as np
import pytest
import torch

from tg_intrinsic.geometry.appearance import lighting
from tg_intrinsic.geometry.appearance.envmap import (equirect_directions,
                                                     equirect_lookup,
                                                     equirect_solid_angles)
from tg_intrinsic.geometry.appearance.lighting import render_radiance
from tg_intrinsic.geometry.appearance.sh import (
    principled_to_torrance_sparrow, schlick_fresnel, smith_g1)

from tests.geometry.appearance.scenes import (D64, material, sky_with_sun,
                                              unit)


def scene_points(num=3, views=3, seed=1):
    g = torch.Generator().manual_seed(seed)
    n = unit(torch.randn(num, 3, dtype=D64, generator=g))
    wo = unit(torch.randn(num, views, 3, dtype=D64, generator=g))
    wo = torch.where((wo * n[:, None]).sum(-1, keepdim=True) < 0, -wo, wo)
    return n, wo


def brute_force(env, n, wo, base_color, metallic, roughness, rows=512):
    """Every direction of a dense equirectangular grid (rows x 2 rows),
    bilinear radiance from torch's lookup, the BRDF as the module docstring
    states it."""
    dirs = equirect_directions(rows, 2 * rows)
    omega = equirect_solid_angles(rows, 2 * rows)
    L = equirect_lookup(env, dirs)
    kd, r0, alpha = principled_to_torrance_sparrow(
        base_color, torch.tensor(metallic, dtype=D64),
        torch.tensor(roughness, dtype=D64))
    alpha = alpha.clamp_min(1e-3)
    out = torch.zeros(wo.shape[:2] + (3, ), dtype=D64)
    for i in range(n.size(0)):
        ci = dirs @ n[i]
        weight = (omega * (ci > 0))[..., None] * L
        diffuse = (kd / math.pi * (ci.clamp_min(0)[..., None] * weight)
                   .sum((0, 1)))
        for v in range(wo.size(1)):
            co = (wo[i, v] @ n[i]).clamp_min(1e-12)
            h = unit(dirs + wo[i, v])
            ch = h @ n[i]
            D = alpha ** 2 / (math.pi * (ch ** 2 * (alpha ** 2 - 1) + 1) ** 2)
            F = schlick_fresnel((h @ wo[i, v])[..., None], r0)
            spec = (D * smith_g1(ci, alpha) * smith_g1(co, alpha)
                    / (4 * co))[..., None] * F
            out[i, v] = diffuse + (spec * weight).sum((0, 1))
    return out


@pytest.mark.parametrize('metallic', [0.0, 1.0])
@pytest.mark.parametrize('roughness', [0.2, 0.4, 0.7])
def test_converges_to_brute_force(metallic, roughness):
    env = sky_with_sun()
    n, wo = scene_points()
    bc, m, r = material(n.size(0), metallic, roughness)
    ref = brute_force(env, n, wo, bc[0], metallic, roughness)
    out = render_radiance(n, bc, m, r, wo, env, specular_samples=1024,
                          light_samples=1024)
    assert float(((out - ref).abs() / ref).max()) < 0.01
    # default quality: a few percent at worst on this sun
    out = render_radiance(n, bc, m, r, wo, env)
    assert float(((out - ref).abs() / ref).max()) < 0.04


def test_constant_environment_diffuse_is_albedo():
    env = torch.full((16, 32, 3), 2.5, dtype=D64)
    n, wo = scene_points(5, 4)
    bc = torch.rand(5, 3, dtype=D64, generator=torch.Generator()
                    .manual_seed(3))
    diffuse, _ = render_radiance(n, bc, torch.zeros(5, dtype=D64),
                                 torch.full((5, ), 0.5, dtype=D64), wo,
                                 env, separate=True)
    expected = (2.5 * bc)[:, None].expand_as(diffuse)
    torch.testing.assert_close(diffuse, expected, rtol=2e-4, atol=0)


def directional_albedo(cos_o, alpha, steps=800):
    """:math:`\\int D G_1 G_1 / (4 \\cos_o) d\\omega_i` by a midpoint rule
    over (theta_i, phi_i) of the upper hemisphere (numpy, F = 1)."""
    theta = (np.arange(steps) + 0.5) * (math.pi / 2 / steps)
    phi = (np.arange(2 * steps) + 0.5) * (math.pi / steps)
    T, P = np.meshgrid(theta, phi, indexing='ij')
    wi = np.stack([np.sin(T) * np.cos(P), np.sin(T) * np.sin(P),
                   np.cos(T)], -1)
    wo = np.array([math.sqrt(1 - cos_o ** 2), 0.0, cos_o])
    h = wi + wo
    h /= np.linalg.norm(h, axis=-1, keepdims=True)
    a2 = alpha ** 2
    D = a2 / (math.pi * (h[..., 2] ** 2 * (a2 - 1) + 1) ** 2)

    def g1(c):
        return 2 * c / (c + np.sqrt(a2 + (1 - a2) * c * c))
    integrand = D * g1(wi[..., 2]) * g1(cos_o) / (4 * cos_o)
    return float((integrand * np.sin(T)).sum() * (math.pi / 2 / steps)
                 * (math.pi / steps))


@pytest.mark.parametrize('roughness', [0.3, 0.6, 0.9])
def test_white_furnace(roughness):
    env = torch.full((16, 32, 3), 1.5, dtype=D64)
    angles = torch.tensor([0.2, 0.9, 1.35], dtype=D64)
    n = unit(torch.tensor([[0.3, -0.2, 0.9]], dtype=D64)).expand(3, 3)
    # views at the given angles from the normal
    t = unit(torch.linalg.cross(n, torch.tensor([[0, 0, 1.0]], dtype=D64)
                                .expand(3, 3)))
    wo = (torch.cos(angles)[:, None] * n
          + torch.sin(angles)[:, None] * t)[:, None]
    args = (n, torch.ones(3, 3, dtype=D64), torch.ones(3, dtype=D64),
            torch.full((3, ), roughness, dtype=D64), wo, env)
    fine = render_radiance(*args, specular_samples=1024, light_samples=1024)
    default = render_radiance(*args)
    for k in range(3):
        expected = 1.5 * directional_albedo(math.cos(float(angles[k])),
                                            roughness ** 2)
        assert abs(float(fine[k, 0, 0]) / expected - 1) < 1e-3
        assert abs(float(default[k, 0, 0]) / expected - 1) < 1e-2
        torch.testing.assert_close(fine[k, 0, 0], fine[k, 0, 2])


def rotation_z(angle):
    c, s = math.cos(angle), math.sin(angle)
    return torch.tensor([[c, -s, 0], [s, c, 0], [0, 0, 1.0]], dtype=D64)


def test_rotation_about_z():
    env = sky_with_sun()
    n, wo = scene_points(6, 3, seed=4)
    bc, m, r = material(6, 0.5, 0.45)
    shift = 5  # columns: a rotation by 5 pixel widths
    Rz = rotation_z(2 * math.pi * shift / env.size(1))
    rotated = torch.roll(env, shift, dims=1)
    d0, s0 = render_radiance(n, bc, m, r, wo, env, separate=True,
                             specular_samples=512, light_samples=512)
    d1, s1 = render_radiance(n @ Rz.T, bc, m, r, wo @ Rz.T, rotated,
                             separate=True, specular_samples=512,
                             light_samples=512)
    torch.testing.assert_close(d1, d0, rtol=1e-10, atol=0)
    assert float(((s1 - s0).abs() / (d0 + s0)).max()) < 0.01


def test_separate_parts_masks_and_back_views():
    env = sky_with_sun(16, 32)
    n, wo = scene_points(4, 3)
    wo[0, 1] = -wo[0, 1]  # now below the horizon
    bc, m, r = material(4, 0.3, 0.5)
    mask = torch.ones(4, 3, dtype=torch.bool)
    mask[2, 2] = False
    total = render_radiance(n, bc, m, r, wo, env, mask=mask)
    d, s = render_radiance(n, bc, m, r, wo, env, mask=mask, separate=True)
    torch.testing.assert_close(total, d + s)
    assert bool((total[0, 1] == 0).all()) and bool((total[2, 2] == 0).all())
    assert bool((total[1] > 0).all())
    # float32 in, float32 out; same seed, same numbers
    out32 = render_radiance(n.float(), bc.float(), m.float(), r.float(),
                            wo.float(), env.float(), mask=mask)
    assert out32.dtype == torch.float32
    torch.testing.assert_close(out32.double(), total, rtol=1e-5, atol=1e-6)


def test_render_radiance_bad_input():
    env = torch.ones(8, 16, 3, dtype=D64)
    n, wo = scene_points(2, 2)
    bc, m, r = material(2, 0.0, 0.5)
    with pytest.raises(ValueError, match='roughness'):
        render_radiance(n, bc, m, r + 0.7, wo, env)
    with pytest.raises(ValueError, match='normal'):
        render_radiance(n * float('nan'), bc, m, r, wo, env)
    with pytest.raises(ValueError, match='view_dirs'):
        render_radiance(n, bc, m, r, wo[:, :, :2], env)
    with pytest.raises(ValueError, match='view_dirs'):
        render_radiance(n, bc, m, r, torch.zeros_like(wo), env)
    with pytest.raises(ValueError, match='envmap'):
        render_radiance(n, bc, m, r, wo, -env)
    with pytest.raises(ValueError, match='base_color'):
        render_radiance(n, bc[:, :2], m, r, wo, env)
    with pytest.raises(ValueError, match='specular_samples'):
        render_radiance(n, bc, m, r, wo, env, specular_samples=0)


def test_kernel_smith_g1_is_the_appearance_packages():
    # the shading kernels inline a scalar copy (numba cannot call torch)
    cos = torch.linspace(-0.2, 1.0, 61, dtype=D64)
    for alpha in (0.05, 0.3, 0.9):
        ours = torch.tensor([lighting._smith_g1(float(c), alpha ** 2)
                             for c in cos], dtype=D64)
        torch.testing.assert_close(
            ours, smith_g1(cos, torch.tensor(alpha, dtype=D64)),
            rtol=1e-14, atol=1e-15)
