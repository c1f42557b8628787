import os

import numpy as np
import pytest
import torch
from scipy.spatial import cKDTree
from torch_geometric.loader import DataLoader

from tg_intrinsic import IntrinsicData
from tg_intrinsic.datasets import SyntheticModelNet

SMALL = dict(num_points=512, num_per_class=(3, 2), log=False)


@pytest.fixture(scope='module')
def root(tmp_path_factory):
    return str(tmp_path_factory.mktemp('modelnet'))


@pytest.fixture(scope='module')
def small(root):
    return (SyntheticModelNet(root, split='train', **SMALL),
            SyntheticModelNet(root, split='test', **SMALL))


def test_api_and_shapes(small):
    train, test = small
    assert len(train) == 12 * 3 and len(test) == 12 * 2
    assert train.num_classes == 12 and len(train.classes) >= 10
    assert list(train.classes) == sorted(train.classes)
    for data in list(train) + list(test):
        assert isinstance(data, IntrinsicData)
        assert data.pos.shape == (512, 3) and data.normal.shape == (512, 3)
        assert data.pos.dtype == torch.float32 and data.y.shape == (1, )
        norm = data.pos.norm(dim=1)
        assert float(norm.max()) == pytest.approx(1.0, abs=1e-5)
        assert torch.allclose(data.normal.norm(dim=1), torch.ones(512),
                              atol=1e-5)
        # farthest point sampling: no duplicates
        assert torch.unique(data.pos, dim=0).size(0) == 512
    assert 'SyntheticModelNet(36' in repr(train)


def test_classes_balanced(small):
    train, test = small
    assert torch.bincount(torch.cat([d.y for d in train])).tolist() == [3] * 12
    assert torch.bincount(torch.cat([d.y for d in test])).tolist() == [2] * 12


def test_dataset_normals_perpendicular_to_local_surface(small):
    """Normals agree with a PCA plane fit of the sampled points."""
    train, _ = small
    agree = []
    for data in train:
        pos, nrm = data.pos.double().numpy(), data.normal.double().numpy()
        _, idx = cKDTree(pos).query(pos, k=10)
        nb = pos[idx] - pos[idx].mean(1, keepdims=True)
        _, _, vt = np.linalg.svd(nb)
        agree.append(np.abs((vt[:, 2] * nrm).sum(1)))
    agree = np.concatenate(agree)
    # thin parts (legs, plates) mix both sides in a neighbourhood; random
    # unit vectors would give a median of 0.5
    assert np.median(agree) > 0.95
    assert (agree > 0.9).mean() > 0.7


def test_upright_and_rotate_up(small, tmp_path):
    train = small[0]
    rot = SyntheticModelNet(str(tmp_path), rotate_up=True, **SMALL)
    for a, b in zip(train, rot):
        assert torch.allclose(a.pos[:, 2], b.pos[:, 2], atol=1e-6)
        assert torch.allclose(a.pos[:, :2].norm(dim=1),
                              b.pos[:, :2].norm(dim=1), atol=1e-6)
        assert torch.allclose(a.normal[:, 2], b.normal[:, 2], atol=1e-6)
    # aligned tables: the table top is the largest horizontal surface
    table = [d for d in train if train.classes[int(d.y)] == 'table'][0]
    up = table.normal[:, 2].abs() > 0.99
    assert up.float().mean() > 0.3


def test_deterministic_and_cached(small, root, tmp_path, monkeypatch):
    train = small[0]
    same = SyntheticModelNet(str(tmp_path / 'a'), **SMALL)
    for a, b in zip(train, same):
        assert torch.equal(a.pos, b.pos) and torch.equal(a.normal, b.normal)
    other = SyntheticModelNet(str(tmp_path / 'b'), seed=3, **SMALL)
    assert not torch.equal(other[0].pos, train[0].pos)

    files = [os.path.join(train.processed_dir, f)
             for f in train.processed_file_names]
    assert all('seed0' in os.path.basename(f) for f in files)
    mtimes = [os.path.getmtime(f) for f in files]

    def fail(self):
        raise AssertionError('process() called although cached')

    monkeypatch.setattr(SyntheticModelNet, 'process', fail)
    again = SyntheticModelNet(root, split='test', **SMALL)
    assert torch.equal(again[0].pos, small[1][0].pos)
    assert [os.path.getmtime(f) for f in files] == mtimes
    with pytest.raises(AssertionError, match='process'):
        SyntheticModelNet(root, num_points=256, num_per_class=(3, 2),
                          log=False)


def test_batching(small):
    batch = next(iter(DataLoader(small[0], batch_size=6, shuffle=True)))
    assert batch.pos.shape == (6 * 512, 3) and batch.normal.shape == (6 * 512,
                                                                      3)
    assert batch.y.shape == (6, ) and batch.batch.max() == 5


def test_bad_arguments(tmp_path):
    with pytest.raises(ValueError, match='split'):
        SyntheticModelNet(str(tmp_path), split='valid')
    with pytest.raises(ValueError, match='num_per_class'):
        SyntheticModelNet(str(tmp_path), num_per_class=10)
    with pytest.raises(ValueError, match='num_points'):
        SyntheticModelNet(str(tmp_path), num_points=0)


def test_a_pre_transform_is_never_skipped_by_an_older_cache(tmp_path):
    # The README's DeltaConv example passes pre_transform=MLSOperators(...)
    # to a root the demo may already have generated without one.
    from tg_intrinsic.transforms import MLSOperators
    kwargs = dict(num_points=64, num_per_class=(1, 1), log=False)
    plain = SyntheticModelNet(str(tmp_path), 'train', **kwargs)
    assert 'grad_weight' not in plain[0]
    pre = SyntheticModelNet(str(tmp_path), 'train', **kwargs,
                            pre_transform=MLSOperators(k=8))
    assert 'grad_weight' in pre[0]
    other = SyntheticModelNet(str(tmp_path), 'train', **kwargs,
                              pre_transform=MLSOperators(k=6))
    assert other[0].edge_index.size(1) == 6 * other[0].num_nodes
    assert torch.equal(plain[0].pos, pre[0].pos)


def _bytes(path):
    with open(path, 'rb') as f:
        return f.read()


def test_workers_give_identical_files(tmp_path):
    from tg_intrinsic.transforms import MLSOperators
    kwargs = dict(num_points=64, num_per_class=(1, 1), log=False,
                  pre_transform=MLSOperators(k=8))
    one = SyntheticModelNet(str(tmp_path / 'one'), **kwargs)
    two = SyntheticModelNet(str(tmp_path / 'two'), workers=2, **kwargs)
    assert 'grad_weight' in two[0]
    for a, b in zip(one.processed_paths, two.processed_paths):
        assert _bytes(a) == _bytes(b)


def test_unpicklable_pre_transform_says_what_to_do(tmp_path):
    kwargs = dict(num_points=32, num_per_class=(1, 1), log=False,
                  pre_transform=lambda data: data)
    with pytest.raises(TypeError, match='SyntheticModelNet: the '
                       'pre_transform .* cannot be sent to worker '
                       'processes .*pass workers=1'):
        SyntheticModelNet(str(tmp_path), workers=2, **kwargs)
    assert len(SyntheticModelNet(str(tmp_path), workers=1, **kwargs)) == 12
    with pytest.raises(ValueError, match="'workers'"):
        SyntheticModelNet(str(tmp_path), workers=0, **kwargs)
