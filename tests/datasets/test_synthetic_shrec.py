import os

import numpy as np
import pytest
import torch
from torch_geometric.loader import DataLoader

from tg_intrinsic import IntrinsicData
from tg_intrinsic.datasets import SyntheticSHREC
from tg_intrinsic.datasets import shrec_shapes as shapes
from tests.datasets.conftest import (assert_closed_manifold,
                                     self_intersecting_pairs)

SMALL = dict(num_per_class=3, num_train_per_class=2, log=False)


@pytest.fixture(scope='module')
def root(tmp_path_factory):
    return str(tmp_path_factory.mktemp('shrec'))


@pytest.fixture(scope='module')
def small(root):
    train = SyntheticSHREC(root, split='train', **SMALL)
    test = SyntheticSHREC(root, split='test', **SMALL)
    seg = SyntheticSHREC(root, split='train', task='segmentation', **SMALL)
    return train, test, seg


# --------------------------------------------------------------- dataset


def test_api(small):
    train, test, seg = small
    assert len(train) == 12 * 2 and len(test) == 12 * 1 and len(seg) == 24
    assert train.num_classes == 12 and seg.num_classes == 6
    assert list(train.classes) == sorted(train.classes)
    assert len(train.classes) >= 10
    assert seg.part_names == shapes.PART_NAMES
    assert isinstance(train[0], IntrinsicData)
    assert 'SyntheticSHREC(24' in repr(train)
    assert torch.bincount(torch.cat([d.y for d in train])).tolist() == [2] * 12


def test_every_mesh_is_a_closed_manifold(small):
    train, test, _ = small
    counts = []
    for data in list(train) + list(test):
        assert data.pos.dtype == torch.float32
        assert data.face.dtype == torch.long
        assert data.face.shape[0] == 3
        r = assert_closed_manifold(data.pos, data.face)
        assert r['area'] == pytest.approx(1.0, rel=1e-3)  # unit area
        assert self_intersecting_pairs(data.pos, data.face) == 0
        counts.append(data.num_nodes)
    counts = np.array(counts)
    assert counts.min() >= 500 and counts.max() <= 2000
    assert len(np.unique(counts)) > len(counts) // 2  # resolution varies


def test_labels(small):
    train, test, seg = small
    for data in list(train) + list(test):
        assert data.y.shape == (1, ) and 0 <= int(data.y) < 12
    for data, cls in zip(seg, train):
        assert data.y.shape == (data.num_nodes, )
        assert data.y.dtype == torch.long
        assert int(data.y.min()) >= 0 and int(data.y.max()) < 6
        assert len(torch.unique(data.y)) > 1
        assert torch.equal(data.category, cls.y)
        assert torch.equal(data.pos, cls.pos)


def test_deterministic_and_seed_dependent(small, tmp_path):
    train = small[0]
    same = SyntheticSHREC(str(tmp_path / 'a'), **SMALL)
    for a, b in zip(train, same):
        assert torch.equal(a.pos, b.pos) and torch.equal(a.face, b.face)
    # shape j of class c does not depend on the dataset size
    fewer = SyntheticSHREC(str(tmp_path / 'b'), num_per_class=2,
                           num_train_per_class=1, log=False)
    assert torch.equal(fewer[0].pos, train[0].pos)
    other = SyntheticSHREC(str(tmp_path / 'c'), num_per_class=2,
                           num_train_per_class=1, seed=1, log=False)
    assert not torch.equal(other[0].pos[:10], fewer[0].pos[:10])


def test_cached_not_regenerated(small, root, monkeypatch):
    train = small[0]
    files = [os.path.join(train.processed_dir, f)
             for f in train.processed_file_names]
    assert all(os.path.exists(f) for f in files)
    assert all('seed0' in f and 'n3' in f for f in files)
    mtimes = [os.path.getmtime(f) for f in files]

    def fail(self):
        raise AssertionError('process() called although cached')

    monkeypatch.setattr(SyntheticSHREC, 'process', fail)
    again = SyntheticSHREC(root, split='test', task='segmentation', **SMALL)
    assert len(again) == 12
    assert [os.path.getmtime(f) for f in files] == mtimes
    # other generation parameters -> other files -> regenerated
    with pytest.raises(AssertionError, match='process'):
        SyntheticSHREC(root, seed=5, **SMALL)


def test_batching(small):
    train, _, seg = small
    loader = DataLoader(seg, batch_size=4, shuffle=False)
    batch = next(iter(loader))
    sizes = [seg[i].num_nodes for i in range(4)]
    assert batch.num_graphs == 4 and batch.pos.size(0) == sum(sizes)
    assert batch.y.size(0) == sum(sizes) and batch.category.shape == (4, )
    nf0 = seg[0].face.size(1)
    assert torch.equal(batch.face[:, :nf0], seg[0].face)
    assert torch.equal(batch.face[:, nf0:nf0 + seg[1].face.size(1)],
                       seg[1].face + sizes[0])
    batch = next(iter(DataLoader(train, batch_size=5)))
    assert batch.y.shape == (5, )


def test_bad_arguments(tmp_path):
    with pytest.raises(ValueError, match='split'):
        SyntheticSHREC(str(tmp_path), split='val')
    with pytest.raises(ValueError, match='task'):
        SyntheticSHREC(str(tmp_path), task='regression')
    with pytest.raises(ValueError, match='num_train_per_class'):
        SyntheticSHREC(str(tmp_path), num_per_class=3, num_train_per_class=3)
    with pytest.raises(ValueError, match='num_vertices'):
        SyntheticSHREC(str(tmp_path), num_vertices=(2000, 500))
    with pytest.raises(ValueError, match='seed'):
        SyntheticSHREC(str(tmp_path), seed=-1)


def test_workers_give_identical_files(tmp_path):
    kwargs = dict(num_per_class=2, num_train_per_class=1,
                  num_vertices=(100, 120), log=False)
    one = SyntheticSHREC(str(tmp_path / 'one'), **kwargs)
    two = SyntheticSHREC(str(tmp_path / 'two'), workers=2, **kwargs)
    assert len(one.processed_paths) == 4
    for a, b in zip(one.processed_paths, two.processed_paths):
        with open(a, 'rb') as fa, open(b, 'rb') as fb:
            assert fa.read() == fb.read()
