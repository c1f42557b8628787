"""Meshes on disk: the OFF parser (ModelNet's malformed headers, COFF,
polygons), the trimesh-backed OBJ/PLY/STL reader, the binary PLY writer,
per-vertex signals, and the errors that name the file and the problem."""
import errno
import os
import warnings

import numpy as np
import pytest
import trimesh

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


TET_OBJ = 'v 0 0 0\nv 1 0 0\nv 0 1 0\nv 0 0 1.5\n'

# (file name, text, what the error says), shared with MeshFolder's test
REPEATED_VERTEX = [
    # the OBJ line 'f 1 1 2' uses vertex 1 twice
    ('a.obj', TET_OBJ + 'f 1 3 2\nf 1 1 2\nf 2 3 4\n',
     r"triangle 1, vertices \[0, 0, 1\] counted from 0, from line 6: "
     r"'f 1 1 2'"),
    # negative (relative) OBJ indices
    ('b.obj', TET_OBJ + 'f 1 3 2\nf -1 2 -1\n',
     r"triangle 1, vertices \[3, 1, 3\] counted from 0, from line 6: "
     r"'f -1 2 -1'"),
    # a quad with a repeated corner, in an OFF file with a comment
    ('c.off', 'OFF\n# comment\n4 2 0\n0 0 0\n1 0 0\n0 1 0\n0 0 1\n'
              '3 0 2 1\n4 0 1 1 3\n',
     r"1 triangle\(s\) that repeat a vertex \(first: triangle 1, vertices "
     r"\[0, 1, 1\] counted from 0, from line 9: '4 0 1 1 3'"),
]


@pytest.mark.parametrize('name,text,match', REPEATED_VERTEX)
def test_faces_repeating_a_vertex_name_file_and_face(tmp_path, name, text,
                                                     match):
    # The reader rejects such faces as it rejects indices out of range
    # (documented), naming the file and the face, and says what to do.
    path = tmp_path / name
    path.write_text(text)
    with pytest.raises(ValueError, match=match) as info:
        mf.read_mesh(str(path))
    message = str(info.value)
    assert str(path) in message and 'repeat a vertex' in message
    assert 'Delete these faces' in message and 'nondegenerate_faces' in \
        message


def test_ply_face_repeating_a_vertex_is_named(tmp_path):
    # no line numbers in a binary file: the triangle index
    path = tmp_path / 'p.ply'
    face = TET_F.copy()
    face[2] = [1, 3, 3]
    mf.write_ply(str(path), TET_V, face)
    with pytest.raises(ValueError, match=r"p\.ply' has 1 triangle\(s\) that "
                       r"repeat a vertex \(first: triangle 2, vertices "
                       r"\[1, 3, 3\] counted from 0\); such"):
        mf.read_mesh(str(path))
    # zero-area triangles with three distinct corners are still read
    flat = TET_V.copy()
    flat[3] = [0.5, 0.5, 0]  # on the line between vertices 1 and 2
    mf.write_ply(str(path), flat, TET_F)
    assert mf.read_mesh(str(path))[1].shape == (4, 3)


# --- reading against trimesh's geometry ---------------------------------


def icosphere():
    m = trimesh.creation.icosphere(subdivisions=1)  # 42 v, 80 f
    return np.asarray(m.vertices), np.asarray(m.faces)


@pytest.mark.parametrize('ext', ['obj', 'off', 'ply', 'stl'])
def test_every_format_gives_the_triangles_it_stores(tmp_path, ext):
    V, F = icosphere()
    path = tmp_path / f'ball.{ext}'
    trimesh.Trimesh(V, F, process=False).export(path)
    pos, face = mf.read_mesh(str(path))
    assert pos.dtype == np.float64 and face.dtype == np.int64
    assert face.shape == F.shape
    # the same triangles, corner by corner (PLY and STL store float32)
    assert np.abs(pos[face] - V[F]).max() < 1e-6
    # STL stores a triangle soup (3 vertices per face), welded on reading
    # back into the mesh (vertex order aside)
    assert len(pos) == len(V)
    if ext != 'stl':
        assert np.array_equal(face, F)
    else:
        assert len(mf.read_mesh(str(path), weld=False)[0]) == 3 * len(F)


def test_polygons_become_triangle_fans(tmp_path):
    pentagon = np.array([[0, 0, 0], [1, 0, 0], [1, 1, 0], [0, 1, 0],
                         [-0.5, 0.5, 0]])
    fans = [[0, 1, 2], [0, 2, 3], [0, 3, 4]]
    off = tmp_path / 'p.off'
    write_off(off, pentagon, [[0, 1, 2, 3, 4]])
    assert mf.read_mesh(str(off))[1].tolist() == fans
    obj = tmp_path / 'p.obj'
    obj.write_text(''.join(f'v {x} {y} {z}\n' for x, y, z in pentagon)
                   + 'f 1 2 3 4 5\n')
    pos, face = mf.read_mesh(str(obj))
    # whatever the triangulation, it covers the pentagon once (area 1.25)
    area = 0.5 * np.linalg.norm(np.cross(pos[face[:, 1]] - pos[face[:, 0]],
                                         pos[face[:, 2]] - pos[face[:, 0]]),
                                axis=1)
    assert face.shape == (3, 3) and area.sum() == pytest.approx(1.25)


def test_point_clouds_have_no_faces(tmp_path):
    points = tmp_path / 'c.off'
    points.write_text('OFF\n3 0 0\n0 0 0\n1 0 0\n1 1 0\n')
    pos, face, props = mf.read_surface(str(points))
    assert pos.tolist() == [[0, 0, 0], [1, 0, 0], [1, 1, 0]]
    assert face is None and props == {}
    obj = tmp_path / 'c.obj'
    obj.write_text('v 0 0 0\nv 1 0 0\nv 1 1 0\n')
    assert mf.read_surface(str(obj))[1] is None
    with pytest.raises(ValueError, match=r"c\.obj' holds a point cloud, not "
                       r"a triangle mesh"):
        mf.read_mesh(str(obj))


# --- the PLY writer ------------------------------------------------------


def test_write_ply_round_trips_positions_faces_and_properties(tmp_path):
    rng = np.random.default_rng(0)
    V, F = icosphere()
    V = V + 1e-3 * rng.standard_normal(V.shape)  # full float64 digits
    heat, feat = rng.random(len(V)), rng.standard_normal((len(V), 2))
    colors = rng.random((len(V), 3))
    colors[0] = [np.nan, -0.5, 1.5]  # clipped, NaN as 0
    path = tmp_path / 'out.ply'
    assert mf.write_ply(str(path), V, F, properties={'heat': heat,
                                                     'feat': feat},
                        colors=colors) == str(path)
    pos, face, props = mf.read_surface(str(path))
    assert np.array_equal(pos, V) and np.array_equal(face, F)
    assert sorted(props) == ['blue', 'feat_0', 'feat_1', 'green', 'heat',
                             'red']
    assert np.array_equal(props['heat'], heat)
    assert np.array_equal(np.stack([props['feat_0'], props['feat_1']], 1),
                          feat)
    rgb = np.stack([props[c] for c in ('red', 'green', 'blue')], 1)
    assert rgb.dtype == np.uint8
    assert rgb[0].tolist() == [0, 0, 255]
    assert np.array_equal(rgb[1:], np.round(colors[1:] * 255))
    # trimesh, MeshLab and friends read the same file
    loaded = trimesh.load(path, process=False)
    assert np.array_equal(loaded.vertices, V)
    assert np.array_equal(loaded.faces, F)


def test_write_ply_is_binary_little_endian_with_the_documented_layout(
        tmp_path):
    V, F = icosphere()
    path = tmp_path / 'out.ply'
    mf.write_ply(str(path), V, F, properties={'q': np.arange(len(V))},
                 colors=np.zeros((len(V), 3)))
    data = path.read_bytes()
    end = data.index(b'end_header\n') + len(b'end_header\n')
    header = data[:end].decode('ascii').splitlines()
    assert header == [
        'ply', 'format binary_little_endian 1.0',
        'comment written by tg_intrinsic', f'element vertex {len(V)}',
        'property double x', 'property double y', 'property double z',
        'property uchar red', 'property uchar green', 'property uchar blue',
        'property double q', f'element face {len(F)}',
        'property list uchar int vertex_indices', 'end_header']
    # 3 doubles, 3 bytes, 1 double per vertex; count byte + 3 int32 per face
    assert len(data) - end == len(V) * (24 + 3 + 8) + len(F) * (1 + 12)
    first = np.frombuffer(data[end:end + 24], dtype='<f8')
    assert np.array_equal(first, V[0])
    # points only: no face element
    mf.write_ply(str(path), V)
    assert b'element face' not in path.read_bytes()
    assert mf.read_surface(str(path))[1] is None
    assert [n for n in os.listdir(tmp_path) if n != 'out.ply'] == []


# --- errors that name the file and the problem ----------------------------


def test_missing_folder_and_unknown_format(tmp_path):
    with pytest.raises(FileNotFoundError, match=r"nope\.obj' does not "
                       r"exist"):
        mf.read_surface(str(tmp_path / 'nope.obj'))
    with pytest.raises(ValueError, match=r"is a folder; give a mesh or point "
                       r"cloud file \(\.obj/\.off/\.ply/\.stl\)"):
        mf.read_surface(str(tmp_path))
    for name, ext in (('scan.xyz', "'.xyz'"), ('mesh', "'(none)'")):
        (tmp_path / name).write_text('0 0 0\n')
        with pytest.raises(ValueError) as info:
            mf.read_surface(str(tmp_path / name))
        assert f'unknown format {ext}; use one of .obj/.off/.ply/.stl' in \
            str(info.value) and name in str(info.value)


OFF_TRIANGLE = 'OFF\n3 1 0\n0 0 0\n1 0 0\n0 1 0\n'


@pytest.mark.parametrize('text,problem', [
    ('', 'empty file'),
    ('# only a comment\n', 'empty file'),
    ('PLY\n3 1 0\n', "missing 'OFF' header (first line: 'PLY')"),
    ('OFF\n', 'the OFF header has no vertex and face counts'),
    ('OFF\nthree one\n', 'malformed OFF header'),
    ('OFF\n8 12 0\n0 0 0\n', 'announces 8 vertices and 12 faces but the '
                            'file has only 1 data lines'),
    ('OFF\n2 0 0\n0 0\n1 1\n', 'every vertex line needs 3 coordinates'),
    ('OFF\n3 1 0\n0 0 0\n1 0\n0 1 0\n3 0 1 2\n', 'malformed vertex line'),
    ('OFF\n3 1 0\n0 0 0\n1 x 0\n0 1 0\n3 0 1 2\n', 'malformed vertex line'),
    (OFF_TRIANGLE + '2 0 1\n', "malformed face line '2 0 1'"),
    (OFF_TRIANGLE + '3 0 1 x\n', 'malformed face line'),
    (OFF_TRIANGLE + '4 0 1 2\n', "malformed face line '4 0 1 2'"),
    (OFF_TRIANGLE + '3 0 1 3\n', 'face indices outside [0, 2] (the vertex '
                                 'count is 3)'),
    (OFF_TRIANGLE + '3 0 1 -1\n', 'face indices outside [0, 2]'),
    ('OFF\n3 1 0\n0 0 nan\n1 0 0\n0 1 0\n3 0 1 2\n',
     'NaN or infinite coordinates at 1 vertex(es)'),
    ('OFF\n3 1 0\ninf 0 0\n1 0 -inf\n0 1 0\n3 0 1 2\n',
     'NaN or infinite coordinates at 2 vertex(es)'),
])
def test_a_bad_off_file_is_named_with_its_problem(tmp_path, text, problem):
    path = tmp_path / 'bad.off'
    path.write_text(text)
    with pytest.raises(ValueError) as info:
        mf.read_surface(str(path))
    message = str(info.value)
    assert str(path) in message and problem in message, message


@pytest.mark.parametrize('name,content', [
    ('a.stl', b'not an stl file at all'),
    ('b.obj', b''),
    ('c.ply', b'ply\nformat ascii 1.0\nelement vertex 2\nproperty float x\n'
              b'end_header\n0\n1\n'),
    ('d.obj', b'v 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 9\n'),
])
def test_a_bad_file_of_another_format_is_named(tmp_path, name, content):
    (tmp_path / name).write_bytes(content)
    with pytest.raises(ValueError) as info:
        mf.read_surface(str(tmp_path / name))
    assert name in str(info.value)


# --- per-vertex signals ----------------------------------------------------


def test_signals_from_every_source(tmp_path):
    rng = np.random.default_rng(1)
    one, two = rng.random(4), rng.standard_normal((4, 2))
    np.save(tmp_path / 's.npy', two)
    np.savetxt(tmp_path / 's.txt', one)
    np.savetxt(tmp_path / 's.csv', two, delimiter=',')
    mf.write_ply(str(tmp_path / 'm.ply'), TET_V, TET_F,
                 properties={'heat': one})
    assert np.array_equal(mf.read_signal(str(tmp_path / 's.npy'), 4), two)
    assert np.allclose(mf.read_signal(str(tmp_path / 's.txt'), 4), one,
                       rtol=1e-15)
    assert np.allclose(mf.read_signal(str(tmp_path / 's.csv'), 4), two,
                       rtol=1e-15)
    assert np.array_equal(
        mf.read_signal(str(tmp_path / 'm.ply') + ':heat', 4), one)
    _, _, props = mf.read_surface(str(tmp_path / 'm.ply'))
    signal = mf.read_signal('heat', 4, props)
    assert signal.dtype == np.float64 and np.array_equal(signal, one)
    np.save(tmp_path / 'i.npy', np.arange(4, dtype=np.int32))
    assert mf.read_signal(str(tmp_path / 'i.npy'), 4).dtype == np.float64


def test_bad_signals_say_what_is_wrong(tmp_path):
    mf.write_ply(str(tmp_path / 'm.ply'), TET_V, TET_F,
                 properties={'heat': np.zeros(4)})
    np.save(tmp_path / 'five.npy', np.zeros(5))
    np.save(tmp_path / 'cube.npy', np.zeros((4, 2, 2)))
    np.save(tmp_path / 'words.npy', np.array(['a', 'b', 'c', 'd']))
    np.save(tmp_path / 'nan.npy', np.array([0, 1, np.nan, 2]))
    (tmp_path / 'bad.txt').write_text('1\n2\nthree\n4\n')
    cases = [
        (str(tmp_path / 'five.npy'), r"has 5 rows but the surface has "
                                     r"4 vertices; give one row per vertex"),
        (str(tmp_path / 'cube.npy'), r"has 3 dimensions \(4, 2, 2\); give "
                                     r"one value, or one row of values, per "
                                     r"vertex: shape \(4,\) or \(4, C\)"),
        (str(tmp_path / 'words.npy'), r"is not numeric \(<U1\)"),
        (str(tmp_path / 'nan.npy'), 'holds NaN or infinite values'),
        (str(tmp_path / 'bad.txt'), r"could not read the signal '.*bad\.txt'"),
        (str(tmp_path / 'm.ply') + ':cold',
         r"m\.ply' has no vertex property 'cold'; it has \['heat'\]"),
        ('cold', r"signal 'cold' is neither a \.npy/\.txt/\.csv file, "
                 r"FILE\.ply:PROPERTY, nor a vertex property of the input "
                 r"\(it has none\)"),
    ]
    for source, match in cases:
        with pytest.raises(ValueError, match=match):
            mf.read_signal(source, 4)
    with pytest.raises(FileNotFoundError, match=r"signal file '.*gone\.npy' "
                       r"does not exist"):
        mf.read_signal(str(tmp_path / 'gone.npy'), 4)


def test_ascii_and_binary_ply_give_the_same_properties(tmp_path):
    V, F = icosphere()
    quality = np.arange(len(V), dtype=np.float64)
    mesh = trimesh.Trimesh(V, F, process=False,
                           vertex_attributes={'quality': quality})
    for encoding in ('ascii', 'binary'):
        path = tmp_path / f'{encoding}.ply'
        path.write_bytes(trimesh.exchange.ply.export_ply(
            mesh, encoding=encoding))
        pos, face, props = mf.read_surface(str(path))
        assert np.array_equal(face, F) and np.abs(pos - V).max() < 1e-6
        assert props['quality'].shape == (len(V),)
        assert np.array_equal(props['quality'], quality)


def test_welding_keeps_the_first_copy_and_gives_the_inverse(tmp_path):
    V, F = icosphere()
    soup = V[F].reshape(-1, 3)
    path = tmp_path / 'soup.ply'
    mf.write_ply(str(path), soup, np.arange(len(soup)).reshape(-1, 3),
                 properties={'corner': np.arange(len(soup))})
    with pytest.warns(UserWarning, match=r"welded 198 vertices .*240 -> 42"):
        pos, face, props, inverse = mf.read_surface(str(path),
                                                    return_inverse=True)
    assert len(pos) == 42 and np.array_equal(pos[inverse], soup)
    assert np.array_equal(pos[face], soup.reshape(-1, 3, 3))
    # each welded vertex keeps the property of its first copy
    first = [int(np.flatnonzero(inverse == k)[0]) for k in range(len(pos))]
    assert np.array_equal(props['corner'], first)
    # two corners of a triangle at one position: named, not welded away
    soup[1] = soup[0]
    mf.write_ply(str(path), soup, np.arange(len(soup)).reshape(-1, 3))
    with pytest.raises(ValueError, match=r"soup.ply' has 1 triangle\(s\) "
                                         r"with two corners at the same"):
        mf.read_surface(str(path))
    # a point cloud is kept as it is
    mf.write_ply(str(path), np.concatenate([V, V]))
    assert len(mf.read_surface(str(path))[0]) == 2 * len(V)


def test_a_signal_that_is_not_npy_is_named(tmp_path):
    (tmp_path / 'signal.npy').write_bytes(b'\x00garbage' * 20)
    with pytest.raises(ValueError, match=r"signal.npy': it is not a NumPy "
                                         r".npy file") as error:
        mf.read_signal(str(tmp_path / 'signal.npy'), 4)
    assert 'pickle' not in str(error.value)


# --- UTF-8 byte-order marks (issue 40) --------------------------------------


def _text_files():
    """The icosphere as the text formats store it: ``{ext: text}``, the
    OBJ beginning with a vertex line (no comment before it)."""
    V, F = icosphere()
    mesh = trimesh.Trimesh(V, F, process=False)
    obj = ''.join(f'v {x!r} {y!r} {z!r}\n' for x, y, z in V.tolist()) + \
        ''.join(f'f {a + 1} {b + 1} {c + 1}\n' for a, b, c in F.tolist())
    return {
        'obj': obj,
        'off': trimesh.exchange.off.export_off(mesh),
        'ply': trimesh.exchange.ply.export_ply(
            mesh, encoding='ascii').decode('ascii'),
        'stl': trimesh.exchange.stl.export_stl_ascii(mesh),
    }


@pytest.mark.parametrize('ext', ['obj', 'off', 'ply', 'stl'])
def test_a_utf8_byte_order_mark_is_ignored(tmp_path, ext):
    # Notepad saves UTF-8 with a BOM: '\ufeffv 0 0 0' lost the first
    # vertex of an OBJ file (IndexError: index 161 is out of bounds)
    text = _text_files()[ext]
    plain, marked = tmp_path / f'plain.{ext}', tmp_path / f'marked.{ext}'
    plain.write_text(text, encoding='utf-8')
    marked.write_text(text, encoding='utf-8-sig')
    assert marked.read_bytes()[:3] == b'\xef\xbb\xbf'
    with warnings.catch_warnings():
        warnings.simplefilter('ignore')  # the STL soup is welded
        want = mf.read_surface(str(plain), return_inverse=True)
        got = mf.read_surface(str(marked), return_inverse=True)
    assert np.array_equal(got[0], want[0]) and np.array_equal(got[1],
                                                              want[1])
    assert got[2].keys() == want[2].keys()
    assert np.array_equal(got[3], want[3])
    assert len(got[0]) == 42 and got[1].shape == (80, 3)


def test_a_byte_order_mark_is_ignored_in_face_line_messages(tmp_path):
    # the line named for a bad face counts the first line as line 1
    path = tmp_path / 'a.obj'
    path.write_text(REPEATED_VERTEX[0][1], encoding='utf-8-sig')
    with pytest.raises(ValueError, match=REPEATED_VERTEX[0][2]):
        mf.read_mesh(str(path))


def test_texture_coordinates_of_an_obj_with_a_byte_order_mark(tmp_path):
    V, F = icosphere()
    uv = (V[:, :2] + 1) / 2
    text = ''.join(f'v {x!r} {y!r} {z!r}\n' for x, y, z in V.tolist()) + \
        ''.join(f'vt {u!r} {v!r}\n' for u, v in uv.tolist()) + \
        ''.join(f'f {a}/{a} {b}/{b} {c}/{c}\n'
                for a, b, c in (F + 1).tolist())
    (tmp_path / 'plain.obj').write_text(text, encoding='utf-8')
    (tmp_path / 'marked.obj').write_text(text, encoding='utf-8-sig')
    got = []
    for name in ('plain.obj', 'marked.obj'):
        pos, face, _ = mf.read_surface(str(tmp_path / name))
        got.append(mf.read_face_uv(str(tmp_path / name), pos, face))
    assert got[0] is not None and np.array_equal(got[0], got[1])
    assert np.allclose(got[1], uv[F].transpose(1, 0, 2))


def test_a_binary_stl_header_is_not_taken_for_a_byte_order_mark(tmp_path):
    V, F = icosphere()
    data = bytearray(trimesh.exchange.stl.export_stl(
        trimesh.Trimesh(V, F, process=False)))
    data[:3] = b'\xef\xbb\xbf'  # the 80-byte header may hold anything
    (tmp_path / 'b.stl').write_bytes(bytes(data))
    with pytest.warns(UserWarning, match='welded 198 vertices'):
        pos, face = mf.read_mesh(str(tmp_path / 'b.stl'))
    assert len(pos) == 42 and face.shape == (80, 3)


def test_signals_in_text_files_with_a_byte_order_mark(tmp_path):
    one = np.arange(4.0)
    (tmp_path / 's.txt').write_text('\n'.join(map(str, one)) + '\n',
                                    encoding='utf-8-sig')
    (tmp_path / 's.csv').write_text('0,1\n2,3\n4,5\n6,7\n',
                                    encoding='utf-8-sig')
    assert np.array_equal(mf.read_signal(str(tmp_path / 's.txt'), 4), one)
    assert np.array_equal(mf.read_signal(str(tmp_path / 's.csv'), 4),
                          np.arange(8.0).reshape(4, 2))


# --- OBJ files: the vertices as stored (issue 40) ---------------------------


def _two_spheres_obj(normals=True):
    """Two disjoint icospheres in one OBJ file, as exporters write them:
    an object each (``o``), a material each (``usemtl``), with vertex
    normals; 2 x 42 vertices, 2 x 80 triangles."""
    V, F = icosphere()
    lines, base = [], 0
    for name, shift in (('first', 0.0), ('second', 5.0)):
        lines += [f'o {name}']
        lines += [f'v {x + shift!r} {y!r} {z!r}' for x, y, z in V.tolist()]
        if normals:
            lines += [f'vn {x!r} {y!r} {z!r}' for x, y, z in V.tolist()]
        lines += [f'usemtl material_{name}', 's 1']
        lines += [' '.join(['f'] + [f'{i}//{i}' if normals else f'{i}'
                                    for i in (face + base + 1).tolist()])
                  for face in F]
        base += len(V)
    both = np.concatenate([V, V + [5.0, 0, 0]])
    return '\n'.join(lines) + '\n', both, np.concatenate([F, F + len(V)])


@pytest.mark.parametrize('normals', [True, False])
def test_a_two_object_obj_is_not_welded(tmp_path, normals):
    # trimesh gave every object all the file's vertices (848 -> 84): the
    # false warning "welded N vertices" for a file without duplicates
    text, V, F = _two_spheres_obj(normals)
    path = tmp_path / 'two.obj'
    path.write_text(text)
    with warnings.catch_warnings():
        warnings.simplefilter('error')  # no warning at all
        pos, face, _, inverse = mf.read_surface(str(path),
                                                return_inverse=True)
    assert np.array_equal(pos, V) and np.array_equal(face, F)
    assert np.array_equal(inverse, np.arange(len(V)))


@pytest.mark.parametrize('objects', [False, True])
def test_the_weld_warning_counts_the_merged_vertices(tmp_path, objects):
    # an icosphere stored in two halves, each with its own copies of the
    # vertices on the seam (as one object, or as two with a material
    # each, as exporters split a mesh into parts): the seam's vertices
    # are merged, and only they are counted
    V, F = icosphere()
    lines, base, stored = [], 0, []
    for k, half in enumerate((F[:40], F[40:])):
        used = np.unique(half)
        index = np.full(len(V), -1)
        index[used] = np.arange(len(used)) + base
        if objects:
            lines += [f'o part{k}', f'usemtl material{k}']
        lines += [f'v {x!r} {y!r} {z!r}' for x, y, z in V[used].tolist()]
        lines += [f'f {a} {b} {c}' for a, b, c in (index[half] + 1).tolist()]
        base += len(used)
        stored.append(used)
    seam = len(np.intersect1d(*stored))
    assert 0 < seam < len(V) and base == len(V) + seam
    path = tmp_path / 'halves.obj'
    path.write_text('\n'.join(lines) + '\n')
    with pytest.warns(UserWarning) as record:
        pos, face, _, inverse = mf.read_surface(str(path),
                                                return_inverse=True)
    messages = [str(w.message) for w in record]
    assert messages == [
        f"'{path}': welded {seam} vertices at the same position as another "
        f"({len(V) + seam} -> {len(V)}), which connects its triangles into "
        f"one surface"]
    assert len(pos) == len(V) and np.array_equal(pos[face], V[F])
    assert np.array_equal(pos[inverse], V[np.concatenate(stored)])


def test_obj_faces_every_way_they_are_written(tmp_path):
    square = 'v 0 0 0\nv 1 0 0\nv 1 1 0\nv 0 1 0\nv 2 0 0 1 0 0\n'
    cases = [
        # a quad and a triangle: fans
        (square + 'f 1 2 3 4\nf 2 5 3\n', [[0, 1, 2], [0, 2, 3], [1, 4, 2]]),
        # texture and normal indices, tabs, comments, indentation
        (square + 'vt 0 0\nvn 0 0 1\nf 1/1/1 2/1/1 3//1 # one\n'
         '  f\t3/1\t4/1\t1/1\n', [[0, 1, 2], [2, 3, 0]]),
        # negative indices count back from the last vertex defined
        ('v 0 0 0\nv 1 0 0\nv 1 1 0\nf -3 -2 -1\nv 0 1 0\nf -4 -2 -1\n',
         [[0, 1, 2], [0, 2, 3]]),
        # a line continued with a backslash, Windows line ends
        ('v 0 0 0\r\nv 1 0 \\\r\n 0\r\nv 1 1 0\r\nf 1 \\\r\n2 3\r\n',
         [[0, 1, 2]]),
    ]
    for k, (text, faces) in enumerate(cases):
        path = tmp_path / f'{k}.obj'
        path.write_text(text, newline='')
        assert mf.read_obj(str(path))[1].tolist() == faces, text
    pos, _ = mf.read_obj(str(tmp_path / '0.obj'))
    assert pos[4].tolist() == [2, 0, 0]  # colours after x y z ignored


@pytest.mark.parametrize('text,problem', [
    ('v 0 0 0\nv 1 0\nv 0 1 0\n', "malformed vertex line 2: 'v 1 0'"),
    ('v 0 0 0\nv 1 x 0\nv 0 1 0\n', "malformed vertex line 2: 'v 1 x 0'"),
    ('v 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 3\nf 1 2\n',
     "malformed face line 5: 'f 1 2'"),
    ('v 0 0 0\nv 1 0 0\nv 0 1 0\n# c\nf 0 1 2\n',
     "malformed face line 5: 'f 0 1 2'"),
    ('v 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 3.5\n',
     "malformed face line 4: 'f 1 2 3.5'"),
])
def test_a_malformed_obj_line_is_named(tmp_path, text, problem):
    path = tmp_path / 'bad.obj'
    path.write_text(text)
    with pytest.raises(ValueError) as info:
        mf.read_surface(str(path))
    assert "bad.obj'" in str(info.value) and problem in str(info.value)


# --- files that cannot be read (issue 40) -----------------------------------


def test_what_is_wrong_with_a_path_is_said_on_one_line(tmp_path):
    (tmp_path / 'm.obj').write_text(TET_OBJ + 'f 1 2 3\n')
    (tmp_path / 'folder.obj').mkdir()
    os.symlink(tmp_path / 'gone.obj', tmp_path / 'link.obj')
    cases = [
        (tmp_path / 'folder.obj', ValueError, r"folder\.obj' is a folder; "
         r"give a mesh or point cloud file \(\.obj/\.off/\.ply/\.stl\)$"),
        (tmp_path / 'link.obj', FileNotFoundError, r"link\.obj' does not "
         r"exist \(it is a link to '.*gone\.obj', which does not exist\)$"),
        (tmp_path / 'm.obj' / 'x.obj', FileNotFoundError, r"x\.obj' does "
         r"not exist \('.*m\.obj' is a file, not a folder\)$"),
    ]
    for path, kind, match in cases:
        with pytest.raises(kind, match=match):
            mf.read_surface(str(path))


def _unreadable():
    """Whether /proc/self/mem opens but fails to read at offset 0 (EIO),
    as on Linux."""
    try:
        with open('/proc/self/mem', 'rb') as f:
            f.read(1)
    except OSError as error:
        return error.errno == errno.EIO
    return False


@pytest.mark.skipif(not _unreadable(), reason='needs /proc/self/mem that '
                    'fails to read (Linux)')
def test_a_file_that_fails_to_read_is_named_without_an_errno(tmp_path):
    # /proc/self/mem opens but fails to read at offset 0 (EIO): the bare
    # "[Errno 5] Input/output error" was the message
    for ext in ('obj', 'off', 'ply', 'stl'):
        os.symlink('/proc/self/mem', tmp_path / f'mem.{ext}')
        with pytest.raises(ValueError) as info:
            mf.read_surface(str(tmp_path / f'mem.{ext}'))
        assert str(info.value) == \
            f"'{tmp_path / f'mem.{ext}'}' cannot be read: input/output error"
    for ext in ('npy', 'txt'):
        os.symlink('/proc/self/mem', tmp_path / f's.{ext}')
        with pytest.raises(ValueError, match=r"^signal file '.*s\.(npy|txt)'"
                           r" cannot be read: input/output error$"):
            mf.read_signal(str(tmp_path / f's.{ext}'), 4)


def test_a_file_that_may_not_be_read_is_named(tmp_path, monkeypatch):
    # (root reads every file, so the refusal is simulated)
    path = tmp_path / 'm.obj'
    path.write_text(TET_OBJ + 'f 1 2 3\n')

    def refuse(*args, **kwargs):
        raise PermissionError(13, 'Permission denied', str(path))

    monkeypatch.setattr(mf, 'open', refuse, raising=False)
    with pytest.raises(PermissionError, match=r"^'.*m\.obj' cannot be read: "
                                              r"permission denied$"):
        mf.read_surface(str(path))


def test_a_signal_folder_is_said_to_be_a_folder(tmp_path):
    (tmp_path / 'values').mkdir()
    (tmp_path / 'values.npy').mkdir()
    with pytest.raises(ValueError, match=r"signal '.*values' is a folder; "
                       r"give a \.npy/\.txt/\.csv file with one row per "
                       r"vertex, or FILE\.ply:NAME$"):
        mf.read_signal(str(tmp_path / 'values'), 4)
    with pytest.raises(ValueError, match=r"signal file '.*values\.npy' is a "
                                         r"folder; give"):
        mf.read_signal(str(tmp_path / 'values.npy'), 4)
    # a vertex property of that name is still the property
    assert mf.read_signal(str(tmp_path / 'values'), 4, {
        str(tmp_path / 'values'): np.ones(4)}).tolist() == [1, 1, 1, 1]


# --- zero-area triangles (issue 40) -----------------------------------------


def test_zero_area_triangles_are_named_with_their_line(tmp_path):
    flat = TET_V.copy()
    flat[3] = [0.5, 0.5, 0]  # on the line between vertices 1 and 2
    path = tmp_path / 'flat.obj'
    path.write_text(''.join(f'v {x} {y} {z}\n' for x, y, z in flat)
                    + ''.join(f'f {a} {b} {c}\n' for a, b, c in TET_F + 1))
    pos, face = mf.read_mesh(str(path))  # read: the policy allows them
    with pytest.raises(ValueError, match=r"flat\.obj' has 1 zero-area "
                       r"triangle\(s\) \(collinear corners; first: triangle "
                       r"2, vertices \[1, 2, 3\] counted from 0, from line 7:"
                       r" 'f 2 3 4'\), which the cotan Laplacian cannot "
                       r"weigh; delete these faces"):
        mf.check_triangle_areas(str(path), pos, face)
    with pytest.raises(ValueError, match=r"weigh; do this$"):
        mf.check_triangle_areas(str(path), pos, face, advice='do this')
    mf.check_triangle_areas(str(path), TET_V, TET_F)  # none: no error


# --- PLY properties in their own types (issue 40) --------------------------


def test_write_ply_keeps_the_types_of_typed_properties(tmp_path):
    V, F = icosphere()
    n = len(V)
    rng = np.random.default_rng(2)
    typed = {'red': rng.integers(0, 256, n).astype(np.uint8),
             'nx': rng.standard_normal(n).astype(np.float32),
             'flag': rng.random(n) > 0.5,
             'id': np.arange(n, dtype=np.int64),
             'big': np.full(n, 2 ** 40, dtype=np.int64),
             'pair': rng.integers(-5, 5, (n, 2)).astype(np.int16)}
    path = tmp_path / 't.ply'
    mf.write_ply(str(path), V, F, properties={'heat': rng.random(n)},
                 typed_properties=typed)
    header = path.read_bytes().split(b'end_header')[0].decode().splitlines()
    assert [h for h in header if h.startswith('property ')][3:] == [
        'property uchar red', 'property float nx', 'property uchar flag',
        'property int id', 'property double big', 'property short pair_0',
        'property short pair_1', 'property double heat',
        'property list uchar int vertex_indices']
    _, _, props = mf.read_surface(str(path))
    for name in ('red', 'nx', 'id', 'big'):
        assert np.array_equal(props[name], typed[name]), name
    assert np.array_equal(props['flag'], typed['flag'])
    assert np.array_equal(np.stack([props['pair_0'], props['pair_1']], 1),
                          typed['pair'])
    assert props['red'].dtype == np.uint8 and props['nx'].dtype == np.float32
    with pytest.raises(ValueError, match="two vertex properties named "
                                         "'red'"):
        mf.write_ply(str(path), V, F, colors=np.zeros((n, 3)),
                     typed_properties={'red': typed['red']})


def test_obj_normals_are_read_when_each_vertex_has_one(tmp_path):
    from tg_intrinsic.io import read_surface
    smooth = tmp_path / 'smooth.obj'
    smooth.write_text('v 0 0 0\nv 1 0 0\nv 0 1 0\nv 0 0 1\n'
                      'vn 0 0 1\nvn 0 1 0\nvn 1 0 0\nvn 0.6 0.8 0\n'
                      'f 1//1 2//2 3//3\nf 1/1/1 3/1/3 4/1/4\n'
                      'vt 0 0\n')
    pos, face, properties = read_surface(str(smooth))
    normal = np.stack([properties[k] for k in ('nx', 'ny', 'nz')], 1)
    assert np.array_equal(normal, [[0, 0, 1], [0, 1, 0], [1, 0, 0],
                                   [0.6, 0.8, 0]])
    # flat shading: vertex 1 has two normals; a corner without one
    for faces in ('f 1//1 2//2 3//3\nf 1//2 3//3 4//4\n',
                  'f 1//1 2//2 3//3\nf 1 3 4\n'):
        flat = tmp_path / 'flat.obj'
        flat.write_text('v 0 0 0\nv 1 0 0\nv 0 1 0\nv 0 0 1\n'
                        'vn 0 0 1\nvn 0 1 0\nvn 1 0 0\nvn 0.6 0.8 0\n'
                        + faces)
        assert read_surface(str(flat))[2] == {}
