"""VectorLinear: channel mixing of tangent vectors against a loop over the
channels, equivariance to turning the tangent frames, bad input."""
import math

import pytest
import torch

from tg_intrinsic.nn import VectorLinear
from tests.symmetry import rotate_vectors


def test_mixes_channels_like_a_loop_over_them():
    torch.manual_seed(0)
    lin = VectorLinear(3, 4).double()
    v = torch.randn(7, 3, 2, dtype=torch.float64, requires_grad=True)
    out = lin(v)
    assert out.shape == (7, 4, 2)
    weight = lin.weight.detach()
    expected = torch.zeros(7, 4, 2, dtype=torch.float64)
    for o in range(4):
        for c in range(3):
            expected[:, o] += float(weight[o, c]) * v.detach()[:, c]
    torch.testing.assert_close(out, expected, rtol=1e-12, atol=1e-12)
    # the backward pass is the transposed mixing, coordinate by coordinate
    g = torch.randn(7, 4, 2, dtype=torch.float64)
    (grad, ) = torch.autograd.grad(out, v, g)
    for c in range(3):
        torch.testing.assert_close(grad[:, c], sum(
            float(weight[o, c]) * g[:, o] for o in range(4)))


def test_commutes_with_turning_the_frames():
    torch.manual_seed(1)
    lin = VectorLinear(4, 5).double()
    v = torch.randn(30, 4, 2, dtype=torch.float64)
    theta = torch.rand(30, dtype=torch.float64) * 2 * math.pi
    out = lin(v)
    turned = lin(rotate_vectors(v, theta))
    torch.testing.assert_close(turned, rotate_vectors(out, theta),
                               rtol=1e-12, atol=1e-12)
    # the coordinates do change with the frames: the check can fail
    assert not torch.allclose(turned, out)


def test_repr():
    assert repr(VectorLinear(2, 3)) == 'VectorLinear(2, 3)'


def test_constructor_needs_positive_channels():
    with pytest.raises(ValueError, match="'in_channels' must be at least 1"):
        VectorLinear(0, 2)


@pytest.mark.parametrize('v', [
    torch.zeros(5, 2, 2), torch.zeros(5, 3, 3), torch.zeros(5, 3),
    torch.zeros(5, 3, 2, dtype=torch.long)])
def test_features_must_be_vectors_of_the_input_width(v):
    with pytest.raises(ValueError, match=r"'v' must be float tangent vector "
                                         r"features \[N, 3, 2\]"):
        VectorLinear(3, 4)(v)
