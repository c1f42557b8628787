"""DeltaNetClassification: the fused channels-first embedding against the
plain PyG layers, independence of the tangent frames, invariance to the
order of the points, shapes, torch.compile and bad input."""
import math

import pytest
import torch
from torch_geometric.data import Batch, Data
from torch_geometric.nn import global_max_pool, global_mean_pool

from tg_intrinsic.nn.models import DeltaNetClassification
from tests.nn.conftest import make_batch
from tests.nn.models.machinery_checks import check_autocast, check_compiles
from tests.symmetry import rotate_frames


def _clouds(sizes, seed=0):
    generator = torch.Generator().manual_seed(seed)
    items = []
    for n in sizes:
        pos = torch.randn(n, 3, generator=generator, dtype=torch.float64)
        items.append(Data(pos=pos, normal=pos / pos.norm(dim=1,
                                                         keepdim=True)))
    return Batch.from_data_list(items)


def _reference(model, data):
    # The plain PyG path: embedding MLP on [N, C], PyG's pooling.
    x = model.embedding(torch.cat(model.base(data), dim=1))
    pooled = torch.cat([global_max_pool(x, data.batch),
                        global_mean_pool(x, data.batch)], dim=1)
    return model.head(pooled)


@pytest.mark.parametrize('dtype', [torch.float64, torch.float32])
@pytest.mark.parametrize('training', [True, False])
def test_channels_first_embedding_matches_the_mlp(training, dtype):
    # Equal-size batches take the fused channels-first path; it must give
    # the MLP's outputs, the gradients of every parameter and the same
    # running statistics, in training (batch statistics) and evaluation
    # (running statistics) mode.
    torch.manual_seed(0)
    model = DeltaNetClassification(3, 4, conv_channels=(8, 8), k=6,
                                   embedding_size=32).to(dtype)
    model.head.eval()   # no dropout, so both paths are comparable
    model.embedding.train(training)
    norm = model.embedding.norms[0].module
    with torch.no_grad():   # running statistics away from their defaults
        norm.running_mean.uniform_(-0.5, 0.5)
        norm.running_var.uniform_(0.5, 2.0)
        norm.weight.uniform_(-1.0, 1.0)   # negative scales flip the max
    start = {k: v.clone() for k, v in norm.state_dict().items()}
    data = _clouds([40, 40, 40])
    data.pos = data.pos.to(dtype)
    parameters = list(model.parameters())

    def run(forward):
        norm.load_state_dict(start)
        out = forward(model, data)
        grads = torch.autograd.grad(out.square().sum(), parameters)
        return out, grads, {k: v.clone() for k, v in
                            norm.state_dict().items()}

    ours, grads_ours, stats_ours = run(lambda m, d: m(d))
    theirs, grads_theirs, stats_theirs = run(_reference)
    tol = {} if dtype == torch.float64 else {'rtol': 1e-4, 'atol': 1e-4}
    torch.testing.assert_close(ours, theirs, **tol)
    for a, b in zip(grads_ours, grads_theirs):
        torch.testing.assert_close(a, b, **tol)
    for key in stats_theirs:
        torch.testing.assert_close(stats_ours[key], stats_theirs[key], **tol)


def test_unequal_batches_take_the_plain_path():
    torch.manual_seed(1)
    model = DeltaNetClassification(3, 4, conv_channels=(8, 8), k=6,
                                   embedding_size=16).double().eval()
    data = _clouds([30, 45])
    torch.testing.assert_close(model(data), _reference(model, data))


def test_fused_embedding_shares_gradient_among_tied_maxima():
    # Repeated rows give tied maxima; the fused pooling must split their
    # gradient evenly, as the unfused layers (and PyG's max pool) do.
    from tg_intrinsic.nn.models._embedding_pool import embed_and_pool
    from tg_intrinsic.pool import dense_max_pool
    torch.manual_seed(2)
    linear = torch.nn.Linear(5, 6, bias=False).double()
    norm = torch.nn.BatchNorm1d(6).double()
    with torch.no_grad():   # dyadic values: W x is exact, ties stay ties
        linear.weight.copy_(torch.randint(-8, 9, (6, 5)) / 8.0)
    rows = torch.randint(-4, 5, (4, 5)).double()
    x = rows[torch.tensor([0, 1, 0, 2, 3, 3, 1, 3])].requires_grad_(True)
    out = embed_and_pool(x, linear, norm, 0.2, 2)
    (ours, ) = torch.autograd.grad(out.sum(), x)
    norm.reset_running_stats()
    a = torch.nn.functional.leaky_relu(norm(linear(x)), 0.2).view(2, 4, 6)
    ref = torch.cat([dense_max_pool(a), a.mean(dim=1)], dim=1)
    (theirs, ) = torch.autograd.grad(ref.sum(), x)
    torch.testing.assert_close(out, ref)
    torch.testing.assert_close(ours, theirs)


def test_fused_embedding_refuses_a_second_backward():
    from tg_intrinsic.nn.models._embedding_pool import embed_and_pool
    linear = torch.nn.Linear(3, 4, bias=False)
    norm = torch.nn.BatchNorm1d(4)
    x = torch.randn(6, 3, requires_grad=True)
    out = embed_and_pool(x, linear, norm, 0.2, 2).sum()
    out.backward(retain_graph=True)
    with pytest.raises(RuntimeError, match='differentiated once'):
        out.backward()


@pytest.mark.parametrize('args,kwargs,match', [
    ((0, 4), {}, "'in_channels' must be at least 1, got 0"),
    ((3, 0), {}, "'num_classes' must be at least 1, got 0"),
    ((3, 4), dict(conv_channels=()), "'conv_channels' must hold at least 1"),
    ((3, 4), dict(conv_channels=(8, 0)), r"'conv_channels\[1\]' must be"),
    ((3, 4), dict(embedding_size=0), "'embedding_size' must be at least 1"),
    ((3, 4), dict(k=0), "'k' must be at least 1"),
    ((3, 4.0), {}, "'num_classes' must be an integer"),
])
def test_constructor_needs_positive_sizes(args, kwargs, match):
    with pytest.raises(ValueError, match=match):
        DeltaNetClassification(*args, **kwargs)


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


def test_torch_compile_matches_eager_without_recompiling():
    torch.manual_seed(0)
    batches = [Batch.from_data_list(make_batch(sizes, dtype=torch.float32))
               for sizes in ((200, 260, 230), (150, 180), (220, 240, 210))]
    # two narrow layers run the same operations as the default four and
    # give inductor half the graph to compile (64 s instead of 95 cold)
    check_compiles(DeltaNetClassification(3, 4, conv_channels=(16, 32), k=12,
                                          embedding_size=64), batches)


def test_bfloat16_autocast():
    torch.manual_seed(0)
    batch = Batch.from_data_list(make_batch(dtype=torch.float32))
    check_autocast(DeltaNetClassification(3, 4, k=12), batch)


def test_missing_points_and_bad_data():
    model = DeltaNetClassification(3, 4, k=12)
    tiny = Data(pos=torch.randn(8, 3))
    with pytest.raises(ValueError, match='k'):
        model(Batch.from_data_list([tiny]))
    nan = Data(pos=torch.full((50, 3), float('nan')))
    with pytest.raises(ValueError, match='NaN'):
        model(Batch.from_data_list([nan]))


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


def test_shapes_and_parameter_count():
    cls = DeltaNetClassification(3, 40)
    n_cls = sum(p.numel() for p in cls.parameters())
    assert 1.9e6 < n_cls < 2.2e6
    data_list = make_batch(dtype=torch.float32, frames=False)
    batch = Batch.from_data_list(data_list)
    assert cls(batch).shape == (3, 40)
    with pytest.raises(ValueError, match='input channels'):
        DeltaNetClassification(6, 4)(batch)
    assert 'vector_stream=True' in repr(cls)


def test_vector_stream_ablation_runs():
    batch = Batch.from_data_list(make_batch(dtype=torch.float32))
    model = DeltaNetClassification(3, 4, k=12, vector_stream=False)
    assert model(batch).shape == (3, 4)


def test_repr_shows_the_architecture():
    model = DeltaNetClassification(3, 7, conv_channels=(8, 16), k=6,
                                   vector_stream=False)
    assert repr(model) == ('DeltaNetClassification(3, 7, conv_channels=(8, '
                           '16), vector_stream=False)')


@pytest.mark.parametrize('sizes', [(40, 40), (40, 55)])
def test_logits_do_not_depend_on_the_order_of_the_points(sizes):
    # Equal sizes take the fused embedding, unequal ones PyG's pooling;
    # both must see a set of points, not a sequence.
    torch.manual_seed(3)
    model = DeltaNetClassification(3, 5, conv_channels=(8, 8), k=6,
                                   embedding_size=16).double()
    data_list = make_batch(sizes, frames=False)
    model(Batch.from_data_list(data_list))  # running statistics
    model.eval()
    out = model(Batch.from_data_list(data_list))
    generator = torch.Generator().manual_seed(4)
    shuffled = []
    for data in data_list:
        order = torch.randperm(data.num_nodes, generator=generator)
        shuffled.append(Data(pos=data.pos[order], normal=data.normal[order]))
    out2 = model(Batch.from_data_list(shuffled))
    assert out.shape == (len(sizes), 5) and out.abs().max() > 1e-3
    torch.testing.assert_close(out2, out, rtol=1e-9, atol=1e-12)
    # The two shapes get different logits: the model is not constant.
    assert not torch.allclose(out[0], out[1], rtol=1e-3, atol=1e-6)
