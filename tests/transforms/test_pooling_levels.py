"""PoolingLevels: level sizes, the pooling edges, frames and operators of
every level, batching round trips, the Gravo option and bad input."""
import pytest
import torch
from torch_geometric.data import Batch

from tg_intrinsic.data import IntrinsicData
from tg_intrinsic.geometry.pointcloud.operators import SurfaceOperators
from tg_intrinsic.transforms import PoolingLevels
from tests.conftest import fibonacci_sphere


def _cloud(n, seed=0):
    g = torch.Generator().manual_seed(seed)
    pos = fibonacci_sphere(n) * (1 + 0.05 * torch.rand(n, 1, generator=g,
                                                        dtype=torch.float64))
    return IntrinsicData(pos=pos, normal=pos / pos.norm(dim=1,
                                                        keepdim=True))


def test_fps_levels_keep_a_quarter_and_pool_to_the_nearest_sample():
    data = PoolingLevels()(_cloud(512))
    sizes = [data.pos.size(0)] + [data[f'pos_{l}'].size(0)
                                  for l in (1, 2, 3)]
    assert sizes == [512, 128, 32, 8]
    for level in (1, 2, 3):
        fine_pos = data.pos if level == 1 else data[f'pos_{level - 1}']
        pos = data[f'pos_{level}']
        # coarse points are fine points, with their frames
        sample = data[f'sample_index_{level}']
        assert torch.equal(pos, fine_pos[sample])
        fine, coarse = data[f'pool_edge_index_{level}']
        assert torch.equal(fine, torch.arange(fine_pos.size(0)))
        nearest = torch.cdist(fine_pos, pos).argmin(1)
        assert torch.equal(coarse, nearest)
        assert torch.equal(data[f'pool_weight_{level}'],
                           torch.ones(fine_pos.size(0), dtype=pos.dtype))
        # the sample itself needs no transport
        assert torch.allclose(data[f'pool_transport_{level}'][sample],
                              torch.zeros(pos.size(0), dtype=pos.dtype),
                              atol=1e-12)
        # operators of the level: the gradient of a linear function
        ops = SurfaceOperators(data[f'edge_index_{level}'],
                               data[f'grad_weight_{level}'],
                               data[f'div_weight_{level}'], pos.size(0))
        assert torch.isfinite(ops.grad(pos[:, :1])).all()
    assert data.pooling_levels.tolist() == [[3.0, 0.25, 20.0, 0.0]]
    assert 'PoolingLevels(num_levels=3' in repr(PoolingLevels())


def test_batches_round_trip_with_offsets():
    a, b = PoolingLevels()(_cloud(512, 0)), PoolingLevels()(_cloud(600, 1))
    batch = Batch.from_data_list([a, b])
    for level in (1, 2, 3):
        fine = 512 if level == 1 else a[f'pos_{level - 1}'].size(0)
        coarse = a[f'pos_{level}'].size(0)
        ei = batch[f'pool_edge_index_{level}']
        n_a = a[f'pool_edge_index_{level}'].size(1)
        assert torch.equal(ei[:, n_a:], b[f'pool_edge_index_{level}']
                           + torch.tensor([[fine], [coarse]]))
        assert torch.equal(batch[f'edge_index_{level}'][:, a[
            f'edge_index_{level}'].size(1):], b[f'edge_index_{level}']
            + coarse)
    for original, back in zip([a, b], batch.to_data_list()):
        assert set(original.keys()) == set(back.keys())
        for key in original.keys():
            assert torch.equal(original[key], back[key]), key


def test_gravo_levels_interpolate_and_keep_constants():
    data = PoolingLevels(method='gravo')(_cloud(1500))
    n = [data.pos.size(0)] + [data[f'pos_{l}'].size(0) for l in (1, 2, 3)]
    assert n[0] > n[1] > n[2] > n[3] >= 3
    for level in (1, 2, 3):
        fine, coarse = data[f'pool_edge_index_{level}']
        weight = data[f'pool_weight_{level}']
        # every fine point interpolates from coarse points (rows sum to 1)
        rows = torch.zeros(n[level - 1], dtype=weight.dtype).index_add_(
            0, fine, weight)
        assert torch.allclose(rows, torch.ones_like(rows))
    assert data.pooling_levels[0, 3] == 1.0


def test_bad_input_is_explained():
    with pytest.raises(ValueError, match='too small.*at least 449 points'):
        PoolingLevels()(_cloud(400))
    PoolingLevels()(_cloud(449))
    with pytest.raises(ValueError, match="'method' must be one of"):
        PoolingLevels(method='random')
    with pytest.raises(ValueError, match="'ratio' must lie in"):
        PoolingLevels(ratio=1.5)
    with pytest.raises(ValueError, match="'k' must be at least 3"):
        PoolingLevels(k=2)
    bad = _cloud(500)
    bad.pos[3, 0] = float('nan')
    with pytest.raises(ValueError, match='NaN'):
        PoolingLevels()(bad)
