"""Point clouds on disk: numeric tables (text with spaces or commas,
.npy) and PLY files, the meaning of their columns and properties,
round trips through numpy's and our own writers and trimesh's loader, and
the errors that name the file."""
import numpy as np
import pytest
import trimesh

from tg_intrinsic.io.mesh import write_ply
from tg_intrinsic.io.points import read_points, read_table


def table(rows=20, columns=3, seed=0):
    """float32 values: text and binary round trips are exact."""
    rng = np.random.default_rng(seed)
    return rng.standard_normal((rows, columns)).astype(np.float32)


def write_text(path, values, sep=' '):
    path.write_text(''.join(sep.join(repr(float(x)) for x in row) + '\n'
                            for row in values))


@pytest.mark.parametrize('sep', [' ', ',', '\t', ', '])
def test_text_tables_with_any_separator(tmp_path, sep):
    values = table(columns=6)
    write_text(tmp_path / 't.txt', values, sep)
    got = read_table(str(tmp_path / 't.txt'))
    assert got.dtype == np.float64 and np.array_equal(got, values)


def test_comments_blank_lines_npy_and_max_rows(tmp_path):
    (tmp_path / 'c.xyz').write_text('# x y z\n1 2 3\n\n4 5 6  # a note\n'
                                    '7 8 9\n')
    assert read_table(str(tmp_path / 'c.xyz')).tolist() == [
        [1, 2, 3], [4, 5, 6], [7, 8, 9]]
    assert read_table(str(tmp_path / 'c.xyz'), max_rows=2).tolist() == [
        [1, 2, 3], [4, 5, 6]]
    np.save(tmp_path / 'one.npy', np.arange(3, dtype=np.int16))
    one = read_table(str(tmp_path / 'one.npy'))
    assert one.shape == (3, 1) and one.dtype == np.float64
    values = table(columns=4)
    np.save(tmp_path / 'v.npy', values)
    assert np.array_equal(read_table(str(tmp_path / 'v.npy')), values)
    assert np.array_equal(read_table(str(tmp_path / 'v.npy'), max_rows=5),
                          values[:5])


@pytest.mark.parametrize('name,content,problem', [
    ('empty.txt', '', 'holds no table of numbers (shape (0, 1)); give one '
                      'row per point'),
    ('blank.txt', '\n# nothing\n\n', 'holds no table of numbers'),
    ('ragged.txt', '1 2 3\n4 5\n', 'could not read'),
    ('word.pts', '1 2 3\n4 five 6\n', 'could not read'),
    ('nan.txt', '1 2 3\n4 nan 6\n7 8 9\n', 'holds NaN or infinite values '
                                          '(first in row 2)'),
    ('inf.xyz', '1 2 3\n4 5 6\n7 8 -inf\n', 'first in row 3'),
])
def test_a_bad_table_names_the_file_and_the_problem(tmp_path, name, content,
                                                    problem):
    (tmp_path / name).write_text(content)
    with pytest.raises(ValueError) as info:
        read_table(str(tmp_path / name))
    assert str(tmp_path / name) in str(info.value)
    assert problem in str(info.value)


def test_bad_npy_tables(tmp_path):
    for name, array, problem in [
            ('e.npy', np.zeros((0, 3)), 'holds no table of numbers'),
            ('cube.npy', np.zeros((2, 2, 3)), 'shape (2, 2, 3)'),
            ('s.npy', np.array([['a', 'b', 'c']]), 'is not numeric (<U1)')]:
        np.save(tmp_path / name, array)
        with pytest.raises(ValueError) as info:
            read_table(str(tmp_path / name))
        assert name in str(info.value) and problem in str(info.value)
    with pytest.raises(FileNotFoundError, match=r"gone\.txt' does not "
                       r"exist"):
        read_table(str(tmp_path / 'gone.txt'))


@pytest.mark.parametrize('columns,normals,labels', [
    (3, False, False), (4, False, True), (5, False, False),
    (6, True, False), (7, True, True), (8, True, False)])
def test_what_the_columns_mean(tmp_path, columns, normals, labels):
    values = table(columns=columns)
    write_text(tmp_path / 'p.txt', values)
    pos, normal, label = read_points(str(tmp_path / 'p.txt'))
    assert np.array_equal(pos, values[:, :3])
    assert (normal is not None) == normals
    assert (label is not None) == labels
    if normals:
        assert np.array_equal(normal, values[:, 3:6])
    if labels:
        assert np.array_equal(label, values[:, -1])


def test_ply_normals_labels_and_faces(tmp_path):
    values = table(columns=6)
    label = np.arange(len(values)) % 3
    path = tmp_path / 'p.ply'
    write_ply(str(path), values[:, :3], properties={
        'nx': values[:, 3], 'ny': values[:, 4], 'nz': values[:, 5],
        'label': label})
    pos, normal, got = read_points(str(path))
    assert np.array_equal(pos, values[:, :3])
    assert np.array_equal(normal, values[:, 3:])
    assert np.array_equal(got, label) and got.dtype == np.float64
    # trimesh's loader agrees on the points
    assert np.array_equal(trimesh.load(path).vertices, pos)
    pos, normal, got = read_points(str(path), max_points=5)
    assert len(pos) == len(normal) == len(got) == 5
    # a 'class' property is a label too; the faces of a mesh are ignored
    mesh = trimesh.creation.icosphere(1)
    write_ply(str(path), mesh.vertices, mesh.faces,
              properties={'class': np.ones(len(mesh.vertices))})
    pos, normal, got = read_points(str(path))
    assert np.array_equal(pos, mesh.vertices) and normal is None
    assert (got == 1).all()
    write_ply(str(path), mesh.vertices)
    assert read_points(str(path))[1:] == (None, None)


def test_npy_points_and_max_points(tmp_path):
    values = table(columns=7)
    np.save(tmp_path / 'p.npy', values)
    pos, normal, label = read_points(str(tmp_path / 'p.npy'), max_points=4)
    assert np.array_equal(pos, values[:4, :3])
    assert np.array_equal(normal, values[:4, 3:6])
    assert np.array_equal(label, values[:4, 6])


def test_bad_point_clouds_name_the_file(tmp_path):
    (tmp_path / 'p.obj').write_text('v 0 0 0\n')
    with pytest.raises(ValueError, match=r"p\.obj': unknown point cloud "
                       r"format '\.obj'; use one of "
                       r"\.ply/\.txt/\.xyz/\.npy/\.pts"):
        read_points(str(tmp_path / 'p.obj'))
    with pytest.raises(ValueError, match=r"'\(none\)'"):
        read_points(str(tmp_path / 'points'))
    write_text(tmp_path / 'flat.txt', table(columns=2))
    with pytest.raises(ValueError, match=r"flat\.txt' has 2 column\(s\); a "
                       r"point needs at least 'x y z'"):
        read_points(str(tmp_path / 'flat.txt'))
    values = table(columns=6).astype(np.float64)
    values[3, 4] = np.nan
    write_ply(str(tmp_path / 'n.ply'), values[:, :3], properties={
        'nx': values[:, 3], 'ny': values[:, 4], 'nz': values[:, 5]})
    with pytest.raises(ValueError, match=r"n\.ply' has NaN or infinite "
                       r"normals"):
        read_points(str(tmp_path / 'n.ply'))
    with pytest.raises(FileNotFoundError, match=r"gone\.xyz"):
        read_points(str(tmp_path / 'gone.xyz'))


def test_a_file_that_is_not_npy_is_named_without_pickle_advice(tmp_path):
    from tg_intrinsic.io import read_points
    path = tmp_path / 'cloud.npy'
    path.write_bytes(b'not numpy at all' * 8)
    with pytest.raises(ValueError, match=r"could not read '.*cloud.npy': "
                                         r"it is not a NumPy .npy file; "
                                         r"write it with numpy.save$"):
        read_points(str(path))


@pytest.mark.parametrize('ext', ['txt', 'xyz', 'pts'])
@pytest.mark.parametrize('sep', [' ', ','])
def test_a_utf8_byte_order_mark_is_ignored(tmp_path, ext, sep):
    # Notepad saves UTF-8 with a BOM: the first value read as
    # '\ufeff0.5', "could not convert string to float64" (issue 40)
    values = table(columns=7)
    write_text(tmp_path / f'plain.{ext}', values, sep)
    text = (tmp_path / f'plain.{ext}').read_text()
    (tmp_path / f'marked.{ext}').write_text(text, encoding='utf-8-sig')
    assert (tmp_path / f'marked.{ext}').read_bytes()[:3] == b'\xef\xbb\xbf'
    want = read_points(str(tmp_path / f'plain.{ext}'))
    got = read_points(str(tmp_path / f'marked.{ext}'))
    for a, b in zip(got, want):
        assert np.array_equal(a, b)
    assert np.array_equal(got[0], values[:, :3])
    # a comment first, then the numbers
    (tmp_path / f'comment.{ext}').write_text('# x y z nx ny nz label\n'
                                             + text, encoding='utf-8-sig')
    assert np.array_equal(read_table(str(tmp_path / f'comment.{ext}')),
                          values)


def test_a_folder_is_said_to_be_a_folder(tmp_path):
    (tmp_path / 'cloud.xyz').mkdir()
    with pytest.raises(ValueError, match=r"cloud\.xyz' is a folder; give a "
                                         r"file$"):
        read_points(str(tmp_path / 'cloud.xyz'))
