import os

import numpy as np
import pytest
import torch

from tg_intrinsic.datasets import PointCloudFolder
from tg_intrinsic.io.mesh import write_ply

RNG = np.random.default_rng(0)


def cloud(n=30, columns=6):
    """float32 values, so that text and binary round trips are exact."""
    return RNG.standard_normal((n, columns)).astype(np.float32)


def write_text(path, table, sep=' '):
    path.parent.mkdir(parents=True, exist_ok=True)
    path.write_text(''.join(sep.join(repr(float(x)) for x in row) + '\n'
                            for row in table))


def write_labels(path, labels):
    path.parent.mkdir(parents=True, exist_ok=True)
    path.write_text(''.join(f'{v}\n' for v in labels))


def write_npy(path, table):
    path.parent.mkdir(parents=True, exist_ok=True)
    np.save(path, table)


def write_ply_normals(path, table):
    path.parent.mkdir(parents=True, exist_ok=True)
    write_ply(str(path), table[:, :3], properties={
        'nx': table[:, 3], 'ny': table[:, 4], 'nz': table[:, 5]})


def classification_tree(root):
    """chair/lamp x train/test, 30 points each, in every format."""
    tables = {}
    for name, writer in [
            ('chair/train/a.txt', lambda p, t: write_text(p, t, ',')),
            ('chair/train/b.xyz', write_text),
            ('chair/test/e.pts', write_text),
            ('lamp/train/c.npy', write_npy),
            ('lamp/train/d.ply', write_ply_normals),
            ('lamp/test/f.txt', write_text)]:
        table = cloud()
        writer(root / name, table)
        tables[name] = table
    return tables


def test_classification_formats_round_trip(tmp_path):
    tables = classification_tree(tmp_path)
    (tmp_path / 'lamp' / 'train' / 'readme.md').write_text('not points')
    train = PointCloudFolder(str(tmp_path), 'train', log=False)
    assert train.classes == ['chair', 'lamp'] and train.num_classes == 2
    assert len(train) == 4 and [int(d.y) for d in train] == [0, 0, 1, 1]
    for data, name in zip(train, ['chair/train/a.txt', 'chair/train/b.xyz',
                                  'lamp/train/c.npy', 'lamp/train/d.ply']):
        table = torch.from_numpy(tables[name])
        assert torch.equal(data.pos, table[:, :3])
        assert torch.equal(data.normal, table[:, 3:])
    test = PointCloudFolder(str(tmp_path), 'test', log=False)
    assert [int(d.y) for d in test] == [0, 1] and len(test) == 2
    assert 'PointCloudFolder(2' in repr(test)


def test_normals_all_or_none(tmp_path):
    classification_tree(tmp_path)
    write_text(tmp_path / 'lamp' / 'train' / 'g.txt', cloud(columns=3))
    with pytest.raises(ValueError, match=r"g\.txt' has no normals"):
        PointCloudFolder(str(tmp_path), 'train', log=False)
    only_xyz = PointCloudFolder(str(tmp_path), 'test', log=False)
    assert 'normal' in only_xyz[0]


def test_corrupt_file_among_good_ones_is_named(tmp_path):
    classification_tree(tmp_path)
    (tmp_path / 'chair' / 'train' / 'zz.xyz').write_text('1 2 3\n4 five 6\n')
    with pytest.raises(ValueError, match=r"could not read '.*zz\.xyz'"):
        PointCloudFolder(str(tmp_path), 'train', log=False)


def segmentation_tree(root):
    s1, s2, s3 = cloud(columns=3), cloud(columns=3), cloud(columns=3)
    l1, l2 = RNG.integers(0, 3, 30), RNG.integers(0, 3, 30)
    l3, l4 = RNG.integers(0, 5, 30), RNG.integers(0, 2, 30)
    write_text(root / 'train' / 's1.txt', np.column_stack([s1, l1]))
    write_text(root / 'train' / 's2.xyz', s2)
    write_labels(root / 'points_label' / 's2.seg', l2)
    write_ply(str(root / 'train' / 's4.ply'), s3, properties={'label': l4})
    write_npy(root / 'test' / 's3.npy', np.column_stack([s3, l3]))
    return (s1, l1), (s2, l2), (s3, l4), (s3, l3)


def test_segmentation_labels(tmp_path):
    (s1, l1), (s2, l2), (s4, l4), (_, l3) = segmentation_tree(tmp_path)
    train = PointCloudFolder(str(tmp_path), 'train', task='segmentation',
                             log=False)
    # the test split's labels count too
    assert train.num_classes == max(l1.max(), l2.max(), l3.max()) + 1 == 5
    assert len(train) == 3 and train.classes is None
    for data, (points, labels) in zip(train, [(s1, l1), (s2, l2),
                                              (s4, l4)]):
        assert torch.equal(data.pos, torch.from_numpy(points[:, :3]))
        assert data.y.dtype == torch.long
        assert data.y.tolist() == labels.tolist()
    assert 'normal' not in train[0]


def test_one_based_label_files(tmp_path):
    write_text(tmp_path / 'train' / 'x.pts', cloud(columns=3))
    write_labels(tmp_path / 'points_label' / 'x.seg', [1, 2, 3] * 10)
    ds = PointCloudFolder(str(tmp_path), task='segmentation',
                          label_offset=1, log=False)
    assert ds[0].y.tolist() == [0, 1, 2] * 10 and ds.num_classes == 3
    with pytest.raises(ValueError, match=r"x\.seg' holds the label 1 .*"
                       r"\(read as 2-based: label_offset=2\)"):
        PointCloudFolder(str(tmp_path), task='segmentation',
                         label_offset=2, log=False)


@pytest.mark.parametrize('labels,kwargs,match', [
    ([0] * 29, {}, r"x\.seg' holds 29 labels but '.*x\.xyz' has 30 points"),
    ([0] * 29 + [0.5], {}, r"x\.seg' holds the non-integer label 0\.5"),
    ([0] * 29 + [-2], {}, r"x\.seg' holds the label -2 \(row 30\)"),
    ([0] * 29 + [7], {'num_classes': 7}, r"label 7 \(row 30\).*"
                                         r"num_classes=7"),
    (None, {}, r"no labels for '.*x\.xyz'"),
])
def test_bad_labels_name_the_file(tmp_path, labels, kwargs, match):
    write_text(tmp_path / 'train' / 'x.xyz', cloud(columns=3))
    if labels is not None:
        write_labels(tmp_path / 'train' / 'x.seg', labels)
    with pytest.raises(ValueError, match=match):
        PointCloudFolder(str(tmp_path), task='segmentation', log=False,
                         **kwargs)


def test_manifest_notices_changes(tmp_path):
    classification_tree(tmp_path)
    assert len(PointCloudFolder(str(tmp_path), log=False)) == 4
    added = cloud()
    write_text(tmp_path / 'chair' / 'train' / 'n.txt', added)
    ds = PointCloudFolder(str(tmp_path), log=False)
    assert len(ds) == 5 and torch.equal(ds[2].pos,
                                        torch.from_numpy(added[:, :3]))
    changed = cloud()
    write_text(tmp_path / 'chair' / 'train' / 'n.txt', changed)
    ds = PointCloudFolder(str(tmp_path), log=False)
    assert torch.equal(ds[2].pos, torch.from_numpy(changed[:, :3]))
    os.remove(tmp_path / 'chair' / 'train' / 'n.txt')
    assert len(PointCloudFolder(str(tmp_path), log=False)) == 4
    assert len(PointCloudFolder(str(tmp_path), log=False,
                                force_reload=True)) == 4


def test_workers_give_identical_files(tmp_path):
    # the pre-transform (operators) runs in two worker processes
    import shutil
    from tg_intrinsic.transforms import MLSOperators
    classification_tree(tmp_path / 'one')
    shutil.copytree(tmp_path / 'one', tmp_path / 'two')
    one = PointCloudFolder(str(tmp_path / 'one'), 'train', log=False,
                           pre_transform=MLSOperators(k=8))
    two = PointCloudFolder(str(tmp_path / 'two'), 'train', log=False,
                           pre_transform=MLSOperators(k=8), workers=2)
    assert len(two) == 4 and 'grad_weight' in two[0]
    with open(one.processed_paths[0], 'rb') as a, \
            open(two.processed_paths[0], 'rb') as b:
        assert a.read() == b.read()
    with pytest.raises(TypeError, match='PointCloudFolder: the pre_filter'):
        PointCloudFolder(str(tmp_path / 'two'), 'test', log=False,
                         pre_filter=lambda data: True, workers=2)
