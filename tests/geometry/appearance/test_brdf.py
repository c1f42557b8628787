"""Frequency-domain reflection and spectral uncertainty
(tg_intrinsic.geometry.appearance.brdf)."""
import math

import pytest
import torch
from scipy.spatial.transform import Rotation

from tg_intrinsic.geometry.appearance.brdf import (
    lobe_degree_sums, lobe_filter, observed_spectra, principled_reflectance,
    principled_reflectance_jacobian, reflect, sh_reflectance,
    spectral_uncertainty, to_local)
from tg_intrinsic.geometry.pointcloud.frames import tangent_frames
from tg_intrinsic.geometry.appearance.sh import (fibonacci_sphere, fit_sh,
                                      principled_to_torrance_sparrow,
                                      real_sh, schlick_fresnel, smith_g1)

L_MAX = 5


def unit(v):
    return v / v.norm(dim=-1, keepdim=True)


def dirac_light(direction, l_max=L_MAX):
    """SH of a unit-power Dirac light in `direction` (N, 3): (N, K, 3)."""
    return real_sh(direction, l_max).unsqueeze(-1).repeat(1, 1, 3)


def test_reflect_and_local_frames():
    g = torch.Generator().manual_seed(0)
    n = unit(torch.randn(50, 3, generator=g, dtype=torch.float64))
    w = unit(torch.randn(50, 7, 3, generator=g, dtype=torch.float64))
    r = reflect(w, n.unsqueeze(1))
    # same angle to the normal, in the plane of n and w, unit length
    assert torch.allclose((r * n.unsqueeze(1)).sum(-1),
                          (w * n.unsqueeze(1)).sum(-1))
    assert torch.allclose(r.norm(dim=-1), torch.ones(50, 7,
                                                     dtype=torch.float64))
    assert torch.allclose(reflect(r, n.unsqueeze(1)), w)
    local = to_local(w, tangent_frames(n))
    assert torch.allclose(local[..., 2], (w * n.unsqueeze(1)).sum(-1))
    assert torch.allclose(local.norm(dim=-1), torch.ones(50, 7,
                                                         dtype=torch.float64))


def test_filter_identity_recovers_parameters():
    """Filter known incoming SH with known (Ks, alpha), fit both back from
    sparse mirror directions, and read (Ks, alpha) off the spectra."""
    g = torch.Generator().manual_seed(1)
    num = 40
    light_dir = unit(torch.randn(num, 3, generator=g, dtype=torch.float64))
    light = dirac_light(light_dir) + 0.3 * torch.randn(
        num, 36, 3, generator=g, dtype=torch.float64)
    ks = 0.2 + 0.8 * torch.rand(num, generator=g, dtype=torch.float64)
    # below r = 0.3 the lobe barely changes degrees <= 5 (e^{-2 r^4 25} >
    # 0.66), so the grid cannot resolve it; tested in the end-to-end runs
    roughness = 0.3 + 0.45 * torch.rand(num, generator=g,
                                        dtype=torch.float64)
    lobe = lobe_filter(L_MAX, roughness ** 2)
    outgoing = ks[:, None, None] * lobe.unsqueeze(-1) * light
    # 60 sparse samples of both, on the upper hemisphere
    directions = unit(torch.randn(num, 60, 3, generator=g,
                                  dtype=torch.float64))
    directions[..., 2] = directions[..., 2].abs()
    basis = real_sh(directions, L_MAX)
    fit_in = fit_sh(directions, basis @ light, L_MAX, regularizer=1e-9)
    fit_out = fit_sh(directions, basis @ outgoing, L_MAX, regularizer=1e-9)
    spectrum_in, spectrum_out = observed_spectra(fit_in, fit_out)
    entropy, likelihood, r_hat, ks_hat = spectral_uncertainty(
        spectrum_in, spectrum_out, grid=(64, 64))
    cell = 1 / 63
    assert (r_hat - roughness).abs().max() <= 1.5 * cell
    assert (ks_hat - ks[:, None]).abs().max() <= 3 * cell
    assert likelihood.shape == (num, 64, 64)
    assert torch.allclose(likelihood.sum((-2, -1)),
                          torch.ones(num, dtype=torch.float64))
    assert bool(((entropy >= 0) & (entropy <= 1)).all())


def test_prefiltered_light_is_undone():
    """Light band-limited by alpha' gives the same answer once alpha' is
    passed on."""
    g = torch.Generator().manual_seed(2)
    light = dirac_light(unit(torch.randn(10, 3, generator=g,
                                         dtype=torch.float64)))
    roughness = torch.linspace(0.35, 0.8, 10, dtype=torch.float64)
    outgoing = 0.7 * lobe_filter(L_MAX, roughness ** 2).unsqueeze(-1) * light
    blurred = lobe_filter(L_MAX, torch.tensor(0.1, dtype=torch.float64)
                          ).unsqueeze(-1) * light
    spectra = observed_spectra(blurred, outgoing)
    _, _, r_hat, _ = spectral_uncertainty(*spectra, grid=(32, 64),
                                          prefilter_alpha=0.1)
    _, _, r_raw, _ = spectral_uncertainty(*spectra, grid=(32, 64))
    assert (r_hat - roughness).abs().max() <= 1 / 63
    # ignoring alpha' biases low roughness down: alpha^2 - alpha'^2
    assert float(r_raw[0]) < float(roughness[0]) - 0.05


def test_entropy_behaviour_of_figure_5_4():
    """Low (~0.25) for a Dirac light with a visible lobe; clearly higher for
    light with only low frequencies and for a tiny Ks."""
    g = torch.Generator().manual_seed(3)
    direction = unit(torch.randn(1, 3, generator=g, dtype=torch.float64))
    dirac = dirac_light(direction)
    smooth = dirac.clone()
    smooth[:, 4:] = 0  # degrees 0 and 1 only
    lobe = lobe_filter(L_MAX, torch.tensor([0.09], dtype=torch.float64)
                       ).unsqueeze(-1)

    def entropy(light, ks):
        return float(spectral_uncertainty(*observed_spectra(
            light, ks * lobe * light))[0])

    sharp = entropy(dirac, 0.9)
    assert 0.1 < sharp < 0.4
    assert entropy(smooth, 0.9) > sharp + 0.15
    assert entropy(dirac, 0.02) > sharp + 0.4
    # nothing observed: a flat likelihood
    zero = torch.zeros_like(dirac)
    assert math.isclose(entropy(zero, 0.0), 1.0, abs_tol=1e-9)


def test_uncertainty_is_rotation_invariant():
    """Rotating light and reflection together leaves spectra, entropy and
    the estimate unchanged (the fit at rotated directions)."""
    g = torch.Generator().manual_seed(4)
    light = dirac_light(unit(torch.randn(5, 3, generator=g,
                                         dtype=torch.float64))) \
        + 0.2 * torch.randn(5, 36, 3, generator=g, dtype=torch.float64)
    outgoing = 0.6 * lobe_filter(L_MAX, torch.full(
        (5, ), 0.2, dtype=torch.float64)).unsqueeze(-1) * light
    dirs = fibonacci_sphere(400)
    rotation = torch.tensor(Rotation.random(random_state=7).as_matrix())
    # values of the rotated functions at dirs = originals at R^T dirs
    basis = real_sh(dirs @ rotation, L_MAX)
    rotated = [fit_sh(dirs.expand(5, -1, -1), basis @ f, L_MAX,
                      regularizer=0.0) for f in (light, outgoing)]
    a = spectral_uncertainty(*observed_spectra(light, outgoing))
    b = spectral_uncertainty(*observed_spectra(*rotated))
    for x, y in zip(a, b):
        assert torch.allclose(x, y, atol=1e-6)


def test_reflectance_under_constant_light():
    """Constant radiance L0: B = Kd L0 + F G L0 exactly (the lobe keeps
    the mean; E = pi L0)."""
    g = torch.Generator().manual_seed(5)
    num, views = 20, 6
    base = torch.rand(num, 3, generator=g, dtype=torch.float64)
    metallic = torch.rand(num, generator=g, dtype=torch.float64)
    roughness = torch.rand(num, generator=g, dtype=torch.float64)
    l0 = torch.tensor([1.0, 2.0, 0.5], dtype=torch.float64)
    sh_in = torch.zeros(num, 36, 3, dtype=torch.float64)
    sh_in[:, 0] = l0 * math.sqrt(4 * math.pi)
    mirror = unit(torch.randn(num, views, 3, generator=g,
                              dtype=torch.float64))
    mirror[..., 2] = mirror[..., 2].abs()
    cos = mirror[..., 2]
    out = sh_reflectance(sh_in, math.pi * l0.expand(num, 3), mirror, base,
                         metallic, roughness, prefilter_alpha=0.1)
    kd, r0, alpha = principled_to_torrance_sparrow(base, metallic, roughness)
    fresnel = schlick_fresnel(cos.unsqueeze(-1), r0.unsqueeze(1))
    masking = smith_g1(cos, alpha.clamp_min(1e-3).unsqueeze(-1)).unsqueeze(-1)
    want = kd.unsqueeze(1) * l0 + fresnel * masking * l0
    assert torch.allclose(out, want, atol=1e-12)
    # gradients reach every parameter
    base.requires_grad_(), metallic.requires_grad_(), roughness.requires_grad_()
    light = sh_in.clone()
    light[:, 5] = 1.0
    sh_reflectance(light, math.pi * l0.expand(num, 3), mirror, base,
                   metallic, roughness).sum().backward()
    for p in (base, metallic, roughness):
        assert p.grad is not None and bool(torch.isfinite(p.grad).all())
        assert p.grad.abs().sum() > 0


@pytest.mark.parametrize('dtype', [torch.float32, torch.float64])
def test_large_batch_is_chunked_and_dtype_stable(dtype):
    g = torch.Generator().manual_seed(6)
    light = dirac_light(unit(torch.randn(300, 3, generator=g,
                                         dtype=torch.float64)))
    outgoing = 0.8 * lobe_filter(L_MAX, torch.full(
        (300, ), 0.16, dtype=torch.float64)).unsqueeze(-1) * light
    spectra = [s.to(dtype) for s in observed_spectra(light, outgoing)]
    whole = spectral_uncertainty(*spectra)
    chunked = spectral_uncertainty(*spectra, chunk_size=7)
    for x, y in zip(whole, chunked):
        assert x.dtype == dtype and torch.allclose(x, y, atol=1e-6)


def test_compiled_grid_matches_the_torch_grid(monkeypatch):
    """The CPU kernel and the broadcast path (used on GPUs) agree."""
    import tg_intrinsic.geometry.appearance.brdf as brdf
    g = torch.Generator().manual_seed(8)
    light = dirac_light(unit(torch.randn(200, 3, generator=g,
                                         dtype=torch.float64))) \
        + 0.3 * torch.randn(200, 36, 3, generator=g, dtype=torch.float64)
    roughness = torch.rand(200, generator=g, dtype=torch.float64)
    outgoing = torch.rand(200, 1, 3, generator=g, dtype=torch.float64) \
        * lobe_filter(L_MAX, roughness ** 2).unsqueeze(-1) * light
    spectra = observed_spectra(light, outgoing)
    compiled = spectral_uncertainty(*spectra, grid=(16, 24), sigma=0.05,
                                    prefilter_alpha=0.05)
    monkeypatch.setattr(brdf, '_grid_cpu', brdf._grid_torch)
    broadcast = spectral_uncertainty(*spectra, grid=(16, 24), sigma=0.05,
                                     prefilter_alpha=0.05)
    for x, y in zip(compiled, broadcast):
        assert x.shape == y.shape and torch.allclose(x, y, atol=1e-10)


def _albedo_by_quadrature(theta_o, alpha, r0, n=600):
    """Independent 2D quadrature of the GGX + Schlick albedo (numpy)."""
    import numpy as np
    th = (np.arange(n) + 0.5) / n * np.pi / 2
    ph = (np.arange(2 * n) + 0.5) / (2 * n) * 2 * np.pi
    T, P = np.meshgrid(th, ph, indexing='ij')
    wi = np.stack([np.sin(T) * np.cos(P), np.sin(T) * np.sin(P), np.cos(T)],
                  -1)
    wo = np.array([np.sin(theta_o), 0.0, np.cos(theta_o)])
    h = wi + wo
    h /= np.linalg.norm(h, axis=-1, keepdims=True)
    D = alpha ** 2 / (np.pi * (h[..., 2] ** 2 * (alpha ** 2 - 1) + 1) ** 2)

    def g1(c):
        return 2 * c / (c + np.sqrt(alpha ** 2 + (1 - alpha ** 2) * c * c))

    F = r0 + (1 - r0) * (1 - (h * wo).sum(-1)) ** 5
    f = D * g1(wi[..., 2]) * g1(wo[2]) * F / (4 * wi[..., 2] * wo[2])
    dw = np.sin(T) * (np.pi / 2 / n) * (2 * np.pi / (2 * n))
    return float((f * wi[..., 2] * dw).sum())


def test_split_sum_reflects_uniform_light_exactly():
    """The split-sum model's directional albedo table against an
    independent quadrature, and uniform light reflected with it."""
    from tg_intrinsic.geometry.appearance.brdf import ggx_albedo
    cases = [(0.2, 0.1), (0.7, 0.4), (1.2, 0.6), (0.4, 0.85)]
    cos = torch.tensor([[math.cos(t) for t, _ in cases]],
                       dtype=torch.float64)
    for i, (theta, r) in enumerate(cases):
        for r0 in (0.04, 0.9):
            got = ggx_albedo(cos[:, i:i + 1], torch.tensor(
                [r], dtype=torch.float64), torch.full(
                (1, 3), r0, dtype=torch.float64))[0, 0, 0]
            want = _albedo_by_quadrature(theta, r * r, r0)
            assert abs(float(got) - want) < 0.01 * want + 2e-3, (theta, r, r0)
    # uniform light: B = Kd L + (R0 A + B) L whatever the roughness
    num = 4
    l0 = 2.0
    sh_in = torch.zeros(num, 36, 3, dtype=torch.float64)
    sh_in[:, 0] = l0 * math.sqrt(4 * math.pi)
    mirror = torch.tensor([[[math.sin(t), 0.0, math.cos(t)]
                            for t, _ in cases]] * num, dtype=torch.float64)
    base = torch.full((num, 3), 0.6, dtype=torch.float64)
    metallic = torch.tensor([0.0, 0.3, 0.7, 1.0], dtype=torch.float64)
    roughness = torch.tensor([0.1, 0.4, 0.6, 0.85], dtype=torch.float64)
    out = sh_reflectance(sh_in, math.pi * l0 * torch.ones(num, 3,
                                                          dtype=torch.float64),
                         mirror, base, metallic, roughness,
                         specular_model='split_sum')
    kd, r0, _ = principled_to_torrance_sparrow(base, metallic, roughness)
    want = kd.unsqueeze(1) * l0 + l0 * ggx_albedo(mirror[..., 2], roughness,
                                                  r0)
    assert torch.allclose(out, want, atol=1e-10)


@pytest.mark.parametrize('dtype', [torch.float32, torch.float64])
def test_a_channel_without_light_is_uninformative_not_an_overflow(dtype):
    # Seen in float32 captures: one colour channel of the light is black
    # while the observations hold a little noise in it; dividing by its
    # power overflowed and left the K_s index unset.
    g = torch.Generator().manual_seed(9)
    light = dirac_light(unit(torch.randn(50, 3, generator=g,
                                         dtype=torch.float64)))
    outgoing = 0.8 * lobe_filter(L_MAX, torch.full(
        (50, ), 0.16, dtype=torch.float64)).unsqueeze(-1) * light
    light[..., 2] = 0
    outgoing[..., 2] += 1e-3 * torch.randn(50, outgoing.size(1),
                                           generator=g, dtype=torch.float64)
    entropy, likelihood, r_hat, ks_hat = spectral_uncertainty(
        *[s.to(dtype) for s in observed_spectra(light, outgoing)])
    for value in (entropy, likelihood, r_hat, ks_hat):
        assert value.dtype == dtype and bool(torch.isfinite(value).all())
    assert bool((ks_hat >= 0).all() and (ks_hat <= 1).all())
    # the lit channels still decide: the same answer as without channel 2
    lit = spectral_uncertainty(*[s[..., :2].to(dtype) for s in
                                 observed_spectra(light, outgoing)])
    assert torch.allclose(entropy, lit[0]) and torch.equal(r_hat, lit[2])


def random_reflection_inputs(num=7, views=5, l_max=L_MAX, seed=0):
    g = torch.Generator().manual_seed(seed)
    sh_in = torch.randn(num, (l_max + 1) ** 2, 3, dtype=torch.float64,
                        generator=g)
    irradiance = torch.rand(num, 3, dtype=torch.float64, generator=g)
    mirror = unit(torch.randn(num, views, 3, dtype=torch.float64,
                              generator=g))
    mirror[..., 2] = mirror[..., 2].abs()
    base = torch.rand(num, 3, dtype=torch.float64, generator=g)
    metallic = torch.rand(num, dtype=torch.float64, generator=g)
    roughness = 0.1 + 0.8 * torch.rand(num, dtype=torch.float64, generator=g)
    roughness[0] = 0.01  # below the model's alpha floor
    return sh_in, irradiance, mirror, base, metallic, roughness


def test_per_degree_filter_and_sums_rebuild_the_lobe():
    alpha = torch.tensor([0.05, 0.3, 0.9], dtype=torch.float64)
    per_degree = lobe_filter(L_MAX, alpha, 0.2, per_degree=True)
    assert per_degree.shape == (3, L_MAX + 1)
    full = lobe_filter(L_MAX, alpha, 0.2)
    for l in range(L_MAX + 1):  # noqa: E741
        assert torch.equal(full[:, l * l:(l + 1) ** 2],
                           per_degree[:, l:l + 1].expand(-1, 2 * l + 1))
    sh_in, _, mirror, *_ = random_reflection_inputs()
    basis = real_sh(mirror, L_MAX)
    sums = lobe_degree_sums(sh_in, basis)
    assert sums.shape == (7, 5, 3, L_MAX + 1)
    # summed over degrees: the light itself along the directions
    torch.testing.assert_close(sums.sum(-1), basis @ sh_in)


@pytest.mark.parametrize('model,fresnel,masking', [
    ('eq5.11', True, True), ('eq5.11', False, True), ('eq5.11', True, False),
    ('split_sum', True, True)])
def test_material_part_and_its_jacobian(model, fresnel, masking):
    sh_in, irradiance, mirror, base, metallic, roughness = \
        random_reflection_inputs()
    reference = sh_reflectance(sh_in, irradiance, mirror, base, metallic,
                               roughness, 0.2, fresnel, masking, model)
    from tg_intrinsic.geometry.appearance.brdf import dominant_direction
    direction = dominant_direction(mirror, roughness) \
        if model == 'split_sum' else mirror
    sums = lobe_degree_sums(sh_in, real_sh(direction, L_MAX))
    args = (sums, irradiance, mirror)
    options = (0.2, fresnel, masking, model)
    value = principled_reflectance(*args, base, metallic, roughness,
                                   *options)
    torch.testing.assert_close(value, reference, rtol=1e-12, atol=1e-12)
    value, jacobian = principled_reflectance_jacobian(
        *args, base, metallic, roughness, *options)
    torch.testing.assert_close(value, reference, rtol=1e-12, atol=1e-12)

    def of_parameters(x):
        return principled_reflectance(*args, x[:, :3], x[:, 3], x[:, 4],
                                      *options)
    x = torch.cat([base, metallic[:, None], roughness[:, None]], 1)
    full = torch.autograd.functional.jacobian(of_parameters, x)
    per_point = torch.stack([full[i, :, :, i] for i in range(x.size(0))])
    torch.testing.assert_close(jacobian, per_point, rtol=1e-10, atol=1e-12)
