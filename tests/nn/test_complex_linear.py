"""ComplexLinear: real weights applied alike to every stream, a bias on
stream 0 only, against a loop; equivariance to a phase rotation of every
stream; bad input."""
import math

import pytest
import torch

from tg_intrinsic.nn import ComplexLinear
from tests.symmetry import rotate_streams

C128 = torch.complex128


def layer(bias=True, seed=0):
    torch.manual_seed(seed)
    lin = ComplexLinear(3, 4, bias=bias).double()
    if bias:
        torch.nn.init.uniform_(lin.bias, -1.0, 1.0)
    return lin


@pytest.mark.parametrize('bias', [True, False])
def test_matches_a_loop_over_streams_and_channels(bias):
    lin = layer(bias)
    z = torch.randn(5, 3, 3, dtype=C128)
    out = lin(z)
    assert out.shape == (5, 3, 4) and out.dtype == C128
    weight = lin.weight.tolist()
    bias_values = lin.bias.tolist() if bias else None
    expected = torch.zeros(5, 3, 4, dtype=C128)
    for s in range(3):
        for o in range(4):
            for c in range(3):
                expected[:, s, o] += weight[c][o] * z[:, s, c]
            if bias and s == 0:
                expected[:, s, o] += bias_values[o]
    torch.testing.assert_close(out, expected, rtol=1e-12, atol=1e-12)


def test_real_weights_commute_with_conjugation():
    lin = layer(bias=True)
    z = torch.randn(5, 2, 3, dtype=C128)
    torch.testing.assert_close(lin(z.conj()), lin(z).conj(), rtol=1e-12,
                               atol=1e-12)


@pytest.mark.parametrize('bias', [True, False])
def test_commutes_with_a_phase_rotation_of_every_stream(bias):
    # order m is multiplied by e^{-i m angle}; the bias sits on order 0,
    # which does not turn
    lin = layer(bias, seed=1)
    z = torch.randn(30, 3, 3, dtype=C128)
    angle = torch.rand(30, dtype=torch.float64) * 2 * math.pi
    out = lin(z)
    turned = lin(rotate_streams(z, angle))
    torch.testing.assert_close(turned, rotate_streams(out, angle),
                               rtol=1e-12, atol=1e-12)
    assert not torch.allclose(turned[:, 1:], out[:, 1:])


def test_bias_reaches_stream_zero_only():
    lin = layer(bias=True)
    out = lin(torch.zeros(2, 3, 3, dtype=C128))
    torch.testing.assert_close(out[:, 0], lin.bias.detach().to(C128)
                               .expand(2, 4))
    assert (out[:, 1:] == 0).all()
    assert lin.bias.abs().max() > 0


def test_repr():
    assert repr(ComplexLinear(3, 4)) == 'ComplexLinear(3, 4, bias=True)'
    assert repr(ComplexLinear(2, 5, bias=False)) == \
        'ComplexLinear(2, 5, bias=False)'


@pytest.mark.parametrize('make,match', [
    (lambda: ComplexLinear(0, 2), "'in_channels' must be at least 1"),
    (lambda: ComplexLinear(2, 0), "'out_channels' must be at least 1"),
])
def test_constructor_needs_positive_channel_counts(make, match):
    with pytest.raises(ValueError, match=match):
        make()


def test_bad_input():
    lin = ComplexLinear(3, 4)
    with pytest.raises(ValueError, match="'z' must be complex stream "
                                         "features"):
        lin(torch.randn(5, 2, 3))
    with pytest.raises(ValueError, match="'z' must be complex stream "
                                         "features"):
        lin(torch.randn(5, 3, dtype=torch.complex64))
    with pytest.raises(ValueError, match=r"expected complex features \[N, "
                                         r"streams, 3\], got \[5, 2, 2\]"):
        lin(torch.randn(5, 2, 2, dtype=torch.complex64))
