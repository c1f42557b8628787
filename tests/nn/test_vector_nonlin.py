"""VectorNonLin: the norm nonlinearity against its formula vector by vector
(learned bias, batch statistics, running statistics), directions kept,
equivariance to turning the tangent frames, bad input."""
import math

import pytest
import torch

from tg_intrinsic.nn import VectorNonLin
from tests.symmetry import rotate_vectors


def reference(v, shifted_norm):
    """relu(shifted |v|) / |v| * v, one vector at a time."""
    out = torch.zeros_like(v)
    for n in range(v.size(0)):
        for c in range(v.size(1)):
            a, b = float(v[n, c, 0]), float(v[n, c, 1])
            length = math.hypot(a, b)
            scale = max(shifted_norm(n, c, length), 0.0) / length
            out[n, c, 0], out[n, c, 1] = scale * a, scale * b
    return out


def test_bias_shifts_the_threshold_of_every_channel():
    torch.manual_seed(0)
    nonlin = VectorNonLin(3, batch_norm=False).double()
    with torch.no_grad():
        nonlin.bias.copy_(torch.tensor([-0.8, 0.0, 0.5]))
    v = torch.randn(20, 3, 2, dtype=torch.float64)
    bias = nonlin.bias.tolist()
    expected = reference(v, lambda n, c, length: length + bias[c])
    torch.testing.assert_close(nonlin(v), expected, rtol=1e-12, atol=1e-12)
    # short vectors of the first channel are switched off
    assert (nonlin(v)[:, 0].norm(dim=-1) == 0).any()


def test_batch_norm_uses_batch_then_running_statistics():
    torch.manual_seed(1)
    nonlin = VectorNonLin(2).double()
    with torch.no_grad():
        nonlin.norm.weight.copy_(torch.tensor([1.5, -0.7]))
        nonlin.norm.bias.copy_(torch.tensor([0.2, 0.4]))
    gamma, beta = nonlin.norm.weight.tolist(), nonlin.norm.bias.tolist()
    v = torch.randn(8, 2, 2, dtype=torch.float64)
    lengths = [[math.hypot(*v[n, c].tolist()) for c in range(2)]
               for n in range(8)]
    mean = [sum(row[c] for row in lengths) / 8 for c in range(2)]
    var = [sum((row[c] - mean[c]) ** 2 for row in lengths) / 8
           for c in range(2)]

    def batch_norm(mu, sigma2):
        return lambda n, c, length: (gamma[c] * (length - mu[c])
                                     / math.sqrt(sigma2[c] + 1e-5) + beta[c])

    torch.testing.assert_close(nonlin(v), reference(v, batch_norm(mean, var)),
                               rtol=1e-10, atol=1e-12)
    # one training step moved the running statistics by the momentum 0.1
    # (the running variance is the unbiased one)
    running_mean = [0.1 * m for m in mean]
    running_var = [0.9 + 0.1 * s * 8 / 7 for s in var]
    nonlin.eval()
    torch.testing.assert_close(
        nonlin(v), reference(v, batch_norm(running_mean, running_var)),
        rtol=1e-10, atol=1e-12)


@pytest.mark.parametrize('batch_norm', [True, False])
def test_keeps_directions_and_commutes_with_turning_the_frames(batch_norm):
    torch.manual_seed(2)
    nonlin = VectorNonLin(4, batch_norm=batch_norm).double()
    if not batch_norm:
        torch.nn.init.uniform_(nonlin.bias, -1.0, 0.5)
    v = torch.randn(40, 4, 2, dtype=torch.float64)
    theta = torch.rand(40, dtype=torch.float64) * 2 * math.pi
    out = nonlin(v)
    cross = out[..., 0] * v[..., 1] - out[..., 1] * v[..., 0]
    assert cross.abs().max() < 1e-12
    assert ((out * v).sum(-1) >= 0).all()
    assert (out.norm(dim=-1) > 0).any() and (out.norm(dim=-1) == 0).any()
    turned = nonlin(rotate_vectors(v, theta))
    torch.testing.assert_close(turned, rotate_vectors(out, theta),
                               rtol=1e-12, atol=1e-12)


def test_zero_vectors_have_finite_gradients():
    nonlin = VectorNonLin(4, batch_norm=False).double()
    zero = torch.zeros(3, 4, 2, dtype=torch.float64, requires_grad=True)
    nonlin(zero).sum().backward()
    assert torch.isfinite(zero.grad).all()


def test_repr():
    assert repr(VectorNonLin(4)) == 'VectorNonLin(4, batch_norm=True)'
    assert repr(VectorNonLin(2, batch_norm=False)) == \
        'VectorNonLin(2, batch_norm=False)'


def test_constructor_needs_positive_channels():
    with pytest.raises(ValueError, match="'channels' must be at least 1"):
        VectorNonLin(0)


@pytest.mark.parametrize('batch_norm', [True, False])
@pytest.mark.parametrize('v', [
    torch.zeros(5, 2, 2), torch.zeros(5, 3, 3), torch.zeros(5, 3)])
def test_features_must_be_vectors_of_the_layer_width(v, batch_norm):
    with pytest.raises(ValueError, match=r"'v' must be float tangent vector "
                                         r"features \[N, 3, 2\]"):
        VectorNonLin(3, batch_norm=batch_norm)(v)
