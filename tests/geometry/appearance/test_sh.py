"""Real spherical harmonics against scipy's complex ones, orthonormality by
exact quadrature, the stated sign convention, least-squares recovery of
band-limited signals, rotation invariance of the power spectrum, gradients
and bad input."""
import math

import numpy as np
import pytest
import torch
from scipy.special import sph_harm_y
from scipy.spatial.transform import Rotation

from tg_intrinsic.geometry.appearance.sh import (fibonacci_sphere,
                                                 fit_light, fit_sh,
                                                 light_directions,
                                                 light_fit_matrix,
                                                 num_coefficients,
                                                 power_spectrum, real_sh,
                                                 sh_index)

L_MAX = 8


def random_directions(n, seed=0):
    d = torch.randn(n, 3, dtype=torch.float64,
                    generator=torch.Generator().manual_seed(seed))
    d = d / d.norm(dim=1, keepdim=True)
    # the poles and the equator too
    extra = torch.tensor([[0, 0, 1.0], [0, 0, -1.0], [1.0, 0, 0]],
                         dtype=torch.float64)
    return torch.cat([d, extra])


def scipy_real_sh(d, l_max):
    x, y, z = d.numpy().T
    theta = np.arccos(np.clip(z, -1, 1))
    phi = np.arctan2(y, x)
    out = np.zeros((d.shape[0], num_coefficients(l_max)))
    for l in range(l_max + 1):  # noqa: E741
        for m in range(-l, l + 1):
            Y = sph_harm_y(l, abs(m), theta, phi)
            if m > 0:
                value = math.sqrt(2) * Y.real
            elif m < 0:
                value = math.sqrt(2) * Y.imag
            else:
                value = Y.real
            out[:, sh_index(l, m)] = value
    return out


def test_matches_scipy_real_form():
    d = random_directions(500)
    ours = real_sh(d, L_MAX).numpy()
    assert np.abs(ours - scipy_real_sh(d, L_MAX)).max() < 1e-10


def test_high_degrees_stay_accurate_in_both_precisions():
    """The recurrence is normalised as it goes: degree 60 matches scipy,
    and float32 stays finite (factorials would overflow it)."""
    d = random_directions(200, seed=5)
    Y = real_sh(d, 60)
    theta = torch.acos(d[:, 2]).numpy()
    phi = torch.atan2(d[:, 1], d[:, 0]).numpy()
    for l in (17, 40, 60):  # noqa: E741
        for m in (-l, -3, 0, 5, l):
            c = sph_harm_y(l, abs(m), theta, phi)
            want = c.real if m == 0 else math.sqrt(2) * (c.real if m > 0
                                                         else c.imag)
            assert np.abs(Y[:, sh_index(l, m)].numpy() - want).max() < 1e-11
    Y32 = real_sh(d.float(), 60)
    assert bool(torch.isfinite(Y32).all())
    assert (Y32.double() - Y).abs().max() < 1e-3


def test_convention_and_shapes():
    d = torch.tensor([[1.0, 0, 0], [0, 1.0, 0], [0, 0, 1.0]],
                     dtype=torch.float64)
    Y = real_sh(d, 1)
    c = math.sqrt(3 / (4 * math.pi))
    assert torch.allclose(Y[:, sh_index(1, 1)], torch.tensor([-c, 0, 0],
                                                             dtype=Y.dtype))
    assert torch.allclose(Y[:, sh_index(1, -1)], torch.tensor([0, -c, 0],
                                                              dtype=Y.dtype))
    assert torch.allclose(Y[:, sh_index(1, 0)], torch.tensor([0, 0, c],
                                                             dtype=Y.dtype))
    assert torch.allclose(Y[:, 0], torch.full((3, ), 0.5 / math.sqrt(
        math.pi), dtype=Y.dtype))
    assert real_sh(torch.zeros(2, 5, 3), 3).shape == (2, 5, 16)


def test_orthonormal_by_exact_quadrature():
    # Gauss-Legendre in z times uniform azimuths integrates every product
    # of two harmonics up to degree 8 exactly.
    nodes, weights = np.polynomial.legendre.leggauss(12)
    phi = np.arange(24) * 2 * np.pi / 24
    z, p = np.meshgrid(nodes, phi, indexing='ij')
    r = np.sqrt(1 - z ** 2)
    d = torch.tensor(np.stack([r * np.cos(p), r * np.sin(p), z], -1)
                     .reshape(-1, 3))
    w = torch.tensor(np.repeat(weights, 24) * 2 * np.pi / 24)
    Y = real_sh(d, L_MAX)
    gram = (Y * w[:, None]).t() @ Y
    assert torch.allclose(gram, torch.eye(gram.size(0), dtype=gram.dtype),
                          atol=1e-12)


def test_fit_recovers_band_limited_signals_batched():
    rng = torch.Generator().manual_seed(1)
    coefficients = torch.randn(3, num_coefficients(4), 2, dtype=torch.float64,
                               generator=rng)
    d = torch.stack([random_directions(60, seed=k) for k in range(3)])
    values = torch.einsum('bsk,bkc->bsc', real_sh(d, 4), coefficients)
    fitted = fit_sh(d, values, 4, regularizer=0.0)
    assert torch.allclose(fitted, coefficients, atol=1e-10)
    # per example equals batched; a tiny regulariser changes little
    for b in range(3):
        one = fit_sh(d[b], values[b], 4, regularizer=1e-10)
        assert torch.allclose(one, coefficients[b], atol=1e-6)


def test_regulariser_keeps_few_samples_solvable():
    d = random_directions(5)[:5]
    values = torch.ones(5, dtype=torch.float64)
    c = fit_sh(d, values, 5, weights=torch.rand(5, dtype=torch.float64),
               regularizer=1e-4)
    assert c.shape == (36, ) and bool(torch.isfinite(c).all())


def test_power_spectrum_is_rotation_invariant():
    coefficients = torch.randn(num_coefficients(L_MAX), dtype=torch.float64,
                               generator=torch.Generator().manual_seed(2))
    d = fibonacci_sphere(2000)
    R = torch.tensor(Rotation.random(random_state=3).as_matrix())
    values = real_sh(d @ R.t(), L_MAX) @ coefficients  # f(R d)
    rotated = fit_sh(d, values, L_MAX, regularizer=0.0)
    assert not torch.allclose(rotated, coefficients, atol=1e-3)
    assert torch.allclose(power_spectrum(rotated, L_MAX),
                          power_spectrum(coefficients, L_MAX), rtol=1e-8)


def test_gradients_and_fibonacci():
    d = random_directions(4).requires_grad_(True)
    assert torch.autograd.gradcheck(lambda x: real_sh(x, 3), (d, ))
    f = fibonacci_sphere(1000)
    assert torch.allclose(f.norm(dim=1), torch.ones(1000, dtype=f.dtype))
    assert abs(float(f.mean(0).norm())) < 1e-3


def test_bad_input():
    with pytest.raises(ValueError, match='l_max'):
        real_sh(torch.zeros(2, 3), -1)
    with pytest.raises(ValueError, match='3 coordinates'):
        real_sh(torch.zeros(2, 4), 2)
    with pytest.raises(ValueError, match='float'):
        real_sh(torch.zeros(2, 3, dtype=torch.long), 2)
    d = random_directions(10)
    with pytest.raises(ValueError, match='NaN'):
        fit_sh(d, torch.full((d.size(0), ), float('nan'),
                             dtype=torch.float64), 2)
    with pytest.raises(ValueError, match='one sample per direction'):
        fit_sh(d, torch.zeros(3, dtype=torch.float64), 2)
    with pytest.raises(ValueError, match='non-negative'):
        fit_sh(d, torch.zeros(d.size(0), dtype=torch.float64), 2,
               weights=-torch.ones(d.size(0), dtype=torch.float64))
    with pytest.raises(ValueError, match='expected 9'):
        power_spectrum(torch.zeros(10), 2)
    with pytest.raises(ValueError, match="'n'"):
        fibonacci_sphere(0)


def test_brdf_terms():
    from tg_intrinsic.geometry.appearance.sh import (brdf_filter,
                                          principled_to_torrance_sparrow,
                                          schlick_fresnel, smith_g1)
    alpha = torch.tensor([0.0, 0.1, 0.5], dtype=torch.float64)
    f = brdf_filter(3, alpha)
    assert f.shape == (3, 16)
    assert torch.all(f[0] == 1) and torch.all(f[:, 0] == 1)
    assert torch.isclose(f[2, sh_index(3, -2)], torch.tensor(
        math.exp(-(0.5 * 3) ** 2), dtype=torch.float64))
    # Schlick: R0 at normal incidence, 1 at grazing
    r0 = torch.tensor(0.04, dtype=torch.float64)
    cos = torch.linspace(0, 1, 11, dtype=torch.float64)
    F = schlick_fresnel(cos, r0)
    assert F[0] == 1 and torch.isclose(F[-1], r0) and (F.diff() < 0).all()
    # Smith GGX against its Lambda form, 1 / (1 + Lambda) with
    # Lambda = (sqrt(1 + alpha^2 tan^2) - 1) / 2
    cos = torch.linspace(0.05, 1, 20, dtype=torch.float64)[:, None]
    a = torch.tensor([0.05, 0.3, 0.9], dtype=torch.float64)
    tan2 = (1 - cos ** 2) / cos ** 2
    lam = (torch.sqrt(1 + a ** 2 * tan2) - 1) / 2
    assert torch.allclose(smith_g1(cos, a), 1 / (1 + lam), atol=1e-12)
    assert smith_g1(torch.tensor([0.0, -0.5]), torch.tensor(0.3)).eq(0).all()
    # principled: dielectric keeps the colour as diffuse, metal as specular
    base = torch.tensor([[0.8, 0.5, 0.2], [0.8, 0.5, 0.2]])
    kd, r0, alpha = principled_to_torrance_sparrow(
        base, torch.tensor([0.0, 1.0]), torch.tensor([0.5, 0.3]))
    assert torch.allclose(kd[0], base[0]) and torch.all(kd[1] == 0)
    assert torch.allclose(r0[0], torch.full((3, ), 0.04))
    assert torch.allclose(r0[1], base[1])
    assert torch.allclose(alpha, torch.tensor([0.25, 0.09]))


def test_principled_round_trip():
    from tg_intrinsic.geometry.appearance.sh import (
        principled_to_torrance_sparrow, torrance_sparrow_to_principled)
    g = torch.Generator().manual_seed(3)
    base = torch.rand(20000, 3, generator=g, dtype=torch.float64)
    metallic = torch.rand(20000, generator=g, dtype=torch.float64)
    metallic[:50], metallic[50:100] = 0.0, 1.0
    roughness = torch.rand(20000, generator=g, dtype=torch.float64)
    back = torrance_sparrow_to_principled(
        *principled_to_torrance_sparrow(base, metallic, roughness))
    for got, want in zip(back, (base, metallic, roughness)):
        assert torch.allclose(got, want, atol=1e-10)
    # one channel alone has two valid roots: a grey colour darker than
    # 0.04 (1 - m) resolves to the less metallic reading, and both map back
    grey = torch.full((1, 3), 0.01, dtype=torch.float64)
    kd, r0, alpha = principled_to_torrance_sparrow(
        grey, torch.tensor([0.2], dtype=torch.float64),
        torch.tensor([0.5], dtype=torch.float64))
    b, m, _ = torrance_sparrow_to_principled(kd, r0, alpha)
    assert float(m) < 0.2 + 1e-12
    kd2, r02, _ = principled_to_torrance_sparrow(b, m, alpha)
    assert torch.allclose(kd2, kd) and torch.allclose(r02, r0)


def test_fit_light_is_the_fit_matrix_over_the_upper_hemisphere():
    local = light_directions(300)
    g = torch.Generator().manual_seed(4)
    samples = torch.rand(6, 300, 3, dtype=torch.float64, generator=g)
    expected = light_fit_matrix(local, 4, 1e-3) @ samples
    torch.testing.assert_close(fit_light(local, samples, 4, 1e-3), expected,
                               rtol=1e-12, atol=1e-12)
    # samples below the horizon are not read
    lower = local[:, 2] <= 0
    changed = samples.clone()
    changed[:, lower] = 1e6
    torch.testing.assert_close(fit_light(local, changed, 4, 1e-3), expected,
                               rtol=1e-12, atol=1e-12)


def test_regularised_fit_is_the_normal_equations_solution():
    d = random_directions(40, seed=5)[:40]
    g = torch.Generator().manual_seed(5)
    values = torch.randn(3, 40, 2, dtype=torch.float64, generator=g)
    weights = torch.rand(3, 40, dtype=torch.float64, generator=g)
    ours = fit_sh(d.expand(3, 40, 3), values, 4, weights, regularizer=1e-2)
    Y = real_sh(d, 4)
    degree = torch.tensor([l for l in range(5) for _ in range(2 * l + 1)],
                          dtype=torch.float64)
    for i in range(3):
        W = torch.diag(weights[i])
        gram = Y.t() @ W @ Y + 1e-2 * torch.diag(degree.exp())
        expected = torch.linalg.solve(gram, Y.t() @ W @ values[i])
        torch.testing.assert_close(ours[i], expected, rtol=1e-10,
                                   atol=1e-12)
