import math

import pytest
import torch
from torch_geometric.data import Batch, Data

from tg_intrinsic.geometry import knn, tangent_frames
from tg_intrinsic.geometry.pointcloud.mls import mls_grad_div
from tg_intrinsic.geometry.pointcloud.operators import (SurfaceOperators,
                                                        rotate_j)
from tg_intrinsic.nn import DeltaConv, VectorLinear, VectorMLP, VectorNonLin
from tg_intrinsic.nn.models import (DeltaNetClassification,
                                    DeltaNetSegmentation)
from tg_intrinsic.transforms import MLSOperators
from tests.conftest import fibonacci_sphere
from tests.symmetry import rotate_frames, rotate_vectors


def blob(n=300, seed=0, dtype=torch.float64):
    """A bumpy closed surface with analytic-ish normals (from a sphere)."""
    g = torch.Generator().manual_seed(seed)
    unit = fibonacci_sphere(n, dtype)
    radius = 1 + 0.2 * torch.sin(3 * unit[:, 0]) * torch.cos(2 * unit[:, 1])
    pos = unit * radius[:, None] + 0.01 * torch.randn(n, 3, generator=g,
                                                      dtype=dtype)
    return pos, unit


def operators(pos, frame, k=12):
    ei = knn(pos, k, loop=True)
    gw, dw = mls_grad_div(pos, frame, ei)
    return ei, SurfaceOperators(ei, gw, dw, pos.size(0))


def test_vector_blocks_are_equivariant():
    torch.manual_seed(0)
    v = torch.randn(50, 4, 2, dtype=torch.float64)
    theta = torch.rand(50, dtype=torch.float64) * 2 * math.pi
    mlp = VectorMLP([4, 8, 3]).double().eval()
    out = mlp(v)
    assert out.shape == (50, 3, 2)
    assert torch.allclose(mlp(rotate_vectors(v, theta)),
                          rotate_vectors(out, theta), atol=1e-12)
    assert torch.allclose(rotate_j(rotate_j(v)), -v)
    nonlin = VectorNonLin(4, batch_norm=False).double()
    zero = torch.zeros(3, 4, 2, dtype=torch.float64, requires_grad=True)
    nonlin(zero).sum().backward()
    assert torch.isfinite(zero.grad).all()
    assert repr(VectorLinear(2, 3)) == 'VectorLinear(2, 3)'


@pytest.mark.parametrize('centralized', [False, True])
def test_delta_conv_gauge_equivariance(centralized):
    torch.manual_seed(0)
    pos, normal = blob()
    frame = tangent_frames(normal)
    theta = torch.rand(pos.size(0), dtype=pos.dtype) * 2 * math.pi
    frame2 = rotate_frames(frame, theta)
    ei, ops1 = operators(pos, frame)
    _, ops2 = operators(pos, frame2)
    conv = DeltaConv(3, 8, depth=2, centralized=centralized).double().eval()
    x = torch.randn(pos.size(0), 3, dtype=pos.dtype)
    v = ops1.grad(x)
    x1, v1 = conv(x, v, ei, ops1)
    x2, v2 = conv(x, rotate_vectors(v, theta), ei, ops2)
    assert torch.allclose(x1, x2, rtol=1e-8, atol=1e-10)
    assert torch.allclose(rotate_vectors(v1, theta), v2, rtol=1e-8,
                          atol=1e-10)


def test_delta_conv_gradcheck():
    torch.manual_seed(0)
    pos, normal = blob(40)
    ei, ops = operators(pos, tangent_frames(normal), k=6)
    conv = DeltaConv(2, 3).double().eval()
    x = torch.randn(40, 2, dtype=torch.float64, requires_grad=True)
    v = torch.randn(40, 2, 2, dtype=torch.float64, requires_grad=True)

    def fn(x, v):
        out, vout = conv(x, v, ei, ops)
        return out, vout

    assert torch.autograd.gradcheck(fn, (x, v), eps=1e-6, atol=1e-5,
                                    fast_mode=True)


def make_batch(sizes=(200, 260, 230), dtype=torch.float64, frames=True):
    data_list = []
    for seed, n in enumerate(sizes):
        pos, normal = blob(n, seed, dtype)
        data = Data(pos=pos, normal=normal, y=torch.tensor([seed % 2]))
        if frames:
            data.frame = tangent_frames(normal)
        data_list.append(data)
    return data_list


def test_deltanet_coordinate_independence():
    torch.manual_seed(0)
    data_list = make_batch()
    batch = Batch.from_data_list(data_list)
    model = DeltaNetClassification(3, 4, k=12, dropout=0.0).double()
    theta = torch.rand(batch.num_nodes, dtype=torch.float64) * 2 * math.pi
    rotated = batch.clone()
    rotated.frame = rotate_frames(batch.frame, theta)

    def run(data):
        model.zero_grad()
        out = model(data)  # train mode: batch statistics
        out.square().sum().backward()
        return out.detach(), [p.grad.clone() for p in model.parameters()]

    out1, grads1 = run(batch)
    out2, grads2 = run(rotated)
    assert (out1 - out2).abs().max() <= 1e-8 * out1.abs().max()
    for g1, g2 in zip(grads1, grads2):
        assert (g1 - g2).abs().max() <= 1e-8 * g1.abs().max() + 1e-14
    # A different network on the same data does change: the test can fail.
    assert not torch.allclose(out1, model.eval()(batch))


def test_deltanet_batched_equals_per_example():
    torch.manual_seed(0)
    data_list = make_batch(frames=False)
    model = DeltaNetSegmentation(3, 5, k=12).double()
    model(Batch.from_data_list(data_list))  # populate running statistics
    model.eval()
    together = model(Batch.from_data_list(data_list))
    apart = torch.cat([model(Batch.from_data_list([d])) for d in data_list])
    assert torch.allclose(together, apart, atol=1e-10)
    # Precomputed operators (the transform) give the same result.
    pre = [MLSOperators(k=12)(d) for d in data_list]
    assert torch.allclose(model(Batch.from_data_list(pre)), together,
                          atol=1e-10)


def test_deltanet_models_shapes_and_parameter_counts():
    cls = DeltaNetClassification(3, 40)
    seg = DeltaNetSegmentation(3, 50, num_categories=16)
    n_cls = sum(p.numel() for p in cls.parameters())
    n_seg = sum(p.numel() for p in seg.parameters())
    assert 1.9e6 < n_cls < 2.2e6 and 1.3e6 < n_seg < 1.5e6
    data_list = make_batch(dtype=torch.float32, frames=False)
    for i, d in enumerate(data_list):
        d.category = torch.tensor([i])
    batch = Batch.from_data_list(data_list)
    assert cls(batch).shape == (3, 40)
    assert seg(batch).shape == (batch.num_nodes, 50)
    with pytest.raises(ValueError, match='input channels'):
        DeltaNetClassification(6, 4)(batch)
    assert 'vector_stream=True' in repr(cls)


def test_vector_stream_ablation_runs():
    batch = Batch.from_data_list(make_batch(dtype=torch.float32))
    model = DeltaNetClassification(3, 4, k=12, vector_stream=False)
    assert model(batch).shape == (3, 4)
    with pytest.raises(ValueError, match='vector output'):
        DeltaConv(3, 4, vector=True, vector_input=False)


def test_torch_compile_matches_eager():
    torch.manual_seed(0)
    batch = Batch.from_data_list(make_batch(dtype=torch.float32))
    model = DeltaNetClassification(3, 4, k=12).eval()
    eager = model(batch)
    compiled = torch.compile(model)
    assert torch.allclose(compiled(batch), eager, atol=1e-5)


def test_missing_points_and_bad_data():
    model = DeltaNetClassification(3, 4, k=12)
    tiny = Data(pos=torch.randn(8, 3))
    with pytest.raises(ValueError, match='k'):
        model(Batch.from_data_list([tiny]))
    nan = Data(pos=torch.full((50, 3), float('nan')))
    with pytest.raises(ValueError, match='NaN'):
        model(Batch.from_data_list([nan]))


def reference_delta_conv(conv, x, v, edge_index, ops):
    """DeltaConv written as the paper states it: concatenate, then MLPs."""
    from tg_intrinsic.geometry.pointcloud.operators import (cat_vectors,
                                                            vector_norm)
    j, i = edge_index
    if conv.lin_vector is not None:
        u = cat_vectors([v, ops.grad(x), ops.hodge_laplacian(v)])
        v = conv.post_vector(conv.lin_vector(cat_vectors([u, rotate_j(u)])))
    parts = [x]
    if conv.vector_input:
        parts += [ops.div(v), ops.curl(v), vector_norm(v)]
    out = conv.post_scalar(conv.lin_scalar(torch.cat(parts, 1)))
    h = conv.mlp_neighbors(x[j] - x[i]) if conv.centralized \
        else conv.mlp_neighbors(x)[j]
    x_max = torch.full_like(out, float('-inf')).scatter_reduce(
        0, i[:, None].expand_as(h), h, 'amax')
    return out + x_max, (v if conv.lin_vector is not None else None)


@pytest.mark.parametrize('kwargs', [
    dict(), dict(centralized=True), dict(depth=2), dict(vector=False),
    dict(vector=False, vector_input=False)])
def test_delta_conv_matches_paper_formula(kwargs):
    torch.manual_seed(0)
    pos, normal = blob(120)
    ei, ops = operators(pos, tangent_frames(normal), k=10)
    conv = DeltaConv(4, 6, **kwargs).double().eval()
    for p in conv.parameters():  # non-trivial weights everywhere
        torch.nn.init.normal_(p)
    x = torch.randn(120, 4, dtype=torch.float64)
    v = None if kwargs.get('vector_input') is False else ops.grad(x)
    out, vout = conv(x, v, ei, ops)
    ref, vref = reference_delta_conv(conv, x, v, ei, ops)
    assert torch.allclose(out, ref, rtol=1e-10, atol=1e-10)
    if vref is not None:
        assert torch.allclose(vout, vref, rtol=1e-10, atol=1e-10)
    # The generic path (no shared operators graph) agrees as well.
    out2, _ = conv(x, v, ei.clone(), ops)
    assert torch.allclose(out2, ref, rtol=1e-10, atol=1e-10)


def test_degenerate_clouds_give_errors_or_finite_outputs():
    model = DeltaNetClassification(3, 4, k=12).eval()
    g = torch.Generator().manual_seed(0)
    # A flat patch without normals: normals are estimated (documented).
    flat = torch.cat([torch.rand(200, 2, generator=g), torch.zeros(200, 1)],
                     1)
    out = model(Batch.from_data_list([Data(pos=flat)]))
    assert torch.isfinite(out).all()
    # Coincident points with normals given: the fit stays finite.
    dup = torch.cat([flat, flat[:50]])
    normal = torch.tensor([[0., 0, 1]]).expand(250, 3)
    out = model(Batch.from_data_list([Data(pos=dup, normal=normal)]))
    assert torch.isfinite(out).all()
    # A line has no tangent plane to estimate: a clear error.
    line = torch.stack([torch.linspace(0, 1, 100), torch.zeros(100),
                        torch.zeros(100)], 1)
    with pytest.raises(ValueError, match='degenerate'):
        model(Batch.from_data_list([Data(pos=line)]))


@pytest.mark.parametrize('train', [False, True])
def test_centralized_layer_in_linear_time_matches_per_edge(train):
    torch.manual_seed(0)
    pos, normal = blob(150)
    ei, ops = operators(pos, tangent_frames(normal), k=10)
    conv = DeltaConv(4, 6, centralized=True).double().train(train)
    for p in conv.parameters():
        torch.nn.init.normal_(p)  # negative BN scales included
    bn = conv.mlp_neighbors.norms[0].module
    bn.running_mean.normal_()
    bn.running_var.uniform_(0.5, 2.0)
    x = torch.randn(150, 4, dtype=torch.float64, requires_grad=True)
    ref_conv = DeltaConv(4, 6, centralized=True).double().train(train)
    ref_conv.load_state_dict(conv.state_dict())
    out = conv._centralized_max(x, ops)
    j, i = ops.edge_index
    ref = ops.edge_max(ref_conv.mlp_neighbors(x[j] - x[i]))
    assert torch.allclose(out, ref, rtol=1e-9, atol=1e-9)
    ref_bn = ref_conv.mlp_neighbors.norms[0].module
    assert torch.allclose(bn.running_mean, ref_bn.running_mean)
    assert torch.allclose(bn.running_var, ref_bn.running_var)
    g1, = torch.autograd.grad(out.square().sum(), x)
    g2, = torch.autograd.grad(ref.square().sum(), x)
    assert torch.allclose(g1, g2, rtol=1e-8, atol=1e-9)


def test_delta_conv_explains_missing_or_mismatched_inputs(monkeypatch):
    pos, normal = blob(60)
    ei, ops = operators(pos, tangent_frames(normal), k=6)
    x = torch.randn(60, 3, dtype=torch.float64)
    v = ops.grad(x)
    conv = DeltaConv(3, 8).double()
    # Nothing may reach the sparse products or numba sweeps first.
    from tg_intrinsic.geometry.sparse import SparseMM

    def fail(*args):
        raise AssertionError('a sparse kernel ran before the input checks')

    monkeypatch.setattr(SparseMM, 'apply', fail)
    cases = [
        (lambda: conv(x, None, ei, ops),
         r"'v' is None, but this layer has a vector stream: pass vector "
         r"features \[N, 3, 2\]; for a first layer use v = "
         r"operators.grad\(x\)"),
        (lambda: conv(x, v, ei, None),
         "'operators' is None, but this layer has a vector stream: pass "
         "SurfaceOperators"),
        (lambda: conv(x[:40], v[:40], ei, ops),
         "'x' has 40 rows but there are 60 nodes in 'operators'"),
        (lambda: conv(x, v[:, :2], ei, ops), r"'v' must be vector features"),
        (lambda: conv(x[:, :2], v, ei, ops), r"'x' must be float scalar "
                                             r"features \[N, 3\]"),
        (lambda: conv(x, v, ei.clone() + 1, ops),
         r"outside \[0, 60\): there are only 60 rows in 'x'"),
        (lambda: conv(x, v, ei, 'ops'), "'operators' must be "
                                        "SurfaceOperators"),
    ]
    for call, match in cases:
        with pytest.raises(ValueError, match=match):
            call()
    # The scalar-only layer legitimately takes neither v nor operators.
    monkeypatch.undo()
    scalar = DeltaConv(3, 8, vector=False, vector_input=False).double()
    out, vout = scalar(x, None, ei, None)
    assert out.shape == (60, 8) and vout is None
    with pytest.raises(ValueError, match=r"outside \[0, 40\)"):
        scalar(x[:40], None, ei, None)


@pytest.mark.parametrize('make,match', [
    (lambda: DeltaConv(0, 8), "'in_channels' must be at least 1, got 0"),
    (lambda: DeltaConv(3, 0), "'out_channels' must be at least 1, got 0"),
    (lambda: DeltaConv(3, 8, depth=0), "'depth' must be at least 1"),
    (lambda: DeltaConv(3.5, 8), "'in_channels' must be an integer"),
    (lambda: VectorLinear(0, 2), "'in_channels' must be at least 1"),
    (lambda: VectorNonLin(0), "'channels' must be at least 1"),
    (lambda: VectorMLP([3, 0]), r"'channels\[1\]' must be at least 1"),
    (lambda: VectorMLP([3]), "at least 2 channel count"),
    (lambda: DeltaNetSegmentation(0, 5), "'in_channels' must be at least"),
    (lambda: DeltaNetSegmentation(3, 0), "'num_classes' must be at least"),
    (lambda: DeltaNetSegmentation(3, 5, num_categories=0),
     "'num_categories' must be at least 1"),
    (lambda: DeltaNetSegmentation(3, 5, conv_channels=(8, -1)),
     r"'conv_channels\[1\]' must be at least 1"),
])
def test_layer_constructors_need_positive_sizes(make, match):
    with pytest.raises(ValueError, match=match):
        make()
