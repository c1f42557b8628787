"""SurfaceOperators: the identities of grad, div, curl and the Laplacians,
the sparse backend against the scatter reference, neighbour reductions and
bad graphs."""
import pytest
import torch

from tg_intrinsic.geometry import knn, tangent_frames
from tg_intrinsic.geometry.pointcloud import operators as ops
from tg_intrinsic.geometry.pointcloud.mls import mls_grad_div
from tg_intrinsic.geometry.pointcloud.operators import SurfaceOperators
from tests.conftest import fibonacci_sphere


def test_identities(sphere_ops):
    pos, frame, ei, gw, dw = sphere_ops
    f = torch.cat([pos, (pos[:, :1] * pos[:, 1:2]),
                   torch.sin(3 * pos[:, 2:])], 1)
    gf = ops.grad(f, ei, gw)
    scale = gf.abs().max()
    # G 1 = 0
    ones = torch.ones(pos.size(0), 1, dtype=pos.dtype)
    assert ops.grad(ones, ei, gw).abs().max() < 1e-3 * scale
    # curl grad = 0 and div J grad = 0 (the same statement, both ways),
    # small against div grad, which is not zero.
    lap = ops.div(gf, ei, dw).abs().amax(0)
    assert (ops.curl(gf, ei, dw).abs().amax(0) < 2e-2 * lap).all()
    assert (ops.div(ops.rotate_j(gf), ei, dw).abs().amax(0)
            < 2e-2 * lap).all()


def test_laplacian_of_position_is_mean_curvature_normal(sphere_ops):
    pos, frame, ei, gw, dw = sphere_ops
    lap = -ops.laplacian(pos, ei, gw, dw)  # Delta p = -2 H n on the sphere
    unit = lap / lap.norm(dim=-1, keepdim=True)
    assert ((unit * pos).sum(-1) < -0.99).all()  # parallel, pointing inwards


def test_sparse_backend_matches_scatter_reference(sphere_ops):
    pos, frame, ei, gw, dw = sphere_ops
    S = SurfaceOperators(ei, gw, dw, pos.size(0))
    torch.manual_seed(0)
    x = torch.randn(pos.size(0), 5, dtype=pos.dtype)
    v = torch.randn(pos.size(0), 5, 2, dtype=pos.dtype)
    assert torch.allclose(S.grad(x), ops.grad(x, ei, gw))
    assert torch.allclose(S.div(v), ops.div(v, ei, dw))
    assert torch.allclose(S.curl(v), ops.curl(v, ei, dw))
    assert torch.allclose(S.laplacian(x), ops.laplacian(x, ei, gw, dw))
    assert torch.allclose(S.hodge_laplacian(v),
                          ops.hodge_laplacian(v, ei, gw, dw))


def test_sparse_backend_gradients(sphere_ops):
    pos, frame, ei, gw, dw = sphere_ops
    S = SurfaceOperators(ei, gw, dw, pos.size(0))
    x = torch.randn(pos.size(0), 3, dtype=pos.dtype, requires_grad=True)
    v = torch.randn(pos.size(0), 3, 2, dtype=pos.dtype, requires_grad=True)
    (S.hodge_laplacian(S.grad(x)).square().sum() + S.curl(v).sum()).backward()
    ref_x = x.detach().requires_grad_()
    ref_v = v.detach().requires_grad_()
    (ops.hodge_laplacian(ops.grad(ref_x, ei, gw), ei, gw, dw).square().sum()
     + ops.curl(ref_v, ei, dw).sum()).backward()
    assert torch.allclose(x.grad, ref_x.grad)
    assert torch.allclose(v.grad, ref_v.grad)


@pytest.mark.parametrize('backend', ['numba', 'torch'])
def test_neighbor_max_regular_and_irregular(sphere_ops, backend):
    pos, frame, ei, gw, dw = sphere_ops
    x = torch.randn(pos.size(0), 4, dtype=pos.dtype)
    S = SurfaceOperators(ei, gw, dw, pos.size(0))
    assert S.k == 20
    ref = torch.full_like(x, float('-inf')).scatter_reduce(
        0, ei[1, :, None].expand(-1, 4), x[ei[0]], 'amax')
    assert torch.equal(S.neighbor_max(x, backend), ref)
    keep = torch.rand(ei.size(1)) < 0.7  # irregular, and shuffled
    perm = torch.randperm(int(keep.sum()))
    sub = ei[:, keep][:, perm]
    S2 = SurfaceOperators(sub, gw[keep][perm], dw[keep][perm], pos.size(0))
    assert S2.k is None
    ref2 = torch.full_like(x, float('-inf')).scatter_reduce(
        0, sub[1, :, None].expand(-1, 4), x[sub[0]], 'amax')
    ref2[torch.isinf(ref2)] = 0.0
    assert torch.equal(S2.neighbor_max(x, backend), ref2)
    # Gradients flow to the winning neighbour, as with a plain amax.
    for graph, ops_ in ((ei, S), (sub, S2)):
        xg = x.clone().requires_grad_()
        weight = torch.arange(4.0, dtype=x.dtype)
        (ops_.neighbor_max(xg, backend) * weight).sum().backward()
        xr = x.clone().requires_grad_()
        ref = torch.full_like(x, float('-inf')).scatter_reduce(
            0, graph[1, :, None].expand(-1, 4), xr[graph[0]], 'amax')
        (ref.masked_fill(torch.isinf(ref), 0.0)
         * torch.arange(4.0, dtype=x.dtype)).sum().backward()
        assert torch.allclose(xg.grad, xr.grad)
    # The shuffled edges give the same operators.
    v = torch.randn(pos.size(0), 4, 2, dtype=pos.dtype)
    assert torch.allclose(S2.div(v), ops.div(v, sub, dw[keep][perm]))
    assert torch.allclose(S2.grad(x), ops.grad(x, sub, gw[keep][perm]))


def test_surface_operators_reject_bad_graphs_and_weights():
    pos = fibonacci_sphere(50)
    ei = knn(pos, 5, loop=True)
    gw, dw = mls_grad_div(pos, tangent_frames(pos), ei)
    nan = dw.clone()
    nan[4, 1] = float('nan')
    negative = ei.clone()
    negative[0, 7] = -3
    cases = [
        (lambda: SurfaceOperators(ei, gw, dw, 40),
         r"'edge_index' holds indices in \[0, 49\], outside \[0, 40\)"),
        (lambda: SurfaceOperators(negative, gw, dw, 50), 'outside'),
        (lambda: SurfaceOperators(ei.float(), gw, dw, 50), 'torch.long'),
        (lambda: SurfaceOperators(ei, gw[:, :1], dw, 50),
         r"'grad_weight' must have shape \[250, 2\]"),
        (lambda: SurfaceOperators(ei, gw, dw[:-1], 50),
         r"'div_weight' must have shape \[250, 2\]"),
        (lambda: SurfaceOperators(ei, gw, nan, 50),
         "'div_weight' contains NaN"),
        (lambda: SurfaceOperators(ei, gw.long(), dw, 50), 'float tensor'),
        (lambda: SurfaceOperators(ei, gw, dw, -1),
         "'num_nodes' must be at least 0"),
    ]
    for call, match in cases:
        with pytest.raises(ValueError, match=match):
            call()
    S = SurfaceOperators(ei, gw, dw, 50)
    short = torch.randn(30, 2, dtype=pos.dtype)
    for call in (S.grad, S.neighbor_max, S.neighbor_sum):
        with pytest.raises(ValueError, match="'x' has 30 rows but there "
                                             "are 50 nodes in the operators"):
            call(short)
    with pytest.raises(ValueError, match="'v' has 30 rows"):
        S.div(torch.randn(30, 2, 2, dtype=pos.dtype))

