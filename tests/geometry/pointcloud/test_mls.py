import math

import pytest
import torch

from tg_intrinsic.geometry import knn, tangent_frames
from tg_intrinsic.geometry.pointcloud import operators as ops
from tg_intrinsic.geometry.pointcloud.mls import mls_grad_div
from tests.conftest import fibonacci_sphere
from tests.geometry.pointcloud.conftest import build, tangential
from tests.symmetry import random_rotation


def plane(n=900, seed=0, dtype=torch.float64):
    g = torch.Generator().manual_seed(seed)
    uv = torch.rand(n, 2, generator=g, dtype=dtype) * 2 - 1
    pos = torch.cat([uv, torch.zeros(n, 1, dtype=dtype)], 1)
    R = random_rotation(dtype, seed)
    return pos @ R.t() + 3.0, R[:, 2].expand(n, 3).clone(), R


@pytest.mark.parametrize('regularizer,tol,median_tol',
                         [(1e-3, 0.1, 1e-2), (1e-9, 1e-6, 1e-7)])
def test_gradient_of_linear_function_on_plane_is_exact(regularizer, tol,
                                                       median_tol):
    pos, normal, R = plane()
    frame, ei, gw, dw = build(pos, normal, regularizer=regularizer,
                              normalized=False)
    a = torch.tensor([0.7, -1.3, 0.0], dtype=pos.dtype) @ R.t()  # in-plane
    f = (pos * a).sum(-1, keepdim=True) + 2.0
    g = ops.grad(f, ei, gw)[:, 0]
    expected = tangential(frame, a.expand_as(pos))
    # Interior points: on the boundary the one-sided fit is still exact
    # without regulariser, but its bias is larger there.
    uv = (pos - 3.0) @ R[:, :2]
    inner = (uv.abs() < 0.8).all(-1)
    err = (g - expected).norm(dim=-1) / a.norm()
    # The regulariser biases the slope where the neighbourhood is lopsided.
    assert err[inner].max() < tol and err[inner].median() < median_tol
    assert err.max() < (tol if regularizer < 1e-6 else 0.5)


def sphere_error(n, k=20):
    pos = fibonacci_sphere(n)
    frame, ei, gw, dw = build(pos, pos, k=k, normalized=False,
                              regularizer=1e-6)
    errs = []
    for axis in range(3):
        e = torch.zeros(3, dtype=pos.dtype)
        e[axis] = 1.0
        g = ops.grad(pos[:, axis:axis + 1], ei, gw)[:, 0]
        errs.append((g - tangential(frame, e.expand_as(pos))).norm(dim=-1))
    return torch.stack(errs).max().item()


def test_gradient_on_sphere_converges():
    errors = [sphere_error(n) for n in (500, 2000, 8000)]
    assert errors[0] > errors[1] > errors[2]
    assert errors[2] < 5e-3


def test_gradient_on_paraboloid():
    errors = []
    for n in (30, 60):
        g = torch.linspace(-1, 1, n, dtype=torch.float64)
        u, v = torch.meshgrid(g, g, indexing='ij')
        u, v = u.flatten(), v.flatten()
        z = 0.5 * u ** 2 - 0.3 * v ** 2
        pos = torch.stack([u, v, z], 1)
        normal = torch.stack([-u, 0.6 * v, torch.ones_like(u)], 1)
        normal = normal / normal.norm(dim=-1, keepdim=True)
        frame, ei, gw, _ = build(pos, normal, normalized=False,
                                 regularizer=1e-8)
        inner = (u.abs() < 0.7) & (v.abs() < 0.7)
        # f = z: the surface gradient is the tangential part of e_z.
        gz = ops.grad(pos[:, 2:], ei, gw)[:, 0]
        ez = torch.tensor([0., 0, 1], dtype=pos.dtype).expand_as(pos)
        errors.append((gz - tangential(frame, ez))[inner].norm(dim=-1).max())
    assert errors[1] < errors[0] and errors[1] < 5e-3


def test_frame_rotation_rotates_gradient(sphere_ops):
    """Gauge: rotating every frame by its own angle rotates G f with it and
    leaves D G f unchanged."""
    pos, frame, ei, gw, dw = sphere_ops
    theta = torch.rand(pos.size(0), dtype=pos.dtype) * 2 * math.pi
    c, s = torch.cos(theta)[:, None], torch.sin(theta)[:, None]
    rotated = frame.clone()
    rotated[:, 0] = c * frame[:, 0] + s * frame[:, 1]
    rotated[:, 1] = -s * frame[:, 0] + c * frame[:, 1]
    gw2, dw2 = mls_grad_div(pos, rotated, ei)
    f = pos[:, :2] ** 2
    g1, g2 = ops.grad(f, ei, gw), ops.grad(f, ei, gw2)
    # coordinates in the rotated frame: R(-theta) applied to g1
    expect = torch.stack([c * g1[..., 0] + s * g1[..., 1],
                          -s * g1[..., 0] + c * g1[..., 1]], -1)
    assert torch.allclose(g2, expect, atol=1e-10)
    assert torch.allclose(ops.div(g2, ei, dw2), ops.div(g1, ei, dw),
                          atol=1e-10)


def test_batched_equals_separate():
    a = fibonacci_sphere(600)
    b = 2.0 * fibonacci_sphere(900) + 0.3
    pos = torch.cat([a, b])
    normal = torch.cat([a, (b - 0.3) / 2.0])
    batch = torch.cat([torch.zeros(600), torch.ones(900)]).long()
    _, ei, gw, dw = build(pos, normal, batch=batch)
    _, _, gwa, dwa = build(a, a)
    _, _, gwb, dwb = build(b, (b - 0.3) / 2.0)
    assert torch.allclose(gw, torch.cat([gwa, gwb]))
    assert torch.allclose(dw, torch.cat([dwa, dwb]))


def test_scale_invariance_when_normalized(sphere_ops):
    pos, frame, ei, gw, dw = sphere_ops
    gw2, dw2 = mls_grad_div(7.5 * pos, frame, ei)
    assert torch.allclose(gw, gw2) and torch.allclose(dw, dw2)


def test_degenerate_fits_stay_finite():
    line = torch.stack([torch.linspace(0, 1, 50), torch.zeros(50),
                        torch.zeros(50)], 1).double()
    normal = torch.tensor([[0., 0, 1]], dtype=line.dtype).expand(50, 3)
    _, ei, gw, dw = build(line, normal, k=8)
    assert torch.isfinite(gw).all() and torch.isfinite(dw).all()
    # Along the line the derivative is still measured.
    g = ops.grad(line[:, :1], ei, gw)[:, 0]
    assert (g[5:-5, 0].abs() > 0).all()
    dup = torch.zeros(10, 3, dtype=torch.float64)
    with pytest.raises(ValueError, match='duplicate'):
        build(dup, torch.tensor([[0., 0, 1]]).double().expand(10, 3), k=4)


def test_bad_inputs():
    pos = fibonacci_sphere(50)
    frame = tangent_frames(pos)
    ei = knn(pos, 5, loop=True)
    with pytest.raises(ValueError, match='frame'):
        mls_grad_div(pos, frame.float(), ei)
    with pytest.raises(ValueError, match='frame'):
        mls_grad_div(pos, frame[:10], ei)
    with pytest.raises(ValueError, match='outside'):
        mls_grad_div(pos, frame, ei + 1)
    with pytest.raises(ValueError, match='regularizer'):
        mls_grad_div(pos, frame, ei, regularizer=0.0)
    bad = pos.clone()
    bad[3, 0] = float('nan')
    with pytest.raises(ValueError, match='NaN'):
        mls_grad_div(bad, frame, ei)

