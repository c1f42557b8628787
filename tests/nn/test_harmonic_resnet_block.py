"""HarmonicResNetBlock and harmonic_operators: the residual formula run
with per-edge messages, gauge equivariance, one operator per order pair,
bad input."""
import math

import pytest
import torch

from tg_intrinsic.geometry.geodesics.harmonic import (HarmonicOperator,
                                                      harmonic_terms)
from tg_intrinsic.nn import ComplexLinear, HarmonicResNetBlock
from tg_intrinsic.nn.harmonic_resnet_block import harmonic_operators
from tests.conftest import rel
from tests.nn.conftest import C128, no_sparse_kernel, random_discs
from tests.symmetry import gauge_change, rotate_streams


def test_features_must_have_one_row_per_graph_node(monkeypatch):
    edge_index, logmap, transport, weight, radius = random_discs()
    harmonic = harmonic_terms(edge_index, logmap, weight, radius, 3, 1)
    short = torch.randn(40, 2, 2, dtype=C128)
    operator = HarmonicOperator(edge_index, harmonic, transport, 60, 2, 2)
    no_sparse_kernel(monkeypatch)
    block = HarmonicResNetBlock(2, 2, max_order=1, rings=3, prev_order=1)
    ops = {(2, 2): operator}
    with pytest.raises(ValueError, match=r"'z' has 40 rows but there are "
                                         r"60 nodes in 'operators'"):
        block(short, ops)
    with pytest.raises(ValueError, match=r'order pairs \[\(1, 2\)\]'):
        HarmonicResNetBlock(2, 2, 1, 3, prev_order=0)(short[:, :1], ops)


def test_harmonic_operators_reject_bad_graphs():
    edge_index, logmap, transport, weight, radius = random_discs()
    harmonic = harmonic_terms(edge_index, logmap, weight, radius, 3, 1)
    negative = edge_index.clone()
    negative[0, 0] = -1
    with pytest.raises(ValueError, match='outside'):
        harmonic_operators(negative, harmonic, transport, 60, [(2, 2)])


def test_constructor_needs_positive_channel_counts():
    with pytest.raises(ValueError, match="'out_channels' must be at least"):
        HarmonicResNetBlock(2, 0)


def level(seed=0, rings=3, max_order=2, angle=None):
    """A disc graph with its harmonic terms and transport angles, seen in
    frames turned by ``angle`` when given."""
    edge_index, logmap, transport, weight, radius = random_discs(seed=seed)
    if angle is not None:
        logmap, transport = gauge_change(edge_index, logmap, transport,
                                         angle)
    harmonic = harmonic_terms(edge_index, logmap, weight, radius, rings,
                              max_order)
    return edge_index, harmonic, transport


def pairs_of(block):
    p, o = block.prev_order + 1, block.max_order + 1
    return [(p, o), (o, o)]


# (in_channels, out_channels, prev_order, max_order): a skip that is the
# identity or a ComplexLinear, input streams padded with 0 or dropped
SHAPES = [(2, 2, 1, 1), (2, 3, 0, 1), (3, 2, 2, 1), (2, 4, 1, 2)]


@pytest.mark.parametrize('c_in,c_out,prev_order,max_order', SHAPES)
def test_block_is_the_residual_formula_on_per_edge_messages(
        c_in, c_out, prev_order, max_order):
    # sigma(BN(conv2(sigma(BN(conv1 z)))) + S z), the convolutions run as
    # per-edge messages, the input streams padded with zeros / cut to the
    # output orders
    torch.manual_seed(0)
    block = HarmonicResNetBlock(c_in, c_out, max_order, 3,
                                prev_order).double()
    for act in (block.act1, block.act2):
        torch.nn.init.uniform_(act.bias, -0.3, 0.3)
    edge_index, harmonic, transport = level()
    graph = (edge_index, harmonic, transport)
    z = torch.randn(60, prev_order + 1, c_in, dtype=C128)
    out = block(z, harmonic_operators(*graph, 60, pairs_of(block)))
    assert out.shape == (60, max_order + 1, c_out)
    h = block.conv1(z, *graph, backend='message')
    h = block.act1(block.norm1(h))
    h = block.norm2(block.conv2(h, *graph, backend='message'))
    skip = torch.zeros(60, max_order + 1, c_in, dtype=C128)
    streams = min(prev_order, max_order) + 1
    skip[:, :streams] = z[:, :streams]
    expected = block.act2(h + block.skip(skip))
    assert out.abs().max() > 1e-3
    torch.testing.assert_close(out, expected, rtol=1e-10, atol=1e-12)
    assert isinstance(block.skip, ComplexLinear) == (c_in != c_out)


@pytest.mark.parametrize('c_in,c_out,prev_order,max_order', SHAPES)
@pytest.mark.parametrize('training', [True, False])
def test_block_is_gauge_equivariant(c_in, c_out, prev_order, max_order,
                                    training):
    gen = torch.Generator().manual_seed(5)
    angle = torch.rand(60, dtype=torch.float64, generator=gen) * 2 * math.pi
    torch.manual_seed(1)
    block = HarmonicResNetBlock(c_in, c_out, max_order, 3,
                                prev_order).double().train(training)
    z = torch.randn(60, prev_order + 1, c_in, dtype=C128)
    ops = harmonic_operators(*level(), 60, pairs_of(block))
    turned = harmonic_operators(*level(angle=angle), 60, pairs_of(block))
    out = block(z, ops)
    out2 = block(rotate_streams(z, angle), turned)
    assert out.abs().max() > 1e-3
    assert rel(out2, rotate_streams(out, angle)) < 1e-10
    assert rel(out2[:, 0], out[:, 0]) < 1e-10  # order 0 is invariant
    assert rel(out2[:, 1:], out[:, 1:]) > 1e-3


def test_harmonic_operators_builds_each_pair_once():
    edge_index, harmonic, transport = level()
    ops = harmonic_operators(edge_index, harmonic, transport, 60,
                             [(1, 2), (2, 2), (1, 2), (3, 2)])
    assert sorted(ops) == [(1, 2), (2, 2), (3, 2)]
    x = torch.randn(60, 3, 2, dtype=C128)
    for (p, o), op in ops.items():
        assert (op.in_orders, op.out_orders, op.num_nodes) == (p, o, 60)
        alone = HarmonicOperator(edge_index, harmonic, transport, 60, p, o)
        torch.testing.assert_close(op.aggregate(x[:, :p]),
                                   alone.aggregate(x[:, :p]))


def test_repr():
    assert repr(HarmonicResNetBlock(2, 3, max_order=2, prev_order=0)) == \
        'HarmonicResNetBlock(2, 3, max_order=2, prev_order=0)'


def test_operators_must_be_a_dict_of_the_level():
    block = HarmonicResNetBlock(2, 2, max_order=1, rings=3, prev_order=1)
    z = torch.randn(60, 2, 2, dtype=C128)
    with pytest.raises(ValueError, match=r"'operators' must be a dict "
                                         r"holding the HarmonicOperator"):
        block(z, [HarmonicOperator(*level(max_order=1), 60, 2, 2)])
