import pytest
import torch

from tg_intrinsic.nn import VectorNonLin


def test_zero_vectors_have_finite_gradients():
    nonlin = VectorNonLin(4, batch_norm=False).double()
    zero = torch.zeros(3, 4, 2, dtype=torch.float64, requires_grad=True)
    nonlin(zero).sum().backward()
    assert torch.isfinite(zero.grad).all()


def test_constructor_needs_positive_channels():
    with pytest.raises(ValueError, match="'channels' must be at least 1"):
        VectorNonLin(0)
