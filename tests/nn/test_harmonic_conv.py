import math

import numpy as np
import pytest
import torch
from scipy import integrate, special

from tg_intrinsic.geometry.geodesics.harmonic import (HarmonicOperator,
                                                      harmonic_terms)
from tg_intrinsic.nn import (ComplexBatchNorm, ComplexLinear, ComplexReLU,
                             HarmonicConv, HarmonicResNetBlock)
from tg_intrinsic.nn.harmonic_resnet_block import harmonic_operators
from tests.conftest import rel
from tests.nn.conftest import C128, no_sparse_kernel, random_discs
from tests.symmetry import gauge_change, rotate_streams


@pytest.mark.parametrize('prev_order,max_order,separate,offset', [
    (0, 1, True, True), (1, 1, True, True), (1, 2, False, True),
    (2, 2, True, False), (2, 1, False, False)])

def test_sparse_aggregation_equals_per_edge_messages(prev_order, max_order,
                                                     separate, offset):
    edge_index, logmap, transport, weight, radius = random_discs()
    harmonic = harmonic_terms(edge_index, logmap, weight, radius, 5,
                              max(prev_order, max_order))
    torch.manual_seed(0)
    conv = HarmonicConv(3, 4, max_order, 5, prev_order, offset,
                        separate).double()
    x = torch.randn(60, prev_order + 1, 3, dtype=C128, requires_grad=True)
    fast = conv(x, edge_index, harmonic, transport)
    slow = conv(x, edge_index, harmonic, transport, backend='message')
    assert fast.shape == (60, max_order + 1, 4)
    assert rel(fast, slow) < 1e-12
    params = [x] + list(conv.parameters())
    g_fast = torch.autograd.grad(fast.abs().sum(), params)
    g_slow = torch.autograd.grad(slow.abs().sum(), params)
    for a, b in zip(g_fast, g_slow):
        assert rel(a, b) < 1e-10


def test_real_input_is_stream_zero():
    edge_index, logmap, transport, weight, radius = random_discs()
    harmonic = harmonic_terms(edge_index, logmap, weight, radius, 4, 1)
    conv = HarmonicConv(2, 3, 1, 4, prev_order=0).double()
    x = torch.randn(60, 2, dtype=torch.float64)
    out = conv(x, edge_index, harmonic, transport)
    ref = conv(torch.complex(x, 0 * x).unsqueeze(1), edge_index, harmonic,
               transport)
    assert torch.equal(out, ref)


@pytest.mark.parametrize('max_order', [1, 2])
def test_gauge_equivariance_of_every_block(max_order):
    edge_index, logmap, transport, weight, radius = random_discs(seed=1)
    rings = 4
    gen = torch.Generator().manual_seed(5)
    angle = torch.rand(60, dtype=torch.float64, generator=gen) * 2 * math.pi
    logmap2, transport2 = gauge_change(edge_index, logmap, transport, angle)
    torch.manual_seed(1)
    conv = HarmonicConv(3, 4, max_order, rings, prev_order=max_order).double()
    block = HarmonicResNetBlock(4, 6, max_order, rings, max_order).double()
    lin = ComplexLinear(6, 5).double()
    act = ComplexReLU(5).double()
    torch.nn.init.constant_(act.bias, -0.3)
    norm = ComplexBatchNorm(5, max_order + 1).double()
    pairs = [(max_order + 1, max_order + 1)]

    def network(logmap, transport, x):
        harmonic = harmonic_terms(edge_index, logmap, weight, radius, rings,
                                  max_order)
        ops = harmonic_operators(edge_index, harmonic, transport, 60, pairs)
        h = conv(x, edge_index, harmonic, transport)
        h = block(h, ops)
        return norm(act(lin(h)))

    x = torch.randn(60, max_order + 1, 3, dtype=C128)
    out = network(logmap, transport, x)
    out2 = network(logmap2, transport2, rotate_streams(x, angle))
    assert out.abs().max() > 1e-3
    assert rel(out2, rotate_streams(out, angle)) < 1e-8
    # order 0 is invariant
    assert rel(out2[:, 0], out[:, 0]) < 1e-8


def test_centre_carries_no_angular_term():
    # A disc with only its centre: m != 0 outputs must vanish, m = 0 not.
    n = 5
    edge_index = torch.arange(n).repeat(2, 1)
    logmap = torch.zeros(n, 2, dtype=torch.float64)
    logmap[:, 1] = 1.234  # a meaningless angle must not leak in
    harmonic = harmonic_terms(edge_index, logmap,
                              torch.ones(n, dtype=torch.float64), 1.0, 3, 2)
    assert (harmonic[:, :, 1:] == 0).all() and (harmonic[:, 0, 0] == 1).all()
    conv = HarmonicConv(2, 2, max_order=2, rings=3, prev_order=0).double()
    out = conv(torch.randn(n, 2, dtype=torch.float64), edge_index, harmonic,
               torch.zeros(n, dtype=torch.float64))
    assert out[:, 1:].abs().max() == 0 and out[:, 0].abs().max() > 0


@pytest.mark.parametrize('m', [0, 1, 2])
def test_flat_grid_matches_continuous_correlation(m):
    # On a fine grid with equal frames (no transport), the layer is the
    # normalised correlation of the signal with R(r) e^{i m theta}. For a
    # plane wave f = exp(i k . p) with k = |k| (cos a, sin a), Jacobi-Anger
    # gives  out = f(p) 2 pi i^m e^{i m a} int_0^eps R(r) J_m(|k| r) r dr
    #              / (pi eps^2).
    h, eps, rings = 0.01, 0.2, 4
    axis = torch.arange(-0.3, 0.3 + h / 2, h, dtype=torch.float64)
    pos = torch.cartesian_prod(axis, axis)
    centre = (pos.abs() <= 0.08).all(1).nonzero().flatten()
    d = torch.cdist(pos[centre], pos)
    c_local, j = (d < eps).nonzero().t()
    i = centre[c_local]
    diff = pos[j] - pos[i]
    logmap = torch.stack([diff.norm(dim=1),
                          torch.atan2(diff[:, 1], diff[:, 0])], 1)
    edge_index = torch.stack([j, i])
    harmonic = harmonic_terms(edge_index, logmap,
                              torch.ones(len(pos), dtype=torch.float64), eps,
                              rings, m)
    conv = HarmonicConv(1, 1, max_order=m, rings=rings, prev_order=0,
                        offset=False).double()
    profile = torch.tensor([0.3, 1.0, -0.5, 0.8], dtype=torch.float64)
    with torch.no_grad():
        conv.radial.zero_()
        conv.radial[m, :, 0, 0] = profile  # the (0 -> m) profile
    transport = torch.zeros(j.numel(), dtype=torch.float64)

    def radial(r):
        return np.interp(r, np.arange(rings + 1) * eps / rings,
                         np.append(profile.numpy(), 0.0))

    for k, a in ((9.0, 0.3), (9.0, 0.3 + 1.1), (14.0, -2.0)):
        wave = torch.polar(torch.ones(len(pos), dtype=torch.float64),
                           k * (pos[:, 0] * math.cos(a)
                                + pos[:, 1] * math.sin(a)))
        out = conv(wave.view(-1, 1, 1), edge_index, harmonic, transport)
        integral = integrate.quad(lambda r: radial(r) * special.jv(m, k * r)
                                  * r, 0, eps, points=[0.05, 0.1, 0.15])[0]
        factor = 2 * math.pi * (1j ** m) * np.exp(1j * m * a) * integral \
            / (math.pi * eps ** 2)
        expected = wave[centre] * complex(factor)
        assert rel(out[centre, m, 0], expected) < 2e-2, (k, a)


def test_bad_input():
    with pytest.raises(ValueError, match="'rings' must be at least 1"):
        HarmonicConv(2, 2, rings=0)
    conv = HarmonicConv(2, 3, max_order=1, rings=3, prev_order=1)
    edge_index, logmap, transport, weight, radius = random_discs()
    with pytest.raises(ValueError, match=r"expected features \[N, 2, 2\]"):
        conv(torch.randn(60, 1, 2, dtype=torch.complex64), edge_index)
    harmonic = harmonic_terms(edge_index, logmap, weight, radius, 3, 0)
    with pytest.raises(ValueError, match='precompute with max_order >= 1'):
        HarmonicOperator(edge_index, harmonic, transport, 60, 2, 2)
    with pytest.raises(ValueError, match='finite'):
        bad = logmap.clone()
        bad[0, 0] = float('nan')
        harmonic_terms(edge_index, bad, weight, radius, 3, 1)
    with pytest.raises(ValueError, match='zero total weight'):
        harmonic_terms(edge_index, logmap, 0 * weight, radius, 3, 1)
    assert 'HarmonicConv(2, 3, max_order=1, rings=3' in repr(conv)


def test_features_must_have_one_row_per_graph_node(monkeypatch):
    # Fewer rows than nodes used to read past the end of x (values ~1e36).
    edge_index, logmap, transport, weight, radius = random_discs()
    harmonic = harmonic_terms(edge_index, logmap, weight, radius, 3, 1)
    conv = HarmonicConv(2, 3, max_order=1, rings=3).double()
    short = torch.randn(40, 2, 2, dtype=C128)
    operator = HarmonicOperator(edge_index, harmonic, transport, 60, 2, 2)
    no_sparse_kernel(monkeypatch)
    for backend in ('sparse', 'message'):
        with pytest.raises(ValueError, match=r"only 40 rows in 'x'"):
            conv(short, edge_index, harmonic, transport, backend=backend)
    with pytest.raises(ValueError, match=r"'x' has 40 rows but there are 60 "
                                         r"nodes in 'operator'"):
        conv(short, operator=operator)
    with pytest.raises(ValueError, match=r"'x' has 40 rows"):
        operator.aggregate(short)
    with pytest.raises(ValueError, match="needs 'edge_index'"):
        conv(short, edge_index)
    with pytest.raises(ValueError, match='HarmonicOperator'):
        conv(short, operator='operator')


def test_operator_rejects_bad_graphs_and_angles():
    edge_index, logmap, transport, weight, radius = random_discs()
    harmonic = harmonic_terms(edge_index, logmap, weight, radius, 3, 1)
    with pytest.raises(ValueError, match=r'outside \[0, 50\)'):
        HarmonicOperator(edge_index, harmonic, transport, 50, 2, 2)
    bad = transport.clone()
    bad[3] = float('nan')
    with pytest.raises(ValueError, match="'transport' contains NaN"):
        HarmonicOperator(edge_index, harmonic, bad, 60, 2, 2)


@pytest.mark.parametrize('make,match', [
    (lambda: HarmonicConv(0, 2), "'in_channels' must be at least 1"),
    (lambda: HarmonicConv(2, 0), "'out_channels' must be at least 1"),
    (lambda: HarmonicConv(2, 2, max_order=-1), "'max_order' must be at "
                                                "least 0"),
    (lambda: HarmonicConv(2.0, 2), "'in_channels' must be an integer"),
])
def test_constructors_need_positive_channel_counts(make, match):
    with pytest.raises(ValueError, match=match):
        make()




def _bad_graphs():
    """(name, edit of (edge_index, harmonic, transport), expected error) for
    a layer with max_order = prev_order = 1 and 3 rings."""
    def nan(transport):
        transport = transport.clone()
        transport[5] = float('nan')
        return transport

    return [
        ('harmonic without rings', lambda e, h, t: (e, h[:, 0], t),
         r"'harmonic' must be complex \[E, rings, orders\]"),
        ('real harmonic', lambda e, h, t: (e, h.real, t),
         r"'harmonic' must be complex \[E, rings, orders\] \(from "
         r"HarmonicPrecompute\), got torch.float64"),
        ('too few orders', lambda e, h, t: (e, h[:, :, :1], t),
         "'harmonic' holds orders up to 0 but this layer needs 1; "
         "precompute with max_order >= 1"),
        ('other rings', lambda e, h, t: (e, h[:, :2], t),
         "'harmonic' has 2 rings but this layer has 3"),
        ('harmonic of other edges', lambda e, h, t: (e, h[:-1], t),
         r"'edge_index' must be \[2, E\] with E = \d+ \(the rows of "
         r"'harmonic'\)"),
        ('short transport', lambda e, h, t: (e, h, t[:-1]),
         r"'transport' must be \[E\] with E = \d+ \(the rows of "
         r"'harmonic'\), got \[\d+\]"),
        ('transport per node', lambda e, h, t: (e, h, t[:, None]),
         r"'transport' must be \[E\]"),
        ('NaN transport', lambda e, h, t: (e, h, nan(t)),
         "'transport' contains NaN"),
        ('integer transport', lambda e, h, t: (e, h, t.long()),
         "'transport' must be a float tensor"),
        ('harmonic as a list', lambda e, h, t: (e, h.tolist(), t),
         "'harmonic' must be a torch.Tensor"),
    ]


@pytest.mark.parametrize('backend', ['message', 'sparse'])
@pytest.mark.parametrize('name,edit,match', _bad_graphs(),
                         ids=[case[0] for case in _bad_graphs()])
def test_per_edge_inputs_are_checked_before_use(backend, name, edit, match,
                                                monkeypatch):
    # The message backend used to fail with an obscure view or index error
    # (or an einsum error for other rings); both backends check alike now.
    edge_index, logmap, transport, weight, radius = random_discs()
    harmonic = harmonic_terms(edge_index, logmap, weight, radius, 3, 1)
    conv = HarmonicConv(2, 3, max_order=1, rings=3, prev_order=1).double()
    x = torch.randn(60, 2, 2, dtype=C128)
    conv(x, edge_index, harmonic, transport, backend=backend)  # all well
    no_sparse_kernel(monkeypatch)

    def fail(*args, **kwargs):
        raise AssertionError('messages ran before the input checks')

    monkeypatch.setattr(conv, 'propagate', fail)
    with pytest.raises(ValueError, match=match):
        conv(x, *edit(edge_index, harmonic, transport), backend=backend)


def test_operator_checks_the_per_edge_inputs_alike():
    edge_index, logmap, transport, weight, radius = random_discs()
    harmonic = harmonic_terms(edge_index, logmap, weight, radius, 3, 1)
    for name, edit, match in _bad_graphs():
        if name == 'other rings':  # an operator takes any number of rings
            continue
        with pytest.raises(ValueError, match=match):
            HarmonicOperator(*edit(edge_index, harmonic, transport), 60, 2, 2)


def test_edge_masks_and_hooks_take_the_message_path():
    # issue 39: the default sparse backend skipped propagate, so neither
    # an edge mask nor a hook saw anything
    from torch_geometric.explain.algorithm.utils import (clear_masks,
                                                         set_masks)

    from tests.nn.conftest import RINGS, two_level_data
    data = two_level_data(0)
    conv = HarmonicConv(3, 4, max_order=1, rings=RINGS,
                        prev_order=0).double()
    operator = HarmonicOperator(data.edge_index, data.harmonic,
                                data.transport, 50, 1, 2)
    plain = conv(data.x, operator=operator)
    calls = []
    handle = conv.register_propagate_forward_hook(
        lambda module, inputs, out: calls.append(out.shape))
    hooked = conv(data.x, operator=operator)
    handle.remove()
    assert len(calls) == 1
    assert torch.allclose(hooked, plain, rtol=1e-10, atol=1e-12)
    edges = data.edge_index.size(1)
    set_masks(conv, torch.full((edges, ), -60.0, dtype=torch.float64),
              data.edge_index)  # sigmoid(-60): every edge off
    assert conv(data.x, operator=operator).abs().max() < 1e-20
    keep = torch.rand(edges, dtype=torch.float64,
                      generator=torch.Generator().manual_seed(0)) * 4 - 2
    set_masks(conv, keep, data.edge_index)
    masked = conv(data.x, operator=operator)
    clear_masks(conv)
    weight = keep.sigmoid()
    by_hand = conv(data.x, data.edge_index, data.harmonic * weight[:, None,
                                                                   None],
                   data.transport)  # a mask scales each edge's term
    assert torch.allclose(masked, by_hand, rtol=1e-10, atol=1e-12)
