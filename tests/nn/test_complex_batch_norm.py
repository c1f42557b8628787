"""ComplexBatchNorm: magnitudes scaled by the root mean square over the
batch (then by the running one), against a loop; invariance to scaling,
equivariance to a phase rotation of every stream; bad input."""
import math

import pytest
import torch

from tg_intrinsic.nn import ComplexBatchNorm
from tests.symmetry import rotate_streams

C128 = torch.complex128


def norm_layer(eps=1e-5):
    torch.manual_seed(0)
    norm = ComplexBatchNorm(3, 2, eps=eps).double()
    torch.nn.init.uniform_(norm.weight, 0.5, 2.0)
    return norm


def test_training_then_evaluation_match_a_loop():
    norm = norm_layer()
    z = torch.randn(5, 2, 3, dtype=C128) * torch.tensor([1.0, 3.0, 0.2],
                                                        dtype=torch.float64)
    out = norm(z)
    assert out.shape == (5, 2, 3) and out.dtype == C128
    weight = norm.weight.tolist()
    mean_square = [[sum(abs(complex(z[n, s, c])) ** 2 for n in range(5)) / 5
                    for c in range(3)] for s in range(2)]
    for s in range(2):
        for c in range(3):
            scale = weight[s][c] / math.sqrt(mean_square[s][c] + 1e-5)
            torch.testing.assert_close(out[:, s, c], z[:, s, c] * scale,
                                       rtol=1e-12, atol=1e-14)
    # the running mean square moved from 1 by the momentum 0.1
    running = torch.tensor(mean_square, dtype=torch.float64) * 0.1 + 0.9
    torch.testing.assert_close(norm.running_square, running)
    norm.eval()
    out = norm(z)
    for s in range(2):
        for c in range(3):
            scale = weight[s][c] / math.sqrt(float(running[s, c]) + 1e-5)
            torch.testing.assert_close(out[:, s, c], z[:, s, c] * scale,
                                       rtol=1e-12, atol=1e-14)
    torch.testing.assert_close(norm.running_square, running)


def test_training_output_does_not_depend_on_the_scale():
    norm = norm_layer(eps=0.0)
    z = torch.randn(6, 2, 3, dtype=C128)
    torch.testing.assert_close(norm(7.5 * z), norm(z), rtol=1e-12,
                               atol=1e-12)
    # but the scale of one point matters, the layer is not pointwise
    scaled = z.clone()
    scaled[0] *= 7.5
    assert not torch.allclose(norm(scaled)[1:], norm(z)[1:])


@pytest.mark.parametrize('training', [True, False])
def test_commutes_with_a_phase_rotation_of_every_stream(training):
    norm = norm_layer().train(training)
    z = torch.randn(30, 2, 3, dtype=C128)
    angle = torch.rand(30, dtype=torch.float64) * 2 * math.pi
    out = norm(z)
    turned = norm(rotate_streams(z, angle))
    torch.testing.assert_close(turned, rotate_streams(out, angle),
                               rtol=1e-12, atol=1e-12)
    assert not torch.allclose(turned[:, 1], out[:, 1])


def test_an_empty_batch_uses_the_running_statistics():
    norm = norm_layer()
    out = norm(torch.zeros(0, 2, 3, dtype=C128))
    assert out.shape == (0, 2, 3)
    assert (norm.running_square == 1).all()


def test_repr():
    assert repr(ComplexBatchNorm(3, 2)) == 'ComplexBatchNorm(3, streams=2)'


def test_constructor_needs_positive_stream_count():
    with pytest.raises(ValueError, match="'streams' must be at least 1"):
        ComplexBatchNorm(2, 0)


@pytest.mark.parametrize('z,match', [
    (torch.randn(5, 2, 3), "'z' must be complex stream features"),
    (torch.randn(5, 3, dtype=torch.complex64),
     "'z' must be complex stream features"),
    (torch.randn(5, 3, 3, dtype=torch.complex64),
     r"expected complex features \[N, 2, 3\], got \[5, 3, 3\]"),
    (torch.randn(5, 2, 4, dtype=torch.complex64),
     r"expected complex features \[N, 2, 3\], got \[5, 2, 4\]"),
])
@pytest.mark.parametrize('training', [True, False])
def test_bad_input(z, match, training):
    norm = ComplexBatchNorm(3, 2).train(training)
    with pytest.raises(ValueError, match=match):
        norm(z)
