import numpy as np
import pytest
import trimesh

from tg_intrinsic.io.labels import (check_labels, edge_label_scores,
                                    face_label_scores, label_kind,
                                    label_scores, meshcnn_edges, read_labels,
                                    read_soft_labels, scores_to_labels,
                                    to_int_labels)


def sphere():
    m = trimesh.creation.icosphere(subdivisions=1)
    return np.asarray(m.vertices), np.asarray(m.faces)


def meshcnn_reference(pos, face):
    """MeshCNN's face filter and edge numbering, face by face."""
    kept, seen = [], set()
    for f in face:
        a, b, c = pos[f]
        if np.linalg.norm(np.cross(b - a, c - b)) == 0:
            continue
        directed = [(f[i], f[(i + 1) % 3]) for i in range(3)]
        if any(d in seen for d in directed):
            continue
        seen.update(directed)
        kept.append(f)
    edges, index = [], {}
    for f in kept:
        for i in range(3):
            e = tuple(sorted((int(f[i]), int(f[(i + 1) % 3]))))
            if e not in index:
                index[e] = len(edges)
                edges.append(e)
    return np.array(edges, dtype=np.int64).reshape(-1, 2)


def brute_votes(num_vertices, items, labels, weights, num_classes):
    """Per vertex: total weight per class over the items holding it."""
    scores = np.zeros((num_vertices, num_classes))
    for item, label, w in zip(items, labels, weights):
        for v in set(int(i) for i in item):
            if np.ndim(label) == 0:
                scores[v, label] += w
            else:
                scores[v] += w * np.asarray(label)
    out = np.full(num_vertices, -1)
    for v in range(num_vertices):
        if scores[v].max() > 0:
            best = scores[v].max()
            out[v] = min(c for c in range(num_classes)
                         if scores[v, c] >= best * (1 - 1e-9))
    return out


def test_read_labels_formats(tmp_path):
    (tmp_path / 'a.txt').write_text('0\n3\n2\n\n1\n')
    (tmp_path / 'b.seg').write_text('2.000000\n1.000000\n')  # float ints
    np.save(tmp_path / 'c.npy', np.array([4, 0, 1], dtype=np.int32))
    (tmp_path / 'd.eseg').write_text('1\n2\n')
    assert read_labels(tmp_path / 'a.txt').tolist() == [0, 3, 2, 1]
    assert read_labels(tmp_path / 'b.seg').tolist() == [2, 1]
    assert read_labels(tmp_path / 'c.npy').tolist() == [4, 0, 1]
    assert read_labels(tmp_path / 'd.eseg').dtype == np.int64


@pytest.mark.parametrize('text,match', [
    ('1\n2.5\n', r'non-integer label 2\.5 \(row 2\)'),
    ('1\nabc\n', 'could not read'),
    ('1 2\n3 4\n', 'values per line'),
    ('', 'no table'),
    ('1\nnan\n', 'NaN'),
])
def test_read_labels_errors_name_the_file(tmp_path, text, match):
    path = tmp_path / 'bad_labels.txt'
    path.write_text(text)
    with pytest.raises(ValueError, match=match) as info:
        read_labels(path)
    assert 'bad_labels.txt' in str(info.value)


def test_read_labels_missing():
    with pytest.raises(FileNotFoundError, match='nope.txt'):
        read_labels('nope.txt')


def test_soft_labels(tmp_path):
    path = tmp_path / 'x.seseg'
    path.write_text('1.000000 0.000000 0.000000\n0.500000 0.500000 0\n')
    assert np.array_equal(read_soft_labels(path), [[1, 0, 0], [.5, .5, 0]])
    path.write_text('1 -0.5\n')
    with pytest.raises(ValueError, match=r"x\.seseg' holds negative"):
        read_soft_labels(path)


def test_check_labels():
    assert check_labels(np.array([1, 2, 3]), 'f.eseg', offset=1).tolist() \
        == [0, 1, 2]
    with pytest.raises(ValueError, match=r"'f\.eseg' holds the label 0 "
                       r"\(row 2\).*negative.*label_offset=1"):
        check_labels(np.array([1, 0]), 'f.eseg', offset=1)
    with pytest.raises(ValueError, match=r"label 5 \(row 3\).*num_classes=4"):
        check_labels(np.array([0, 1, 5]), 'f.txt', num_classes=4)
    with pytest.raises(ValueError, match='non-integer'):
        to_int_labels([1.0, 1.5], 'f.txt')


def test_meshcnn_edges_closed_mesh():
    pos, face = sphere()
    rng = np.random.default_rng(0)
    face = face[rng.permutation(len(face))]
    edges = meshcnn_edges(pos, face)
    assert np.array_equal(edges, meshcnn_reference(pos, face))
    # independent count: a closed triangle mesh has 3F/2 edges, trimesh's
    assert len(edges) == 3 * len(face) // 2
    ref = trimesh.Trimesh(pos, face, process=False).edges_unique
    assert {tuple(e) for e in edges} == {tuple(sorted(e)) for e in ref}
    # first edge: the first face's (v0, v1), sorted
    assert edges[0].tolist() == sorted(face[0, :2].tolist())


def test_meshcnn_edges_drops_faces_like_meshcnn():
    pos, face = sphere()
    pos = np.vstack([pos, pos[:1]])  # a duplicate of vertex 0
    extra = np.array([
        face[3],                          # repeats every directed edge
        face[5][::-1],                    # flipped: opposite directions
        [0, 1, len(pos) - 1],             # zero area (vertex 0 twice)
        [face[7][0], face[7][1], 2],      # repeats one directed edge
    ])
    face = np.vstack([face[:10], extra, face[10:]])
    edges = meshcnn_edges(pos, face)
    assert np.array_equal(edges, meshcnn_reference(pos, face))


def test_label_kind():
    pos, face = sphere()  # 42 vertices, 80 faces, 120 edges
    assert label_kind('l', 42, pos, face) == ('vertex', None)
    assert label_kind('l', 80, pos, face) == ('face', None)
    kind, edges = label_kind('l', 120, pos, face)
    assert kind == 'edge' and np.array_equal(edges, meshcnn_edges(pos, face))
    with pytest.raises(ValueError, match=r"'l' holds 7 labels, but 'm' has "
                       r"42 vertices, 80 faces and 120 edges"):
        label_kind('l', 7, pos, face, mesh_path="'m'")
    with pytest.raises(ValueError, match=r"holds 42 labels, but per-face "
                       r"labels of 'm' need 80"):
        label_kind('l', 42, pos, face, 'face', mesh_path="'m'")
    # as many vertices as faces: auto reads per vertex, kind decides
    tri = np.array([[0, 1, 2], [0, 2, 3], [0, 3, 1], [1, 3, 2]])
    quad = np.array([[0., 0, 0], [1, 0, 0], [0, 1, 0], [0, 0, 1]])
    assert label_kind('l', 4, quad, tri)[0] == 'vertex'
    assert label_kind('l', 4, quad, tri, 'face')[0] == 'face'
    with pytest.raises(ValueError, match='label_kind'):
        label_kind('l', 4, quad, tri, 'corner')


def grid(n=4):
    """A plane of equal right triangles (many exact ties)."""
    xs, ys = np.meshgrid(np.arange(n + 1.0), np.arange(n + 1.0))
    pos = np.stack([xs.ravel(), ys.ravel(), np.zeros(xs.size)], 1)
    v = np.arange((n + 1) ** 2).reshape(n + 1, n + 1)
    a, b = v[:-1, :-1].ravel(), v[:-1, 1:].ravel()
    c, d = v[1:, :-1].ravel(), v[1:, 1:].ravel()
    face = np.concatenate([np.stack([a, b, d], 1), np.stack([a, d, c], 1)])
    return pos, face


@pytest.mark.parametrize('mesh', ['grid', 'sphere'])
def test_face_to_vertex_against_brute_force(mesh):
    pos, face = grid() if mesh == 'grid' else sphere()
    rng = np.random.default_rng(1)
    if mesh == 'sphere':
        pos = pos * rng.uniform(0.8, 1.2, size=(len(pos), 1))
    labels = rng.integers(0, 3, len(face))
    a = pos[face]
    area = 0.5 * np.linalg.norm(np.cross(a[:, 1] - a[:, 0],
                                         a[:, 2] - a[:, 0]), axis=1)
    y = scores_to_labels(face_label_scores(pos, face, labels))
    assert np.array_equal(y, brute_votes(len(pos), face, labels, area, 3))
    assert (y >= 0).all()


@pytest.mark.parametrize('soft', [False, True])
def test_edge_to_vertex_against_brute_force(soft):
    pos, face = grid()
    rng = np.random.default_rng(2)
    edges = meshcnn_edges(pos, face)
    labels = rng.random((len(edges), 4)) * (rng.random((len(edges), 4)) > .5)\
        if soft else rng.integers(0, 4, len(edges))
    length = np.linalg.norm(pos[edges[:, 0]] - pos[edges[:, 1]], axis=1)
    y = scores_to_labels(edge_label_scores(pos, edges, labels))
    assert np.array_equal(y, brute_votes(len(pos), edges, labels, length, 4))


def test_unit_votes_and_no_votes():
    # three old vertices merged into target 0, one into target 1, none in 2
    scores = label_scores([0, 0, 0, 1], [2, 1, 1, 3], 3)
    assert scores.shape == (3, 4)
    assert scores_to_labels(scores).tolist() == [1, 3, -1]
    # a tie goes to the smaller label
    assert scores_to_labels(label_scores([0, 0], [2, 1], 1)).tolist() == [1]


def test_label_files_with_a_utf8_byte_order_mark(tmp_path):
    # Notepad saves UTF-8 with a BOM (issue 40)
    (tmp_path / 'a.seg').write_text('2\n0\n1\n', encoding='utf-8-sig')
    (tmp_path / 'a.seseg').write_text('0.5 0.5\n1 0\n',
                                      encoding='utf-8-sig')
    assert read_labels(str(tmp_path / 'a.seg')).tolist() == [2, 0, 1]
    assert read_soft_labels(str(tmp_path / 'a.seseg')).tolist() == [
        [0.5, 0.5], [1, 0]]
