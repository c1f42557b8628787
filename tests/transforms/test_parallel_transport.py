import pytest

from tg_intrinsic.transforms import ParallelTransport
from tests.transforms.conftest import sphere_data


def test_bad_input():
    with pytest.raises(ValueError, match='apply LogMap'):
        ParallelTransport()(sphere_data(1))
