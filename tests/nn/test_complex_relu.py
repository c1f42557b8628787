import pytest

from tg_intrinsic.nn import ComplexReLU


def test_constructor_needs_positive_channel_count():
    with pytest.raises(ValueError, match="'channels' must be at least 1"):
        ComplexReLU(0)
