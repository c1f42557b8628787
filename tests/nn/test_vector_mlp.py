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


@pytest.mark.parametrize('make,match', [
    (lambda: VectorMLP([3, 0]), r"'channels\[1\]' must be at least 1"),
    (lambda: VectorMLP([3]), "at least 2 channel count"),
])
def test_constructor_needs_positive_sizes(make, match):
    with pytest.raises(ValueError, match=match):
        make()
