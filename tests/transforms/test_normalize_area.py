import pytest
import torch
from torch_geometric.data import Data

from tg_intrinsic.transforms import NormalizeArea


def test_bad_input():
    with pytest.raises(ValueError, match='NormalizeArea needs a mesh'):
        NormalizeArea()(Data(pos=torch.rand(5, 3)))
