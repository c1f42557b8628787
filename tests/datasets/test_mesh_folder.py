import os

import numpy as np
import pytest
import torch
import trimesh
from torch_geometric.loader import DataLoader

from tg_intrinsic import IntrinsicData
from tg_intrinsic.datasets import MeshFolder
from tg_intrinsic.io import mesh as mf

TET_V = np.array([[0, 0, 0], [1, 0, 0], [0, 1, 0], [0, 0, 1.5]])
TET_F = np.array([[0, 2, 1], [0, 1, 3], [1, 2, 3], [0, 3, 2]])


def write_off(path, V, F, header='OFF\n{nv} {nf} 0\n', comment=True):
    with open(path, 'w') as f:
        f.write(header.format(nv=len(V), nf=len(F)))
        if comment:
            f.write('# a comment line\n')
        for v in V:
            f.write(' '.join(f'{x:.6f}' for x in v) + '\n')
        for face in F:
            f.write(f'{len(face)} ' + ' '.join(str(i) for i in face) + '\n')


def cube():
    m = trimesh.creation.box()
    return np.asarray(m.vertices), np.asarray(m.faces)


def make_tree(root):
    """cube/{train,test}, tet/{train,test}, with .obj/.off/.ply files."""
    for c in ('cube', 'tet'):
        for s in ('train', 'test'):
            os.makedirs(root / c / s)
    V, F = cube()
    trimesh.Trimesh(V, F, process=False).export(root / 'cube' / 'train' /
                                                'c1.obj')
    # quads in an OFF file, counts on the next line
    quads = [[0, 1, 3, 2], [4, 6, 7, 5]]
    write_off(root / 'cube' / 'test' / 'c2.off', V, quads)
    # ModelNet's malformed single-line header
    write_off(root / 'tet' / 'train' / 't1.off', TET_V, TET_F,
              header='OFF{nv} {nf} 0\n', comment=False)
    trimesh.Trimesh(TET_V + 1, TET_F, process=False).export(
        root / 'tet' / 'train' / 't2.ply')
    trimesh.Trimesh(TET_V * 2, TET_F, process=False).export(
        root / 'tet' / 'test' / 't3.obj')
    (root / 'tet' / 'train' / 'notes.txt').write_text('not a mesh')
    return V, F


def test_reads_tree(tmp_path):
    V, F = make_tree(tmp_path)
    train = MeshFolder(str(tmp_path), split='train', log=False)
    assert train.classes == ['cube', 'tet'] and train.num_classes == 2
    assert len(train) == 3
    assert [int(d.y) for d in train] == [0, 1, 1]
    c1, t1, t2 = train[0], train[1], train[2]
    assert isinstance(c1, IntrinsicData)
    assert c1.pos.dtype == torch.float32 and c1.face.shape == (3, 12)
    # nothing merged or reordered
    assert np.allclose(c1.pos.numpy(), V, atol=1e-6)
    assert np.array_equal(c1.face.t().numpy(), F)
    assert np.allclose(t1.pos.numpy(), TET_V, atol=1e-6)
    assert np.array_equal(t1.face.t().numpy(), TET_F)
    assert np.allclose(t2.pos.numpy(), TET_V + 1, atol=1e-6)
    assert np.array_equal(t2.face.t().numpy(), TET_F)
    assert os.path.isdir(tmp_path / 'processed_tg_intrinsic')

    test = MeshFolder(str(tmp_path), split='test', log=False)
    assert len(test) == 2 and [int(d.y) for d in test] == [0, 1]
    # quads are split into triangle fans
    assert test[0].face.t().tolist() == [[0, 1, 3], [0, 3, 2], [4, 6, 7],
                                         [4, 7, 5]]
    assert 'MeshFolder(2' in repr(test)


def test_malformed_off_header(tmp_path):
    path = tmp_path / 'm.off'
    write_off(path, TET_V, TET_F, header='OFF{nv} {nf} 0\n', comment=False)
    assert path.read_text().startswith('OFF4 4 0\n')
    pos, face = mf.read_off(str(path))
    assert np.allclose(pos, TET_V) and np.array_equal(face, TET_F)
    # COFF with colour columns, counts on the header line too
    path2 = tmp_path / 'c.off'
    with open(path2, 'w') as f:
        f.write('COFF 4 4 0\n')
        for v in TET_V:
            f.write(' '.join(map(str, v)) + ' 255 0 0 255\n')
        for t in TET_F:
            f.write('3 ' + ' '.join(map(str, t)) + ' 0 255 0\n')
    pos, face = mf.read_off(str(path2))
    assert np.allclose(pos, TET_V) and np.array_equal(face, TET_F)


def test_cached(tmp_path, monkeypatch):
    make_tree(tmp_path)
    first = MeshFolder(str(tmp_path), log=False)

    def fail(*args, **kwargs):
        raise AssertionError('files read again')

    monkeypatch.setattr(mf, 'read_mesh', fail)
    again = MeshFolder(str(tmp_path), log=False)
    assert len(again) == len(first) and again.classes == first.classes
    assert torch.equal(again[1].pos, first[1].pos)


def test_missing_and_empty_folders(tmp_path):
    with pytest.raises(ValueError, match=r"not a folder.*<class>/<split>"):
        MeshFolder(str(tmp_path / 'nope'))
    with pytest.raises(ValueError, match='no class folders'):
        MeshFolder(str(tmp_path))
    os.makedirs(tmp_path / 'chair' / 'train')
    (tmp_path / 'chair' / 'train' / 'a.off').write_text(
        'OFF\n4 4 0\n' + '\n'.join(' '.join(map(str, v)) for v in TET_V)
        + '\n' + '\n'.join('3 ' + ' '.join(map(str, t)) for t in TET_F))
    with pytest.raises(ValueError, match=r"split 'test'.*chair"):
        MeshFolder(str(tmp_path), split='test', log=False)
    assert len(MeshFolder(str(tmp_path), split='train', log=False)) == 1


@pytest.mark.parametrize('name,text,match', [
    ('bad.off', 'this is not an off file\n', 'OFF'),
    ('short.off', 'OFF\n8 12 0\n0 0 0\n', 'announces'),
    ('range.off', 'OFF\n3 1 0\n0 0 0\n1 0 0\n0 1 0\n3 0 1 7\n', 'outside'),
    ('nan.off', 'OFF\n3 1 0\n0 0 nan\n1 0 0\n0 1 0\n3 0 1 2\n', 'NaN'),
    ('empty.obj', '# nothing here\n', 'no'),
])
def test_unreadable_file_is_named(tmp_path, name, text, match):
    os.makedirs(tmp_path / 'thing' / 'train')
    path = tmp_path / 'thing' / 'train' / name
    path.write_text(text)
    with pytest.raises(ValueError, match=match) as info:
        MeshFolder(str(tmp_path), log=False)
    assert name in str(info.value)


def test_batching(tmp_path):
    make_tree(tmp_path)
    ds = MeshFolder(str(tmp_path), log=False)
    batch = next(iter(DataLoader(ds, batch_size=3)))
    assert batch.num_graphs == 3 and batch.pos.size(0) == 8 + 4 + 4
    assert int(batch.face[:, 12:].min()) == 8
    assert int(batch.face.max()) == 15


def test_bad_split(tmp_path):
    with pytest.raises(ValueError, match='split'):
        MeshFolder(str(tmp_path), split='validation')
