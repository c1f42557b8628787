import math

import pytest
import torch

from tg_intrinsic.geometry import tangent_frames
from tg_intrinsic.geometry.pointcloud.operators import rotate_j
from tg_intrinsic.nn import DeltaConv
from tests.nn.conftest import blob, no_sparse_kernel, operators
from tests.symmetry import rotate_frames, rotate_vectors


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
    reduce = {'max': 'amax', 'min': 'amin', 'add': 'sum', 'sum': 'sum',
              'mean': 'mean'}[conv.aggr]
    x_max = torch.zeros_like(out).scatter_reduce(
        0, i[:, None].expand_as(h), h, reduce, include_self=False)
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
    no_sparse_kernel(monkeypatch)
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
        (lambda: conv(x, v[:, :2], ei, ops),
         r"'v' must be float tangent vector features \[60, 3, 2\]"),
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


def test_quarter_turn_of_the_vector_stream():
    # J, which the vector stream concatenates with its input, is a turn by
    # +90 degrees: applied twice it negates.
    torch.manual_seed(0)
    v = torch.randn(50, 4, 2, dtype=torch.float64)
    assert torch.allclose(rotate_j(rotate_j(v)), -v)


def test_vector_output_needs_vector_input():
    with pytest.raises(ValueError, match='vector output'):
        DeltaConv(3, 4, vector=True, vector_input=False)


@pytest.mark.parametrize('make,match', [
    (lambda: DeltaConv(0, 8), "'in_channels' must be at least 1, got 0"),
    (lambda: DeltaConv(3, 0), "'out_channels' must be at least 1, got 0"),
    (lambda: DeltaConv(3, 8, depth=0), "'depth' must be at least 1"),
    (lambda: DeltaConv(3.5, 8), "'in_channels' must be an integer"),
])
def test_layer_constructors_need_positive_sizes(make, match):
    with pytest.raises(ValueError, match=match):
        make()


def test_repr_shows_the_options():
    assert repr(DeltaConv(3, 8, depth=2, centralized=True, vector=False)) \
        == ('DeltaConv(3, 8, depth=2, centralized=True, vector=False, '
            'vector_input=True)')


AGGREGATIONS = ['max', 'mean', 'add', 'sum', 'min', 'std']


@pytest.mark.parametrize('aggr', AGGREGATIONS)
@pytest.mark.parametrize('centralized, depth', [(False, 1), (True, 1),
                                                (True, 2)])
def test_every_aggr_is_honoured_on_every_path(aggr, centralized, depth):
    # issue 39: the operators' own edge_index took the maximum whatever aggr
    torch.manual_seed(0)
    pos, normal = blob(120)
    ei, ops = operators(pos, tangent_frames(normal), k=8)
    conv = DeltaConv(3, 6, depth=depth, centralized=centralized,
                     aggr=aggr).double().train()  # edge BN statistics too
    x = torch.randn(120, 3, dtype=torch.float64)
    v = ops.grad(x)
    sparse = conv(x, v, ei, ops)
    for other in (conv(x, v, ei.clone(), ops),
                  conv(x, v, ei, ops, backend='message')):
        for a, b in zip(sparse, other):
            assert torch.allclose(a, b, rtol=1e-9, atol=1e-10)
    if aggr != 'std':  # the oracle reduces with torch.scatter_reduce
        conv.eval()
        expected = reference_delta_conv(conv, x, v, ei, ops)
        for a, b in zip(conv(x, v, ei, ops), expected):
            assert torch.allclose(a, b, rtol=1e-9, atol=1e-10)


def test_message_backend_needs_the_operators_graph():
    pos, normal = blob(80)
    ei, ops = operators(pos, tangent_frames(normal), k=6)
    conv = DeltaConv(3, 4).double()
    x = pos.clone()
    shuffled = ei[:, torch.randperm(ei.size(1))]
    with pytest.raises(ValueError, match='graph the operators were built'):
        conv(x, ops.grad(x), shuffled, ops, backend='message')
    with pytest.raises(ValueError, match="backend must be"):
        conv(x, ops.grad(x), ei, ops, backend='fast')


def test_edge_masks_and_hooks_reach_both_streams():
    # issue 39: set_masks changed nothing, propagate hooks never fired
    from torch_geometric.explain.algorithm.utils import (clear_masks,
                                                         set_masks)
    torch.manual_seed(0)
    pos, normal = blob(100)
    ei, ops = operators(pos, tangent_frames(normal), k=8)
    conv = DeltaConv(3, 5).double().eval()
    x = pos.clone()
    v = ops.grad(x)
    plain = conv(x, v, ei, ops)
    ones = torch.full((ei.size(1), ), 50.0, dtype=torch.float64)
    set_masks(conv, ones, ei, apply_sigmoid=True)  # sigmoid(50) = 1
    for a, b in zip(conv(x, v, ei, ops), plain):
        assert torch.allclose(a, b, atol=1e-12)
    # masking every edge but the self-loops leaves no gradient at all
    keep = (ei[0] == ei[1]).double() * 100 - 50
    set_masks(conv, keep, ei, apply_sigmoid=True)
    masked = conv(x, v, ei, ops)
    assert (masked[1] - plain[1]).abs().max() > 1e-3
    assert (masked[0] - plain[0]).abs().max() > 1e-3
    clear_masks(conv)
    calls = []
    handle = conv.register_propagate_forward_hook(
        lambda module, inputs, out: calls.append(out.shape))
    hooked = conv(x, v, ei, ops)
    handle.remove()
    # G x, D then G for the Hodge Laplacian, D for the scalars, h2
    assert len(calls) == 5
    for a, b in zip(hooked, plain):
        assert torch.allclose(a, b, rtol=1e-9, atol=1e-12)


def test_explainer_on_a_delta_conv_model():
    from torch_geometric.explain import Explainer, GNNExplainer

    from tg_intrinsic.geometry.pointcloud import SurfaceOperators

    class UserModel(torch.nn.Module):
        def __init__(self):
            super().__init__()
            self.conv1 = DeltaConv(3, 8)
            self.conv2 = DeltaConv(8, 8, vector=False)
            self.lin = torch.nn.Linear(8, 3)

        def forward(self, x, edge_index, grad_weight, div_weight):
            ops = SurfaceOperators(edge_index, grad_weight, div_weight,
                                   x.size(0))
            x, v = self.conv1(x, ops.grad(x), edge_index, ops)
            x, _ = self.conv2(x, v, edge_index, ops)
            return self.lin(x).amax(0, keepdim=True)

    torch.manual_seed(0)
    pos, normal = blob(90, dtype=torch.float32)
    ei = operators(pos.double(), tangent_frames(normal.double()), k=6)[0]
    gw, dw = (w.float() for w in
              operators(pos.double(), tangent_frames(normal.double()),
                        k=6)[1].source_weights)
    explainer = Explainer(
        UserModel().eval(), GNNExplainer(epochs=15),
        explanation_type='model', edge_mask_type='object',
        model_config=dict(mode='multiclass_classification',
                          task_level='graph', return_type='raw'))
    explanation = explainer(pos, ei, grad_weight=gw, div_weight=dw)
    assert explanation.edge_mask.shape == (ei.size(1), )
    assert explanation.edge_mask.std() > 1e-3
