import pytest
import torch
from torch_geometric.data import Data

from tg_intrinsic.transforms import LogMap, MultiscaleSupports, \
    RandomTranslation
from tests.conftest import grid_mesh
from tests.transforms.conftest import angle_gap, edge_order


def test_translation_moves_the_whole_shape():
    torch.manual_seed(1)
    data = Data(pos=torch.randn(20, 3), normal=torch.randn(20, 3),
                grad_weight=torch.ones(3, 2))
    out = RandomTranslation(0.1)(data)
    offset = out.pos - data.pos
    assert torch.allclose(offset, offset[:1].expand(20, 3))
    assert offset.abs().max() <= 0.1
    assert torch.equal(out.normal, data.normal) and 'grad_weight' in out


def test_offsets_fill_the_cube_and_follow_the_global_seed():
    pos = torch.randn(7, 3, dtype=torch.float64,
                      generator=torch.Generator().manual_seed(0))
    data = Data(pos=pos)
    torch.manual_seed(2)
    offsets = torch.stack([RandomTranslation(0.5)(data).pos[3] - pos[3]
                           for _ in range(300)])
    # inside [-0.5, 0.5]^3, reaching towards every face of the cube, and
    # not one draw shared by the three axes
    assert offsets.abs().max() <= 0.5
    assert (offsets.amin(0) < -0.45).all() and (offsets.amax(0) > 0.45).all()
    assert offsets.mean(0).abs().max() < 0.06
    assert not torch.allclose(offsets[:, 0], offsets[:, 1])
    torch.manual_seed(2)
    again = RandomTranslation(0.5)(data).pos - pos
    assert torch.equal(again[3], offsets[0])
    assert torch.equal(data.pos, pos)  # the input is not mutated


def test_zero_offset_keeps_the_points_and_float32_stays_float32():
    pos = torch.rand(5, 3)
    out = RandomTranslation(0.0)(Data(pos=pos))
    assert torch.equal(out.pos, pos)
    out = RandomTranslation(2.0)(Data(pos=pos))
    assert out.pos.dtype == torch.float32
    assert (out.pos - pos).std(0).max() < 1e-6  # one offset
    assert (out.pos - pos).abs().max() > 0  # but moved


def test_coarse_levels_and_intrinsic_quantities_move_along():
    pos, face = grid_mesh(6, jitter=0.3)
    data = MultiscaleSupports([0.25], [0.6])(LogMap(0.3)(Data(pos=pos,
                                                              face=face)))
    torch.manual_seed(0)
    out = RandomTranslation(1.0)(data)
    offset = out.pos[0] - data.pos[0]
    assert offset.abs().min() > 0
    # the samples of level 1 are still points of the shape
    assert torch.allclose(out.pos_1, out.pos[out.sample_index_1])
    assert torch.allclose(out.pos_1 - data.pos_1, offset.expand(
        data.pos_1.size(0), 3))
    for key in ('frame', 'logmap', 'logmap_1', 'transport', 'area',
                'edge_index_1', 'cluster_1'):
        assert torch.equal(out[key], data[key]), key
    # and what is built on the moved shape agrees with what was kept
    rebuilt = LogMap(0.3)(Data(pos=out.pos, face=face))
    a, b = edge_order(rebuilt.edge_index), edge_order(data.edge_index)
    assert torch.equal(rebuilt.edge_index[:, a], data.edge_index[:, b])
    assert torch.allclose(rebuilt.logmap[a, 0], data.logmap[b, 0],
                          atol=1e-12)
    assert angle_gap(rebuilt.logmap[a, 1], data.logmap[b, 1]) < 1e-9


def test_bad_input():
    with pytest.raises(ValueError, match='must not be negative'):
        RandomTranslation(-1.0)
    assert repr(RandomTranslation(0.1)) == 'RandomTranslation(max_offset=0.1)'


def test_bad_values_are_named():
    with pytest.raises(ValueError, match='must be finite'):
        RandomTranslation(float('inf'))
    with pytest.raises(ValueError, match='max_offset'):
        RandomTranslation(float('nan'))
    with pytest.raises(ValueError, match="needs 'data.pos'"):
        RandomTranslation(0.1)(Data(x=torch.zeros(3, 1)))
    # integer points used to fail inside torch, NaN ones passed silently
    with pytest.raises(ValueError, match='float32 or float64'):
        RandomTranslation(0.1)(Data(pos=torch.ones(4, 3, dtype=torch.long)))
    with pytest.raises(ValueError, match='NaN'):
        RandomTranslation(0.1)(Data(pos=torch.full((4, 3), float('nan'))))
    with pytest.raises(ValueError, match=r'\[N, D\]'):
        RandomTranslation(0.1)(Data(pos=torch.ones(4)))
    assert repr(RandomTranslation(2.5)) == 'RandomTranslation(max_offset=2.5)'
