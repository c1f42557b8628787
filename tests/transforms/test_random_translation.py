import pytest
import torch
from torch_geometric.data import Data

from tg_intrinsic.transforms import RandomTranslation


def test_translation_moves_the_whole_shape():
    torch.manual_seed(1)
    data = Data(pos=torch.randn(20, 3), normal=torch.randn(20, 3),
                grad_weight=torch.ones(3, 2))
    out = RandomTranslation(0.1)(data)
    offset = out.pos - data.pos
    assert torch.allclose(offset, offset[:1].expand(20, 3))
    assert offset.abs().max() <= 0.1
    assert torch.equal(out.normal, data.normal) and 'grad_weight' in out


def test_bad_input():
    with pytest.raises(ValueError, match='must not be negative'):
        RandomTranslation(-1.0)
    assert repr(RandomTranslation(0.1)) == 'RandomTranslation(max_offset=0.1)'
