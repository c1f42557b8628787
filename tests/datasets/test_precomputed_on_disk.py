import os
import sqlite3

import pytest
import torch
from torch_geometric.loader import DataLoader

from tests.conftest import icosphere
from tg_intrinsic import IntrinsicData
from tg_intrinsic.datasets import PrecomputedOnDisk
from tg_intrinsic.train import hsn_pipeline
from tg_intrinsic.transforms import GravoHierarchy, MLSOperators


def clouds(n=7, points=40):
    """Noisy unit spheres with their normals, labelled by index."""
    generator = torch.Generator().manual_seed(0)
    out = []
    for i in range(n):
        pos = torch.randn(points, 3, generator=generator)
        pos = pos / pos.norm(dim=1, keepdim=True)
        out.append(IntrinsicData(pos=pos * (1 + 0.1 * i), normal=pos.clone(),
                                 y=torch.tensor([i])))
    return out


def meshes(n=3, subdivisions=2):
    """Icospheres with their vertices pushed in or out a little."""
    pos, face = icosphere(subdivisions, torch.float32)
    generator = torch.Generator().manual_seed(1)
    return [IntrinsicData(pos=pos * (1 + 0.05 * torch.rand(
        pos.size(0), 1, generator=generator)), face=face.clone(),
        y=torch.tensor([i])) for i in range(n)]


def assert_same(a, b):
    assert type(a) is type(b)
    assert sorted(a.keys()) == sorted(b.keys())
    for key in a.keys():
        if isinstance(a[key], torch.Tensor):
            assert a[key].dtype == b[key].dtype, key
            assert torch.equal(a[key], b[key]), key
        else:
            assert a[key] == b[key], key


def rows(dataset):
    """The stored bytes of every example, in order."""
    path = dataset.processed_paths[0]
    with sqlite3.connect(path) as connection:
        return connection.execute(
            'SELECT * FROM PrecomputedOnDisk ORDER BY id').fetchall()


KINDS = {
    'mls': (clouds, MLSOperators(k=8), ['edge_index', 'grad_weight']),
    'hsn': (meshes, hsn_pipeline(radius=0.3, rings=2),
            ['edge_index_1', 'cluster_1', 'sample_index_1']),
    'gravo': (lambda: meshes(3, 3), GravoHierarchy(ratio=4, lower_bound=30),
              ['edge_index_2', 'prolong_index_2', 'cluster_2']),
}


@pytest.mark.parametrize('kind', sorted(KINDS))
def test_round_trip_and_batches(tmp_path, kind):
    make, pre_transform, keys = KINDS[kind]
    source = make()
    expected = [pre_transform(data) for data in source]
    dataset = PrecomputedOnDisk(str(tmp_path), source, pre_transform,
                                chunk_size=2, log=False)
    assert len(dataset) == len(source)
    for i, data in enumerate(expected):
        assert_same(data, dataset[i])
        for key in keys:  # the level structure is there
            assert key in dataset[i], key
    # batches: every key, the level indices offset per level
    on_disk = list(DataLoader(dataset, batch_size=2))
    in_memory = list(DataLoader(expected, batch_size=2))
    assert len(on_disk) == len(in_memory) == (len(source) + 1) // 2
    for a, b in zip(on_disk, in_memory):
        assert_same(a, b)
    level = keys[0]
    assert int(on_disk[0][level].max()) >= expected[0][level].max() + 1
    # reopened: read back, not recomputed
    again = PrecomputedOnDisk(str(tmp_path), source, pre_transform,
                              log=False)
    assert_same(again[len(source) - 1], expected[-1])
    assert rows(again) == rows(dataset)
    # opened without the source (e.g. by another process)
    opened = PrecomputedOnDisk(str(tmp_path), None, log=False)
    assert len(opened) == len(source)
    assert_same(opened[0], expected[0])


def test_a_subset_batches_its_own_examples(tmp_path):
    source = clouds(6)
    dataset = PrecomputedOnDisk(str(tmp_path), source, log=False)
    subset = dataset[torch.tensor([4, 1, 3])]
    batch = next(iter(DataLoader(subset, batch_size=3)))
    assert batch.y.tolist() == [4, 1, 3]
    assert 'PrecomputedOnDisk(3' in repr(subset)


def test_workers_write_the_same_database(tmp_path):
    source = clouds(5)
    one = PrecomputedOnDisk(str(tmp_path / 'one'), source, MLSOperators(k=8),
                            log=False)
    two = PrecomputedOnDisk(str(tmp_path / 'two'), source, MLSOperators(k=8),
                            workers=2, chunk_size=2, log=False)
    assert rows(one) == rows(two) and len(rows(two)) == 5


class FailAt:
    """Raises on the example labelled ``at`` while the file ``flag``
    exists (a run killed there); records the labels it processed."""
    def __init__(self, at, flag):
        self.at, self.flag, self.seen = at, flag, []

    def __call__(self, data):
        if int(data.y) == self.at and os.path.exists(self.flag):
            raise RuntimeError('killed')
        self.seen.append(int(data.y))
        return MLSOperators(k=8)(data)

    def __repr__(self):
        return 'FailAt()'


def test_an_interrupted_write_resumes_and_is_never_complete(tmp_path):
    source = clouds(7)
    flag = tmp_path / 'flag'
    flag.write_text('')
    root = str(tmp_path / 'set')
    with pytest.raises(RuntimeError, match='example 5: killed'):
        PrecomputedOnDisk(root, source, FailAt(5, flag), chunk_size=2,
                          log=False)
    processed = os.path.join(root, 'processed')
    assert not os.path.exists(os.path.join(processed, 'complete.json'))
    with sqlite3.connect(os.path.join(processed, 'sqlite.db')) as db:
        # the whole chunks before the failure, not the part of one
        assert db.execute('SELECT COUNT(*) FROM PrecomputedOnDisk'
                          ).fetchone() == (4, )
    flag.unlink()
    resumed_transform = FailAt(5, flag)
    resumed = PrecomputedOnDisk(root, source, resumed_transform,
                                chunk_size=2, log=False)
    assert resumed_transform.seen == [4, 5, 6]  # started at the first gap
    fresh = PrecomputedOnDisk(str(tmp_path / 'fresh'), source,
                              FailAt(5, flag), log=False)
    assert rows(resumed) == rows(fresh)


def test_an_unfinished_database_of_other_settings_starts_over(tmp_path):
    source = clouds(5)
    flag = tmp_path / 'flag'
    flag.write_text('')
    with pytest.raises(RuntimeError):
        PrecomputedOnDisk(str(tmp_path), source, FailAt(3, flag),
                          chunk_size=1, log=False)
    dataset = PrecomputedOnDisk(str(tmp_path), source, MLSOperators(k=6),
                                log=False)
    for i, data in enumerate(source):
        assert_same(dataset[i], MLSOperators(k=6)(data))


def test_reuse_with_other_settings_fails_clearly(tmp_path):
    source = clouds(4)
    PrecomputedOnDisk(str(tmp_path), source, MLSOperators(k=8), log=False)
    with pytest.raises(ValueError, match=r"other settings \(pre_transform "
                       r"'MLSOperators\(k=8.*force_reload=True"):
        PrecomputedOnDisk(str(tmp_path), source, MLSOperators(k=6),
                          log=False)
    with pytest.raises(ValueError, match='length 4 -> 3'):
        PrecomputedOnDisk(str(tmp_path), source[:3], MLSOperators(k=8),
                          log=False)
    moved = [data.clone() for data in source]
    moved[-1].pos = moved[-1].pos + 1
    with pytest.raises(ValueError, match='digest'):
        PrecomputedOnDisk(str(tmp_path), moved, MLSOperators(k=8),
                          log=False)
    rebuilt = PrecomputedOnDisk(str(tmp_path), moved, MLSOperators(k=8),
                                log=False, force_reload=True)
    assert_same(rebuilt[3], MLSOperators(k=8)(moved[3]))


def test_bad_input(tmp_path):
    with pytest.raises(ValueError, match='holds no finished database'):
        PrecomputedOnDisk(str(tmp_path), None, log=False)
    with pytest.raises(ValueError, match="'source' is empty"):
        PrecomputedOnDisk(str(tmp_path), [], log=False)
    with pytest.raises(TypeError, match='sequence'):
        PrecomputedOnDisk(str(tmp_path), iter(clouds(2)), log=False)
    with pytest.raises(ValueError, match='workers'):
        PrecomputedOnDisk(str(tmp_path), clouds(2), workers=0, log=False)
    with pytest.raises(TypeError, match='cannot be sent to worker '
                       'processes.*workers=1'):
        PrecomputedOnDisk(str(tmp_path), clouds(2), lambda d: d, workers=2,
                          log=False)
    with pytest.raises(TypeError, match='example 0: the pre_transform must '
                       'return a torch_geometric Data object, got dict'):
        PrecomputedOnDisk(str(tmp_path / 'dict'), clouds(2),
                          lambda d: dict(d), log=False)
