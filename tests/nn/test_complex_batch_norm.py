import pytest

from tg_intrinsic.nn import ComplexBatchNorm


def test_constructor_needs_positive_stream_count():
    with pytest.raises(ValueError, match="'streams' must be at least 1"):
        ComplexBatchNorm(2, 0)
