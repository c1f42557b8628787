import pytest

from tg_intrinsic.nn import ComplexLinear


@pytest.mark.parametrize('make,match', [
    (lambda: ComplexLinear(0, 2), "'in_channels' must be at least 1"),
    (lambda: ComplexLinear(2, 0), "'out_channels' must be at least 1"),
])
def test_constructor_needs_positive_channel_counts(make, match):
    with pytest.raises(ValueError, match=match):
        make()
