import json

import numpy as np
import pytest
import torch

from tg_intrinsic.datasets import ShapeNetPartNormal
from tg_intrinsic.datasets.shapenet_part_normal import CATEGORY_PARTS

SYNSETS = [('Airplane', '02691156'), ('Bag', '02773838'),
           ('Cap', '02954340'), ('Car', '02958343'), ('Chair', '03001627'),
           ('Earphone', '03261776'), ('Guitar', '03467517'),
           ('Knife', '03624134'), ('Lamp', '03636649'),
           ('Laptop', '03642806'), ('Motorbike', '03790512'),
           ('Mug', '03797390'), ('Pistol', '03948459'),
           ('Rocket', '04099429'), ('Skateboard', '04225987'),
           ('Table', '04379243')]
SPLITS = {'train': [('02691156', 'a1'), ('02691156', 'a2'),
                    ('03001627', 'c1')],
          'val': [('03001627', 'c2')],
          'test': [('02691156', 'a3'), ('03001627', 'c3')]}
PARTS = {'02691156': [0, 1, 2, 3], '03001627': [12, 13, 14, 15]}


def write_shape(path, rng, parts, n=30):
    """'x y z nx ny nz part' per line, the part written as a float."""
    table = rng.uniform(-1, 1, (n, 6))
    labels = rng.choice(parts, n)
    path.write_text(''.join(
        ' '.join(f'{x:.5f}' for x in row) + f' {label:.6f}\n'
        for row, label in zip(table, labels)))
    return np.round(table, 5).astype(np.float32), labels


def make_release(root):
    rng = np.random.default_rng(0)
    (root / 'synsetoffset2category.txt').write_text(
        ''.join(f'{name}\t{synset}\n' for name, synset in SYNSETS))
    (root / 'train_test_split').mkdir()
    values = {}
    for split, shapes in SPLITS.items():
        with open(root / 'train_test_split' /
                  f'shuffled_{split}_file_list.json', 'w') as f:
            json.dump([f'shape_data/{s}/{t}' for s, t in shapes], f)
        for synset, token in shapes:
            (root / synset).mkdir(exist_ok=True)
            values[token] = write_shape(root / synset / f'{token}.txt', rng,
                                        PARTS[synset])
    return values


def test_reads_the_release(tmp_path):
    values = make_release(tmp_path)
    train = ShapeNetPartNormal(str(tmp_path), 'train', log=False)
    assert len(train) == 3 and train.num_classes == 50
    assert train.categories == [name for name, _ in SYNSETS]
    for data, token in zip(train, ['a1', 'a2', 'c1']):
        table, labels = values[token]
        assert torch.equal(data.pos, torch.from_numpy(table[:, :3]))
        assert torch.equal(data.normal, torch.from_numpy(table[:, 3:]))
        assert data.y.dtype == torch.long
        assert data.y.tolist() == labels.tolist()
    assert [int(d.category) for d in train] == [0, 0, 4]
    trainval = ShapeNetPartNormal(str(tmp_path), 'trainval', log=False)
    assert len(trainval) == 4
    assert torch.equal(trainval[3].pos, torch.from_numpy(
        values['c2'][0][:, :3]))
    assert len(ShapeNetPartNormal(str(tmp_path), 'val', log=False)) == 1
    chairs = ShapeNetPartNormal(str(tmp_path), 'test', categories='Chair',
                                log=False)
    assert len(chairs) == 1 and int(chairs[0].category) == 4
    assert "categories=['Chair']" in repr(chairs)


def test_category_parts():
    ds_parts = CATEGORY_PARTS
    assert sum(len(p) for p in ds_parts.values()) == 50
    assert ds_parts['Airplane'] == [0, 1, 2, 3]
    assert ds_parts['Chair'] == [12, 13, 14, 15]
    assert ds_parts['Motorbike'] == [30, 31, 32, 33, 34, 35]
    assert ds_parts['Table'] == [47, 48, 49]


def test_part_mask(tmp_path):
    make_release(tmp_path)
    ds = ShapeNetPartNormal(str(tmp_path), 'test', log=False)
    assert ds.part_mask.shape == (16, 50) and ds.part_mask.sum() == 50
    assert ds.part_mask[4].nonzero().flatten().tolist() == [12, 13, 14, 15]
    assert ds.category_parts['Bag'] == [4, 5]
    # every point's label is a part of its shape's category
    for data in ds:
        assert ds.part_mask[data.category, data.y].all()


@pytest.mark.parametrize('change,match', [
    ('wrong_part', r"a1\.txt' row 1: part label 12 is not a part of "
                   r"Airplane \(its parts are 0-3\)"),
    ('missing', r"a2\.txt' \(listed in '.*shuffled_train_file_list\.json'\)"),
    ('synset', r"lists 'shape_data/99999999/x'.*not in "
               r"'.*synsetoffset2category\.txt'"),
    ('columns', r"a1\.txt' must have 7 columns"),
    ('category', r"synsetoffset2category\.txt' line 1"),
])
def test_errors_name_the_file(tmp_path, change, match):
    make_release(tmp_path)
    a1 = tmp_path / '02691156' / 'a1.txt'
    lists = tmp_path / 'train_test_split' / 'shuffled_train_file_list.json'
    if change == 'wrong_part':
        lines = a1.read_text().splitlines()
        lines[0] = lines[0].rsplit(' ', 1)[0] + ' 12.000000'
        a1.write_text('\n'.join(lines) + '\n')
    elif change == 'missing':
        (tmp_path / '02691156' / 'a2.txt').unlink()
    elif change == 'synset':
        lists.write_text(json.dumps(json.loads(lists.read_text())
                                    + ['shape_data/99999999/x']))
    elif change == 'columns':
        a1.write_text('0 0 0\n1 1 1\n')
    else:
        synsets = tmp_path / 'synsetoffset2category.txt'
        synsets.write_text('Plane\t02691156\n' + synsets.read_text())
    with pytest.raises(ValueError, match=match):
        ShapeNetPartNormal(str(tmp_path), 'train', log=False)


def test_bad_arguments(tmp_path):
    make_release(tmp_path)
    with pytest.raises(ValueError, match="unknown ShapeNet-Part categories "
                       r"\['chair'\]"):
        ShapeNetPartNormal(str(tmp_path), categories=['chair'])
    with pytest.raises(ValueError, match="'split' must be one of"):
        ShapeNetPartNormal(str(tmp_path), split='all')
    with pytest.raises(ValueError, match=r"split 'val' has no shapes of "
                       r"\['Airplane'\]"):
        ShapeNetPartNormal(str(tmp_path), 'val', categories='Airplane')


def test_manifest_notices_changes(tmp_path):
    make_release(tmp_path)
    assert len(ShapeNetPartNormal(str(tmp_path), 'test', log=False)) == 2
    lists = tmp_path / 'train_test_split' / 'shuffled_test_file_list.json'
    lists.write_text(json.dumps(['shape_data/03001627/c3']))
    ds = ShapeNetPartNormal(str(tmp_path), 'test', log=False)
    assert len(ds) == 1 and int(ds[0].category) == 4
