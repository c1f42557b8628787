"""VectorMLP: the stack of VectorLinear and VectorNonLin against its
formula, equivariance to turning the tangent frames, sizes, bad input."""
import math

import pytest
import torch

from tg_intrinsic.nn import VectorMLP
from tests.symmetry import rotate_vectors


def test_vector_mlp_is_equivariant():
    torch.manual_seed(0)
    v = torch.randn(50, 4, 2, dtype=torch.float64)
    theta = torch.rand(50, dtype=torch.float64) * 2 * math.pi
    mlp = VectorMLP([4, 8, 3]).double().eval()
    out = mlp(v)
    assert out.shape == (50, 3, 2)
    assert torch.allclose(mlp(rotate_vectors(v, theta)),
                          rotate_vectors(out, theta), atol=1e-12)


def test_layers_follow_the_formula():
    # v <- relu(|W v| + b) (W v) / |W v|, layer after layer
    torch.manual_seed(1)
    mlp = VectorMLP([3, 5, 2], batch_norm=False).double()
    for layer in mlp.layers[1::2]:
        torch.nn.init.uniform_(layer.bias, -0.5, 0.5)
    v = torch.randn(10, 3, 2, dtype=torch.float64)
    expected = v
    for linear, nonlin in zip(mlp.layers[0::2], mlp.layers[1::2]):
        weight, bias = linear.weight.detach(), nonlin.bias.detach()
        u = torch.einsum('oc,ncd->nod', weight, expected)
        length = torch.sqrt(u[..., 0] ** 2 + u[..., 1] ** 2)
        expected = u * (torch.clamp(length + bias, min=0) / length)[..., None]
    out = mlp(v)
    assert out.shape == (10, 2, 2) and out.abs().max() > 0
    torch.testing.assert_close(out, expected, rtol=1e-10, atol=1e-12)


def test_sizes_and_repr():
    mlp = VectorMLP([4, 8, 3])
    # bias-free maps, batch norm (weight and bias) on the norms
    assert sum(p.numel() for p in mlp.parameters()) == \
        4 * 8 + 8 * 3 + 2 * 8 + 2 * 3
    assert repr(mlp) == 'VectorMLP([4, 8, 3])'
    assert sum(p.numel() for p in VectorMLP([4, 8, 3],
                                            batch_norm=False).parameters()) \
        == 4 * 8 + 8 * 3 + 8 + 3


def test_input_must_have_the_first_width():
    with pytest.raises(ValueError, match=r"'v' must be float tangent vector "
                                         r"features \[N, 4, 2\]"):
        VectorMLP([4, 8])(torch.zeros(6, 3, 2))


@pytest.mark.parametrize('make,match', [
    (lambda: VectorMLP([3, 0]), r"'channels\[1\]' must be at least 1"),
    (lambda: VectorMLP([3]), "at least 2 channel count"),
])
def test_constructor_needs_positive_sizes(make, match):
    with pytest.raises(ValueError, match=match):
        make()
