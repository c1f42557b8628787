"""Meshes on disk: the OFF parser (ModelNet's malformed headers, COFF,
polygons), the trimesh-backed OBJ/PLY/STL reader, the binary PLY writer,
per-vertex signals, and the errors that name the file and the problem."""
import numpy as np
import pytest

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
