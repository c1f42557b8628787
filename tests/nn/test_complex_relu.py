"""ComplexReLU: the C-ReLU against its formula entry by entry, zero kept at
zero with finite gradients, equivariance to a phase rotation of every
stream, bad input."""
import cmath
import math

import pytest
import torch

from tg_intrinsic.nn import ComplexReLU
from tests.symmetry import rotate_streams

C128 = torch.complex128


def test_matches_the_formula_entry_by_entry():
    torch.manual_seed(0)
    act = ComplexReLU(3).double()
    with torch.no_grad():
        act.bias.copy_(torch.tensor([-0.8, 0.0, 0.7], dtype=torch.float64))
    z = torch.randn(20, 2, 3, dtype=C128)
    z[0, 1, 2] = 0  # no phase: the output is 0 whatever the bias
    out = act(z).detach()
    assert out.shape == (20, 2, 3) and out.dtype == C128
    bias = act.bias.tolist()
    for n in range(20):
        for s in range(2):
            for c in range(3):
                value = complex(z[n, s, c])
                r = abs(value)
                want = max(r + bias[c], 0.0) * value / r if r > 0 else 0j
                assert cmath.isclose(complex(out[n, s, c]), want,
                                     rel_tol=1e-12, abs_tol=1e-15)
    # the negative bias switches some entries of channel 0 off, not all
    off = out[:, :, 0] == 0
    assert off.any() and not off.all()


def test_zero_stays_zero_with_finite_gradients():
    act = ComplexReLU(2).double()
    with torch.no_grad():
        act.bias.fill_(0.3)
    z = torch.zeros(4, 2, 2, dtype=C128, requires_grad=True)
    out = act(z)
    assert (out == 0).all()
    (out.real + out.imag).sum().backward()
    assert torch.isfinite(torch.view_as_real(z.grad)).all()
    assert torch.isfinite(act.bias.grad).all()


def test_commutes_with_a_phase_rotation_of_every_stream():
    torch.manual_seed(1)
    act = ComplexReLU(4).double()
    torch.nn.init.uniform_(act.bias, -1.0, 1.0)
    z = torch.randn(30, 3, 4, dtype=C128)
    angle = torch.rand(30, dtype=torch.float64) * 2 * math.pi
    out = act(z)
    turned = act(rotate_streams(z, angle))
    torch.testing.assert_close(turned, rotate_streams(out, angle),
                               rtol=1e-12, atol=1e-12)
    assert not torch.allclose(turned[:, 1:], out[:, 1:])


def test_repr():
    assert repr(ComplexReLU(3)) == 'ComplexReLU(3)'


def test_constructor_needs_positive_channel_count():
    with pytest.raises(ValueError, match="'channels' must be at least 1"):
        ComplexReLU(0)


def test_bad_input():
    act = ComplexReLU(3)
    with pytest.raises(ValueError, match="'z' must be complex stream "
                                         "features"):
        act(torch.randn(5, 2, 3))
    with pytest.raises(ValueError, match="'z' must be complex stream "
                                         "features"):
        act(torch.randn(5, 3, dtype=torch.complex64))
    with pytest.raises(ValueError, match=r"expected complex features \[N, "
                                         r"streams, 3\], got \[5, 2, 4\]"):
        act(torch.randn(5, 2, 4, dtype=torch.complex64))
