"""GravoHierarchy: the level keys, batching (block-diagonal prolongations),
point clouds through a k-NN graph, and bad input."""
import numpy as np
import pytest
import scipy.sparse as sp
import torch
from torch_geometric.data import Batch, Data

from tg_intrinsic.transforms import GravoHierarchy

from tests.conftest import grid_mesh, icosphere


def prolongation(data, level):
    rows, cols = data[f'prolong_index_{level}'].numpy()
    fine = data.pos if level == 1 else data[f'pos_{level - 1}']
    return sp.csr_matrix((data[f'prolong_weight_{level}'].numpy(),
                          (rows, cols)),
                         shape=(fine.size(0), data[f'pos_{level}'].size(0)))


def test_levels_of_a_mesh():
    pos, face = icosphere(5)
    data = GravoHierarchy(lower_bound=100)(Data(pos=pos, face=face))
    assert data.pos_1.size(0) < pos.size(0) and data.pos_2.size(0) >= 100
    assert 'pos_3' not in data  # 10242 -> ~1.6k -> ~160 -> stop
    for level in (1, 2):
        P = prolongation(data, level)
        assert np.abs(P.sum(1).A1 - 1).max() < 1e-12
        assert data[f'cluster_{level}'].max() + 1 == P.shape[1]
        assert data[f'edge_index_{level}'].max() < P.shape[1]
    assert data.prolong_weight_1.dtype == pos.dtype
    assert 'GravoHierarchy(ratio=8.0' in repr(GravoHierarchy())


def test_batching_makes_prolongations_block_diagonal():
    transform = GravoHierarchy(lower_bound=20, max_levels=2)
    pos, face = icosphere(4)
    p2, f2 = grid_mesh(40, jitter=0.2)
    a = transform(Data(pos=pos, face=face))
    b = transform(Data(pos=p2, face=f2))
    batch = Batch.from_data_list([a, b])
    for level in (1, 2):
        expected = sp.block_diag([prolongation(a, level),
                                  prolongation(b, level)])
        assert abs(prolongation(batch, level) - expected).max() == 0
        n_a = a[f'pos_{level}'].size(0)
        fine_a = (a.pos if level == 1 else a[f'pos_{level - 1}']).size(0)
        cluster = batch[f'cluster_{level}']
        assert torch.equal(cluster[:fine_a], a[f'cluster_{level}'])
        assert torch.equal(cluster[fine_a:], b[f'cluster_{level}'] + n_a)


def test_point_cloud_uses_a_knn_graph():
    g = torch.Generator().manual_seed(0)
    pos = torch.randn(4000, 3, generator=g, dtype=torch.float64)
    pos = pos / pos.norm(dim=1, keepdim=True)
    data = GravoHierarchy(lower_bound=100, k=10)(Data(pos=pos))
    assert 200 < data.pos_1.size(0) < 1000
    P = prolongation(data, 1)
    assert np.abs(P.sum(1).A1 - 1).max() < 1e-12


def test_bad_input():
    with pytest.raises(ValueError, match='above 1'):
        GravoHierarchy(ratio=0.5)
    with pytest.raises(ValueError, match='lower_bound'):
        GravoHierarchy(lower_bound=0)
    with pytest.raises(ValueError, match='weighting'):
        GravoHierarchy(weighting='cubic')
    pos, face = icosphere(2)
    loose = torch.cat([pos, pos[:1] + 3.0])
    with pytest.raises(ValueError, match='on no edge'):
        GravoHierarchy(lower_bound=10)(Data(pos=loose, face=face))
    bad = pos.clone()
    bad[0, 0] = float('nan')
    with pytest.raises(ValueError, match='NaN'):
        GravoHierarchy()(Data(pos=bad, face=face))
    # Too small for one level: no level keys, the input comes back whole.
    small = GravoHierarchy(lower_bound=1000)(Data(pos=pos, face=face))
    assert 'pos_1' not in small and torch.equal(small.pos, pos)


def test_points_that_cannot_coarsen_end_the_hierarchy():
    # 50 identical points: no sample covers another, so a level would keep
    # all of them; it used to repeat that level max_levels times.
    data = GravoHierarchy(lower_bound=2)(
        Data(pos=torch.zeros(50, 3, dtype=torch.float64)))
    assert 'pos_1' not in data
    spread = GravoHierarchy(lower_bound=2)(
        Data(pos=torch.rand(50, 3, dtype=torch.float64)))
    sizes = [spread[f'pos_{level}'].size(0) for level in range(1, 11)
             if f'pos_{level}' in spread]
    assert sizes and all(a > b for a, b in zip([50] + sizes, sizes))
