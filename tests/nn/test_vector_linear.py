import pytest

from tg_intrinsic.nn import VectorLinear


def test_repr():
    assert repr(VectorLinear(2, 3)) == 'VectorLinear(2, 3)'


def test_constructor_needs_positive_channels():
    with pytest.raises(ValueError, match="'in_channels' must be at least 1"):
        VectorLinear(0, 2)
