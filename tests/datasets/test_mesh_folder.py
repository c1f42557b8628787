import os

import numpy as np
import pytest
import torch
import trimesh
from torch_geometric.loader import DataLoader

from tg_intrinsic import IntrinsicData
from tg_intrinsic.datasets import MeshFolder
from tg_intrinsic.datasets import mesh_folder
from tg_intrinsic.io import mesh as mf
from tests.io.test_labels import brute_votes, meshcnn_reference
from tests.io.test_mesh import REPEATED_VERTEX, TET_F, TET_V, write_off


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


def test_cached(tmp_path, monkeypatch):
    make_tree(tmp_path)
    first = MeshFolder(str(tmp_path), log=False)

    def fail(*args, **kwargs):
        raise AssertionError('files read again')

    monkeypatch.setattr(mesh_folder, "read_mesh", fail)
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


# --- segmentation -----------------------------------------------------------


def sphere():
    m = trimesh.creation.icosphere(subdivisions=1)  # 42 v, 80 f, 120 e
    return np.asarray(m.vertices), np.asarray(m.faces)


def write_obj(path, V, F):
    """An OBJ as MeshCNN's files are: 'v' and 1-based 'f' lines only."""
    with open(path, 'w') as f:
        f.writelines('v ' + ' '.join(repr(float(x)) for x in p) + '\n'
                     for p in V)
        f.writelines(f'f {a + 1} {b + 1} {c + 1}\n' for a, b, c in F)


def write_lines(path, values, fmt='{}'):
    path.parent.mkdir(parents=True, exist_ok=True)
    path.write_text(''.join(fmt.format(v) + '\n' for v in values))


def meshcnn_tree(root):
    """MeshCNN's human_seg layout: train/test objs, seg/*.eseg (1-based),
    sseg/*.seseg. Returns {stem: (V, F, edges, hard 0-based, soft)}."""
    rng = np.random.default_rng(0)
    V, F = sphere()
    bV, bF = cube()
    meshes = {'a': ('train', V, F), 'b': ('train', bV, bF),
              'c': ('test', V * 2, F[rng.permutation(len(F))])}
    out = {}
    for stem, (split, V_, F_) in meshes.items():
        (root / split).mkdir(parents=True, exist_ok=True)
        write_obj(root / split / f'{stem}.obj', V_, F_)
        edges = meshcnn_reference(V_, F_)
        top = 4 if stem == 'c' else 3  # class 4 only in the test split
        hard = rng.integers(1, top + 1, len(edges))
        write_lines(root / 'seg' / f'{stem}.eseg', hard)
        soft = rng.random((len(edges), top)) * (
            rng.random((len(edges), top)) > 0.5)
        write_lines(root / 'sseg' / f'{stem}.seseg',
                    [' '.join(f'{x:.6f}' for x in row) for row in soft])
        out[stem] = (V_, F_, edges, hard - 1,
                     np.loadtxt(root / 'sseg' / f'{stem}.seseg'))
    return out


def test_meshcnn_segmentation_layout(tmp_path):
    meshes = meshcnn_tree(tmp_path)
    train = MeshFolder(str(tmp_path), 'train', task='segmentation',
                       log=False)
    assert len(train) == 2 and train.classes is None
    assert train.num_classes == 4  # the test split's label 4 counts
    assert 'segmentation' in repr(train)
    for data, stem in zip(train, 'ab'):
        V, F, edges, hard, soft = meshes[stem]
        length = np.linalg.norm(V[edges[:, 0]] - V[edges[:, 1]], axis=1)
        assert np.allclose(data.pos.numpy(), V, atol=1e-6)
        assert np.array_equal(data.face.t().numpy(), F)
        assert data.y.dtype == torch.long and data.y.shape == (len(V), )
        assert np.array_equal(data.y.numpy(), brute_votes(
            len(V), edges, hard, length, 4))
        votes = np.zeros((len(V), 3))
        for (i, j), row, w in zip(edges, soft, length):
            votes[i] += w * row
            votes[j] += w * row
        assert data.y_soft.shape == (len(V), 4)  # padded to num_classes
        assert np.allclose(data.y_soft[:, :3].numpy(),
                           votes / votes.sum(1, keepdims=True), atol=1e-6)
        assert (data.y_soft[:, 3] == 0).all()
    test = MeshFolder(str(tmp_path), 'test', task='segmentation', log=False)
    V, F, edges, hard, _ = meshes['c']
    length = np.linalg.norm(V[edges[:, 0]] - V[edges[:, 1]], axis=1)
    assert np.array_equal(test[0].y.numpy(), brute_votes(
        len(V), edges, hard, length, 4))
    batch = next(iter(DataLoader(train, batch_size=2)))
    assert batch.y.shape == (42 + 8, ) and batch.y_soft.shape == (50, 4)


def test_vertex_and_face_labels(tmp_path):
    V, F = sphere()
    rng = np.random.default_rng(3)
    vertex_labels = rng.integers(0, 3, len(V))
    face_labels = rng.integers(0, 5, len(F))
    (tmp_path / 'train').mkdir()
    (tmp_path / 'test').mkdir()
    write_obj(tmp_path / 'train' / 'v.obj', V, F)
    write_lines(tmp_path / 'train' / 'v.txt', vertex_labels)  # beside
    trimesh.Trimesh(V, F, process=False).export(tmp_path / 'test' / 'f.ply')
    (tmp_path / 'labels').mkdir()
    np.save(tmp_path / 'labels' / 'f.npy', face_labels)  # parallel folder
    train = MeshFolder(str(tmp_path), 'train', task='segmentation',
                       log=False)
    assert np.array_equal(train[0].y.numpy(), vertex_labels)
    assert train.num_classes == 5 and 'y_soft' not in train[0]
    test = MeshFolder(str(tmp_path), 'test', task='segmentation', log=False)
    a = mf.read_mesh(str(tmp_path / 'test' / 'f.ply'))[0][F]  # float32 PLY
    area = 0.5 * np.linalg.norm(np.cross(a[:, 1] - a[:, 0],
                                         a[:, 2] - a[:, 0]), axis=1)
    assert np.array_equal(test[0].y.numpy(),
                          brute_votes(len(V), F, face_labels, area, 5))
    # label_kind forces a reading; 42 labels cannot be per face
    with pytest.raises(ValueError, match=r"holds 42 labels, but per-face "
                       r"labels of '.*v\.obj' need 80"):
        MeshFolder(str(tmp_path), 'train', task='segmentation',
                   label_kind='face', log=False)


def test_triangle_soup_is_welded(tmp_path):
    V, F = sphere()
    rng = np.random.default_rng(4)
    truth = rng.integers(0, 3, len(V))
    soup_V = V[F].reshape(-1, 3)  # 240 vertices, no face shares one
    soup_F = np.arange(len(soup_V)).reshape(-1, 3)
    labels = truth[F].reshape(-1).copy()
    # one copy of a vertex disagrees: the majority of its copies wins
    copies = np.nonzero(F.reshape(-1) == 0)[0]
    labels[copies[0]] = (truth[0] + 1) % 3
    (tmp_path / 'train').mkdir()
    write_obj(tmp_path / 'train' / 'soup.obj', soup_V, soup_F)
    write_lines(tmp_path / 'train' / 'soup.txt', labels)
    with pytest.warns(UserWarning, match=r"soup\.obj.*merged 198 vertices "
                      r"\(240 -> 42\)"):
        ds = MeshFolder(str(tmp_path), 'train', task='segmentation',
                        log=False)
    data = ds[0]
    merged = trimesh.Trimesh(soup_V, soup_F, process=False)
    merged.merge_vertices(merge_tex=True, merge_norm=True)
    assert data.pos.size(0) == len(merged.vertices) == 42
    welded = trimesh.Trimesh(data.pos.numpy(), data.face.t().numpy(),
                             process=False)
    assert welded.is_watertight  # faces share vertices now
    # labels followed the weld: match vertices by position
    original = np.linalg.norm(data.pos.numpy()[:, None] - V[None], axis=2
                              ).argmin(1)
    assert np.array_equal(data.y.numpy(), truth[original])


def test_classification_soup_warns(tmp_path):
    V, F = sphere()
    (tmp_path / 'ball' / 'train').mkdir(parents=True)
    write_obj(tmp_path / 'ball' / 'train' / 's.obj', V[F].reshape(-1, 3),
              np.arange(3 * len(F)).reshape(-1, 3))
    with pytest.warns(UserWarning, match='merged 198 vertices'):
        ds = MeshFolder(str(tmp_path), log=False)
    assert ds[0].pos.size(0) == 42


def seg_tree(root, label_text='0\n' * 8):
    """train/{a,b}.obj (cubes) with beside labels; b's text is given."""
    V, F = cube()
    for split in ('train', 'test'):
        (root / split).mkdir(exist_ok=True)
    write_obj(root / 'train' / 'a.obj', V, F)
    write_lines(root / 'train' / 'a.txt', [0, 1] * 4)
    write_obj(root / 'train' / 'b.obj', V, F)
    (root / 'train' / 'b.txt').write_text(label_text)


@pytest.mark.parametrize('text,kwargs,match', [
    ('0\n' * 7, {}, r"b\.txt' holds 7 labels, but '.*b\.obj' has 8 "
                    r"vertices, 12 faces and 18 edges"),
    ('0\n' * 7 + '1.5\n', {}, r"b\.txt' holds the non-integer label 1\.5"),
    ('0\n' * 7 + '-1\n', {}, r"b\.txt' holds the label -1 \(row 8\), which "
                             r"is negative"),
    ('0\n' * 7 + '3\n', {'num_classes': 3}, r"b\.txt' holds the label 3 "
                                            r"\(row 8\).*num_classes=3"),
    ('0\n' * 7 + 'x\n', {}, r"could not read '.*b\.txt'"),
])
def test_bad_labels_name_the_file(tmp_path, text, kwargs, match):
    seg_tree(tmp_path, text)
    with pytest.raises(ValueError, match=match):
        MeshFolder(str(tmp_path), task='segmentation', log=False, **kwargs)


def test_missing_and_ambiguous_label_files(tmp_path):
    seg_tree(tmp_path)
    (tmp_path / 'train' / 'b.txt').unlink()
    with pytest.raises(ValueError, match=r"no label file for '.*b\.obj'"):
        MeshFolder(str(tmp_path), task='segmentation', log=False)
    write_lines(tmp_path / 'train' / 'b.txt', [0] * 8)
    write_lines(tmp_path / 'labels' / 'b.seg', [0] * 8)
    with pytest.raises(ValueError, match=r"several label files for 'b'"):
        MeshFolder(str(tmp_path), task='segmentation', log=False)


def test_eseg_is_one_based(tmp_path):
    V, F = cube()
    (tmp_path / 'train').mkdir()
    write_obj(tmp_path / 'train' / 'a.obj', V, F)
    write_lines(tmp_path / 'seg' / 'a.eseg', [1, 2] * 9)
    ds = MeshFolder(str(tmp_path), task='segmentation', log=False)
    assert ds.num_classes == 2 and set(ds[0].y.tolist()) <= {0, 1}
    write_lines(tmp_path / 'seg' / 'a.eseg', [0, 1] * 9)
    with pytest.raises(ValueError, match=r"a\.eseg' holds the label 0 .*"
                       r"negative \(read as 1-based: label_offset=1\)"):
        MeshFolder(str(tmp_path), task='segmentation', log=False)
    ds = MeshFolder(str(tmp_path), task='segmentation', label_offset=0,
                    log=False)
    assert ds.num_classes == 2
    write_lines(tmp_path / 'seg' / 'a.eseg', [1] * 17)
    with pytest.raises(ValueError, match=r"holds 17 labels, but per-edge "
                       r"labels of '.*a\.obj' need 18"):
        MeshFolder(str(tmp_path), task='segmentation', log=False)


def test_bad_mesh_among_good_ones_is_named(tmp_path):
    make_tree(tmp_path)
    (tmp_path / 'tet' / 'train' / 'broken.off').write_text('OFF\n8 12 0\n')
    with pytest.raises(ValueError, match=r"broken\.off"):
        MeshFolder(str(tmp_path), log=False)
    seg_tree(tmp_path)
    (tmp_path / 'train' / 'c.obj').write_text('v 0 0 0\nf 1 2 3\n')
    write_lines(tmp_path / 'train' / 'c.txt', [0])
    with pytest.raises(ValueError, match=r"c\.obj"):
        MeshFolder(str(tmp_path), task='segmentation', log=False)


def test_classification_rejects_label_options(tmp_path):
    make_tree(tmp_path)
    with pytest.raises(ValueError, match="'num_classes' apply to "
                       "task='segmentation'"):
        MeshFolder(str(tmp_path), num_classes=3)
    with pytest.raises(ValueError, match="'task' must be one of"):
        MeshFolder(str(tmp_path), task='regression')


def test_manifest_notices_changes(tmp_path, monkeypatch):
    seg_tree(tmp_path)
    calls = []

    def counting(path, **kwargs):
        calls.append(os.path.basename(path))
        return mf.read_mesh(path, **kwargs)

    monkeypatch.setattr(mesh_folder, 'read_mesh', counting)

    def load(**kwargs):
        calls.clear()
        return MeshFolder(str(tmp_path), task='segmentation', log=False,
                          **kwargs)

    assert len(load()) == 2 and calls == ['a.obj', 'b.obj']
    assert len(load()) == 2 and calls == []  # cached
    manifest = tmp_path / 'processed_tg_intrinsic' / \
        'segmentation_train_auto_offsetauto_classesauto_manifest.json'
    assert 'train/a.obj' in manifest.read_text().replace(os.sep, '/')
    # added
    V, F = cube()
    write_obj(tmp_path / 'train' / 'c.obj', V, F)
    write_lines(tmp_path / 'train' / 'c.txt', [2] * 8)
    ds = load()
    assert len(ds) == 3 and ds.num_classes == 3 and len(calls) == 3
    # rewritten (same size, new content and time)
    write_lines(tmp_path / 'train' / 'c.txt', [1] * 8)
    stat = os.stat(tmp_path / 'train' / 'c.txt')
    os.utime(tmp_path / 'train' / 'c.txt',
             ns=(stat.st_atime_ns, stat.st_mtime_ns + 10 ** 9))
    ds = load()
    assert ds[2].y.tolist() == [1] * 8 and ds.num_classes == 2
    # touched only
    stat = os.stat(tmp_path / 'train' / 'a.obj')
    os.utime(tmp_path / 'train' / 'a.obj',
             ns=(stat.st_atime_ns, stat.st_mtime_ns + 10 ** 9))
    assert len(load()) == 3 and len(calls) == 3
    # removed
    os.remove(tmp_path / 'train' / 'c.obj')
    os.remove(tmp_path / 'train' / 'c.txt')
    assert len(load()) == 2 and len(calls) == 2
    assert len(load()) == 2 and calls == []
    assert len(load(force_reload=True)) == 2 and len(calls) == 2


def test_soft_labels_alone_and_unlabelled_vertices(tmp_path):
    meshes = meshcnn_tree(tmp_path)
    for stem in 'abc':
        os.remove(tmp_path / 'seg' / f'{stem}.eseg')
    ds = MeshFolder(str(tmp_path), task='segmentation', log=False)
    V, F, edges, _, soft = meshes['a']
    length = np.linalg.norm(V[edges[:, 0]] - V[edges[:, 1]], axis=1)
    assert ds.num_classes == 4  # the test split's 4 soft label columns
    assert np.array_equal(ds[0].y.numpy(),
                          brute_votes(len(V), edges, soft, length, 3))
    # a vertex on no face cannot take a per-face label
    (tmp_path / 'train' / 'lone.off').write_text(
        'OFF\n5 4 0\n' + '\n'.join(' '.join(map(str, v)) for v in
                                   np.vstack([TET_V, [[5, 5, 5]]]))
        + '\n' + '\n'.join('3 ' + ' '.join(map(str, t)) for t in TET_F))
    write_lines(tmp_path / 'train' / 'lone.txt', [0, 1, 0, 1])
    with pytest.raises(ValueError, match=r"1 vertex\(es\) of '.*lone\.off' "
                       r"\(first: 4\) get no label from '.*lone\.txt'"):
        MeshFolder(str(tmp_path), task='segmentation', log=False)


@pytest.mark.parametrize('name,text,match', REPEATED_VERTEX)
def test_faces_repeating_a_vertex_name_file_and_face(tmp_path, name, text,
                                                     match):
    # The reader rejects such faces (tests/io/test_mesh.py), naming the
    # file and the face; before, MeshFolder loaded them and the geometry
    # code failed later without naming the file.
    os.makedirs(tmp_path / 'thing' / 'train')
    path = tmp_path / 'thing' / 'train' / name
    path.write_text(text)
    with pytest.raises(ValueError, match=match) as info:
        MeshFolder(str(tmp_path), log=False)
    message = str(info.value)
    assert str(path) in message and 'repeat a vertex' in message
    assert 'Delete these faces' in message and 'nondegenerate_faces' in \
        message
