import pytest

from tg_intrinsic.transforms import MultiscaleSupports
from tests.transforms.conftest import sphere_data


def test_bad_input():
    with pytest.raises(ValueError, match='apply LogMap'):
        MultiscaleSupports([0.25], [0.4])(sphere_data(1))
    with pytest.raises(ValueError, match='decrease within'):
        MultiscaleSupports([0.5, 0.7], [0.4, 0.8])
