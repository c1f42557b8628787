import os

import numpy as np
import pytest
import torch

from tg_intrinsic.datasets import ModelNetResampled

SHAPES = {'train': ['airplane_0001', 'airplane_0002', 'night_stand_0001',
                    'night_stand_0002'],
          'test': ['airplane_0003', 'night_stand_0003']}


def write_shape(path, rng, n=30, columns=6):
    """PointNet++'s format: 'x,y,z,nx,ny,nz' with 6 decimals."""
    rows = [','.join(f'{x:.6f}' for x in row)
            for row in rng.uniform(-1, 1, (n, columns))]
    path.write_text('\n'.join(rows) + '\n')
    return np.array([[float(x) for x in r.split(',')] for r in rows],
                    dtype=np.float32)


def make_release(root):
    """modelnet40_normal_resampled/ with 2 classes (and bathtub listed)."""
    rng = np.random.default_rng(0)
    (root / 'modelnet40_shape_names.txt').write_text(
        'airplane\nbathtub\nnight_stand\n')
    (root / 'modelnet10_shape_names.txt').write_text('bathtub\nnight_stand\n')
    values = {}
    for split, shapes in SHAPES.items():
        (root / f'modelnet40_{split}.txt').write_text('\n'.join(shapes)
                                                      + '\n')
        (root / f'modelnet10_{split}.txt').write_text('\n'.join(
            s for s in shapes if s.startswith('night')) + '\n')
        for shape in shapes:
            folder = root / shape.rsplit('_', 1)[0]
            folder.mkdir(exist_ok=True)
            values[shape] = write_shape(folder / f'{shape}.txt', rng)
    return values


def test_reads_the_release(tmp_path):
    values = make_release(tmp_path)
    train = ModelNetResampled(str(tmp_path), 'train', num_points=20,
                              log=False)
    assert train.classes == ['airplane', 'bathtub', 'night_stand']
    assert train.num_classes == 3 and len(train) == 4
    assert [int(d.y) for d in train] == [0, 0, 2, 2]
    for data, shape in zip(train, SHAPES['train']):
        table = torch.from_numpy(values[shape])
        assert torch.equal(data.pos, table[:20, :3])  # the first 20 points
        assert torch.equal(data.normal, table[:20, 3:])
    test = ModelNetResampled(str(tmp_path), 'test', num_points=30,
                             log=False)
    assert [int(d.y) for d in test] == [0, 2]
    assert test[1].pos.shape == (30, 3)
    ten = ModelNetResampled(str(tmp_path), 'train', num_classes=10,
                            num_points=30, log=False)
    assert ten.classes == ['bathtub', 'night_stand'] and len(ten) == 2
    assert [int(d.y) for d in ten] == [1, 1]
    assert 'num_classes=10, num_points=30' in repr(ten)


def test_pointnet2_shape_names_file(tmp_path):
    make_release(tmp_path)
    os.rename(tmp_path / 'modelnet40_shape_names.txt',
              tmp_path / 'shape_names.txt')
    ds = ModelNetResampled(str(tmp_path), num_points=10, log=False)
    assert ds.classes[-1] == 'night_stand'


@pytest.mark.parametrize('change,match', [
    ('missing', r"night_stand_0002\.txt' \(listed in '.*modelnet40_train"),
    ('unknown', r"modelnet40_train\.txt' line 5: shape 'chair_0001' is of "
                r"class 'chair'"),
    ('no_normals', r"night_stand_0001\.txt' has no normals"),
    ('short', r"airplane_0001\.txt' has 29 points, fewer than "
              r"num_points=30"),
    ('no_list', r"modelnet40_train\.txt' does not exist"),
])
def test_errors_name_the_file(tmp_path, change, match):
    make_release(tmp_path)
    rng = np.random.default_rng(1)
    if change == 'missing':
        os.remove(tmp_path / 'night_stand' / 'night_stand_0002.txt')
    elif change == 'unknown':
        with open(tmp_path / 'modelnet40_train.txt', 'a') as f:
            f.write('chair_0001\n')
    elif change == 'no_normals':
        write_shape(tmp_path / 'night_stand' / 'night_stand_0001.txt', rng,
                    columns=3)
    elif change == 'short':
        write_shape(tmp_path / 'airplane' / 'airplane_0001.txt', rng, n=29)
    else:
        os.remove(tmp_path / 'modelnet40_train.txt')
    with pytest.raises(ValueError, match=match):
        ModelNetResampled(str(tmp_path), num_points=30, log=False)


def test_manifest_notices_changes(tmp_path):
    make_release(tmp_path)
    ds = ModelNetResampled(str(tmp_path), num_points=30, log=False)
    new = write_shape(tmp_path / 'airplane' / 'airplane_0002.txt',
                      np.random.default_rng(5))
    ds = ModelNetResampled(str(tmp_path), num_points=30, log=False)
    assert torch.equal(ds[1].pos, torch.from_numpy(new[:, :3]))
    (tmp_path / 'modelnet40_train.txt').write_text('airplane_0001\n')
    assert len(ModelNetResampled(str(tmp_path), num_points=30,
                                 log=False)) == 1
    with pytest.raises(ValueError, match='num_classes'):
        ModelNetResampled(str(tmp_path), num_classes=20)
