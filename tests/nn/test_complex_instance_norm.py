"""ComplexInstanceNorm: magnitudes scaled by the root mean square over each
shape's points, against a loop; the same in training and evaluation and
for a shape alone or in any batch; invariance to a shape's scale,
equivariance to a phase rotation of every stream; bad input."""
import math

import pytest
import torch

from tg_intrinsic.nn import ComplexInstanceNorm
from tests.symmetry import rotate_streams

C128 = torch.complex128


def norm_layer(eps=1e-5):
    torch.manual_seed(0)
    norm = ComplexInstanceNorm(3, 2, eps=eps).double()
    torch.nn.init.uniform_(norm.weight, 0.5, 2.0)
    return norm


def shapes(sizes=(5, 1, 7), seed=0):
    g = torch.Generator().manual_seed(seed)
    z = torch.randn(sum(sizes), 2, 3, dtype=C128, generator=g)
    z = z * torch.tensor([1.0, 3.0, 0.2], dtype=torch.float64)
    batch = torch.repeat_interleave(torch.arange(len(sizes)),
                                    torch.tensor(sizes))
    return z, batch


@pytest.mark.parametrize('training', [True, False])
def test_matches_a_loop_over_shapes(training):
    norm = norm_layer().train(training)
    z, batch = shapes()
    out = norm(z, batch)
    assert out.shape == z.shape and out.dtype == C128
    weight = norm.weight.tolist()
    for g in range(3):
        rows = (batch == g).nonzero().flatten().tolist()
        for s in range(2):
            for c in range(3):
                square = sum(abs(complex(z[n, s, c])) ** 2
                             for n in rows) / len(rows)
                scale = weight[s][c] / math.sqrt(square + 1e-5)
                torch.testing.assert_close(out[rows, s, c],
                                           z[rows, s, c] * scale,
                                           rtol=1e-12, atol=1e-14)


def test_training_and_evaluation_agree_and_keep_no_state():
    norm = norm_layer()
    z, batch = shapes()
    trained = norm.train()(z, batch)
    assert dict(norm.named_buffers()) == {}
    torch.testing.assert_close(norm.eval()(z, batch), trained, rtol=0,
                               atol=0)


def test_a_shape_alone_equals_the_shape_in_a_batch():
    norm = norm_layer()
    z, batch = shapes()
    out = norm(z, batch, num_shapes=3)
    for g in range(3):
        at = batch == g
        torch.testing.assert_close(norm(z[at]), out[at], rtol=1e-12,
                                   atol=1e-14)


def test_each_shape_is_invariant_to_its_own_scale():
    norm = norm_layer(eps=0.0)
    z, batch = shapes()
    scaled = z * torch.where(batch == 2, 40.0, 1.0)[:, None, None]
    torch.testing.assert_close(norm(scaled, batch), norm(z, batch),
                               rtol=1e-12, atol=1e-12)
    # but the scale of one point matters, the layer is not pointwise
    scaled = z.clone()
    scaled[0] *= 7.5
    assert not torch.allclose(norm(scaled, batch)[1:5], norm(z, batch)[1:5])


def test_commutes_with_a_phase_rotation_of_every_stream():
    norm = norm_layer()
    z, batch = shapes()
    angle = torch.rand(z.size(0), dtype=torch.float64) * 2 * math.pi
    out = norm(z, batch)
    turned = norm(rotate_streams(z, angle), batch)
    torch.testing.assert_close(turned, rotate_streams(out, angle),
                               rtol=1e-12, atol=1e-12)
    assert not torch.allclose(turned[:, 1], out[:, 1])


def test_gradient_matches_finite_differences():
    norm = norm_layer()
    z, batch = shapes((3, 4))
    z.requires_grad_(True)
    assert torch.autograd.gradcheck(lambda x: norm(x, batch), (z, ))


def test_empty_input_and_empty_shapes():
    norm = norm_layer()
    assert norm(torch.zeros(0, 2, 3, dtype=C128)).shape == (0, 2, 3)
    # shape 1 has no points: the others are normalised as without it
    z, batch = shapes((4, 5))
    gapped = torch.where(batch == 1, 2, 0)
    torch.testing.assert_close(norm(z, gapped, num_shapes=3),
                               norm(z, batch))


def test_repr():
    assert repr(ComplexInstanceNorm(3, 2)) == \
        'ComplexInstanceNorm(3, streams=2)'


def test_constructor_needs_positive_sizes():
    with pytest.raises(ValueError, match="'streams' must be at least 1"):
        ComplexInstanceNorm(2, 0)
    with pytest.raises(ValueError, match="'channels' must be at least 1"):
        ComplexInstanceNorm(0, 2)


@pytest.mark.parametrize('z,batch,match', [
    (torch.randn(5, 2, 3), None, "'z' must be complex stream features"),
    (torch.randn(5, 3, 3, dtype=torch.complex64), None,
     r"expected complex features \[N, 2, 3\], got \[5, 3, 3\]"),
    (torch.randn(5, 2, 3, dtype=torch.complex64), torch.zeros(4).long(),
     r"'batch' must have shape \[5\]"),
    (torch.randn(5, 2, 3, dtype=torch.complex64), torch.zeros(5),
     "'batch' must be torch.long"),
    (torch.randn(3, 2, 3, dtype=torch.complex64), torch.tensor([1, 0, 0]),
     "'batch' must be sorted"),
])
def test_bad_input(z, batch, match):
    with pytest.raises(ValueError, match=match):
        ComplexInstanceNorm(3, 2)(z, batch)
