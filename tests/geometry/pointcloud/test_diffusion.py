import math

import pytest
import torch

from tg_intrinsic.geometry.pointcloud import SurfaceOperators
from tg_intrinsic.geometry.pointcloud.diffusion import (conductance,
                                                        perona_malik,
                                                        perona_malik_step,
                                                        spectral_radius)
from tests.conftest import fibonacci_sphere
from tests.geometry.pointcloud.conftest import build
from tests.geometry.pointcloud.test_mls import plane


@pytest.fixture(scope='module')
def sphere():
    pos = fibonacci_sphere(1500)
    _, ei, gw, dw = build(pos, pos, normalized=False)
    return pos, SurfaceOperators(ei, gw, dw, pos.size(0))


def noisy_step(pos, seed=0):
    g = torch.Generator().manual_seed(seed)
    clean = (pos[:, 0] > 0.1).to(pos.dtype)
    return clean, clean + 0.1 * torch.randn(pos.size(0), generator=g,
                                            dtype=pos.dtype)


def test_without_edge_stopping_it_is_the_heat_step(sphere):
    pos, ops = sphere
    _, u = noisy_step(pos)
    dt = 0.5 / spectral_radius(ops)
    expected = u[:, None]
    for _ in range(5):  # heat: u - dt * Laplacian u, Laplacian = -DG
        expected = expected - dt * ops.laplacian(expected)
    out = perona_malik(pos, u, steps=5, dt=dt, kind='none', operators=ops)
    assert torch.allclose(out, expected[:, 0], atol=1e-12)
    # a huge kappa is the heat step too
    far = perona_malik(pos, u, steps=5, dt=dt, kappa=1e9, operators=ops)
    assert torch.allclose(far, out, atol=1e-9)


def test_linear_signal_on_a_plane_does_not_change():
    pos, normal, R = plane(700)
    _, ei, gw, dw = build(pos, normal, regularizer=1e-9, normalized=False)
    ops = SurfaceOperators(ei, gw, dw, pos.size(0))
    a = torch.tensor([0.7, -1.3, 0.0], dtype=pos.dtype) @ R.t()
    u = (pos * a).sum(-1) + 2.0
    out = perona_malik(pos, u, steps=20, kappa=0.5, operators=ops)
    assert (out - u).abs().max() < 1e-5 * u.abs().max()
    # a quadratic does change: the test can fail
    quad = u + (pos * a).sum(-1) ** 2
    assert (perona_malik(pos, quad, steps=20, kappa=0.5, operators=ops)
            - quad).abs().max() > 1e-3


def test_edges_survive_better_than_under_heat_diffusion(sphere):
    pos, ops = sphere
    clean, u = noisy_step(pos)
    pm = perona_malik(pos, u, kappa=0.5, operators=ops)
    heat = perona_malik(pos, u, kind='none', operators=ops)
    # closer to the clean step than heat diffusion, and than the input
    assert (pm - clean).norm() < 0.5 * (heat - clean).norm()
    assert (pm - clean).norm() < (u - clean).norm()
    # the jump across the edge stays (heat flattens it)
    near = (pos[:, 0] - 0.1).abs() < 0.15
    jump = lambda f: (f[near & (pos[:, 0] > 0.1)].mean()  # noqa: E731
                      - f[near & (pos[:, 0] <= 0.1)].mean())
    assert jump(pm) > 0.75 and jump(heat) < 0.5 * jump(pm)


def test_perona_malik_energy_decreases(sphere):
    pos, ops = sphere
    _, u = noisy_step(pos, seed=1)
    u = u[:, None]
    kappa = 0.5
    dt = 1 / spectral_radius(ops)

    def energy(f):  # sum of kappa^2 / 2 log(1 + |grad f|^2 / kappa^2)
        s = ops.grad(f).square().sum(-1)
        return float((0.5 * kappa ** 2 * torch.log1p(s / kappa ** 2)).sum())

    values = [energy(u)]
    for _ in range(20):
        u = perona_malik_step(u, ops, dt, kappa)
        values.append(energy(u))
    assert all(b < a for a, b in zip(values, values[1:]))
    assert values[-1] < 0.8 * values[0]


def test_conductances():
    s = torch.tensor([0.0, 1.0, 2.0], dtype=torch.float64)
    assert torch.allclose(conductance(s, 1.0),
                          torch.tensor([1.0, 0.5, 0.2], dtype=s.dtype))
    assert torch.allclose(conductance(s, 2.0, 'exp'),
                          torch.exp(-(s / 2) ** 2))
    assert torch.equal(conductance(s, 1.0, 'none'), torch.ones_like(s))


def test_channels_and_default_operators():
    pos = fibonacci_sphere(400)
    _, u = noisy_step(pos)
    v = pos[:, 2] ** 2
    both = perona_malik(pos, torch.stack([u, v], 1), steps=3, normal=pos)
    assert both.shape == (400, 2)
    # every channel diffuses on its own (the filter is nonlinear)
    for c, f in enumerate((u, v)):
        single = perona_malik(pos, f, steps=3, normal=pos)
        assert torch.allclose(both[:, c], single, atol=1e-12)
    assert not torch.allclose(both[:, 0], u, atol=1e-3)


def test_bad_input_is_explained(sphere):
    pos, ops = sphere
    _, u = noisy_step(pos)
    rho = spectral_radius(ops)
    with pytest.raises(ValueError, match=r"too large for explicit steps"):
        perona_malik(pos, u, dt=3 / rho, operators=ops)
    with pytest.raises(ValueError, match="'signal' must be a tensor"):
        perona_malik(pos, u[:10], operators=ops)
    with pytest.raises(ValueError, match="finite floating point"):
        perona_malik(pos, torch.full_like(u, math.nan), operators=ops)
    with pytest.raises(ValueError, match="'kappa'"):
        perona_malik(pos, u, kappa=0.0, operators=ops)
    with pytest.raises(ValueError, match="'kind' must be one of"):
        perona_malik(pos, u, kind='tv', operators=ops)
    with pytest.raises(ValueError, match="built on 'pos'"):
        perona_malik(pos[:100], u[:100], operators=ops)
