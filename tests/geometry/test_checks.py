"""The shared validation layer, one check at a time: what each accepts and
returns, and the message of every refusal (names the argument, says what is
wrong). The entry points' own messages are tested with them and in
test_bad_input.py / test_property_based.py."""
import math

import numpy as np
import pytest
import torch

from tg_intrinsic.geometry import checks as C

D64 = torch.float64
POS = torch.zeros(4, 3, dtype=D64)


def rotation_z(angle):
    c, s = math.cos(angle), math.sin(angle)
    return torch.tensor([[c, -s, 0], [s, c, 0], [0, 0, 1]], dtype=D64)


def camera_pair():
    K = torch.tensor([[50.0, 0, 16], [0, 50, 12], [0, 0, 1]], dtype=D64)
    E = torch.cat([rotation_z(0.3), torch.tensor([[0.0], [0], [3]],
                                                 dtype=D64)], 1)
    return K, E


def test_points_and_vectors():
    assert C.check_points(POS) is POS
    assert C.check_points(torch.zeros(5, 2), dim=2).shape == (5, 2)
    assert C.check_vectors(torch.ones(4, 3, dtype=D64), 'normal', 4,
                           POS).shape == (4, 3)
    nan = POS.clone()
    nan[2, 1] = float('nan')
    for value, match in [
            (np.zeros((4, 3)), r"'pos' must be a torch.Tensor.*as_tensor"),
            (torch.zeros(4, 2), r"'pos' must have shape \[N, 3\]"),
            (torch.zeros(4, 3, dtype=torch.float16), 'float32 or float64'),
            (torch.zeros(4, 3, dtype=torch.long), r'pos.float\(\)'),
            (nan, r'NaN or infinite values at 1 row\(s\) \(first: \[2\]\)')]:
        with pytest.raises(ValueError, match=match):
            C.check_points(value)
    with pytest.raises(ValueError, match='2 points but at least 3'):
        C.check_points(POS[:2], min_points=3)
    with pytest.raises(ValueError, match="'normal' has 3 rows but there "
                                         "are 4 points"):
        C.check_vectors(POS[:3], 'normal', 4, POS)


def test_batch():
    assert C.check_batch(None, 4, POS) is None
    batch = torch.tensor([0, 0, 2, 2])
    assert C.check_batch(batch, 4, POS) is batch
    # examples in between may be empty
    assert C.batch_sizes(batch, 4).tolist() == [2, 0, 2]
    assert C.batch_sizes(None, 4).tolist() == [4]
    for value, match in [(torch.tensor([0, 0, 1]), r'shape \[4\]'),
                         (torch.tensor([0., 0, 1, 1]), 'torch.long'),
                         (torch.tensor([-1, 0, 0, 0]), 'negative'),
                         (torch.tensor([1, 0, 0, 0]), 'sorted')]:
        with pytest.raises(ValueError, match=match):
            C.check_batch(value, 4, POS)


@pytest.mark.parametrize('value,minimum,expected', [
    (3, 1, 3), (np.int64(3), 1, 3), (torch.tensor(3), 1, 3), (0, 0, 0)])
def test_positive_int_accepts(value, minimum, expected):
    out = C.check_positive_int(value, 'k', minimum)
    assert out == expected and type(out) is int


@pytest.mark.parametrize('value,match', [
    (True, 'must be an integer'), (2.0, 'must be an integer'),
    ('3', 'must be an integer'), (torch.tensor(2.0), 'must be an integer'),
    (torch.tensor([1, 2]), 'must be an integer'), (0, 'must be at least 1')])
def test_positive_int_refuses(value, match):
    with pytest.raises(ValueError, match=f"'k' {match}"):
        C.check_positive_int(value, 'k')


def test_channels_choice_and_floats():
    assert C.check_channels([8, np.int32(16)], 'widths') == (8, 16)
    with pytest.raises(ValueError, match='sequence of channel counts'):
        C.check_channels('64', 'widths')
    with pytest.raises(ValueError, match='exactly 3 channel'):
        C.check_channels([8, 16], 'widths', length=3)
    with pytest.raises(ValueError, match=r"'widths\[1\]' must be at least"):
        C.check_channels([8, 0], 'widths')
    assert C.check_choice('mean', 'reduce', ('mean', 'sum')) == 'mean'
    with pytest.raises(ValueError, match=r"one of \('mean', 'sum'\)"):
        C.check_choice('max', 'reduce', ('mean', 'sum'))
    assert C.check_positive_float(np.float32(0.5), 'eps') == 0.5
    assert C.check_positive_float(0, 'eps', allow_zero=True) == 0.0
    for value, match in [('a', 'a number'), (None, 'a number'),
                         (float('nan'), 'finite'), (math.inf, 'finite'),
                         (0.0, 'positive'), (-1.0, 'positive')]:
        with pytest.raises(ValueError, match=f"'eps' must be {match}"):
            C.check_positive_float(value, 'eps')


def test_faces_and_referenced_vertices():
    face = torch.tensor([[0], [1], [2]])
    assert C.check_faces(face, 4, POS) is face
    repeated = torch.tensor([[0, 1], [1, 1], [2, 3]])
    assert C.check_faces(repeated, 4, POS, allow_degenerate_indices=True) \
        is repeated
    for value, match in [
            (face.t(), r'\[3, F\].*pass face.t\(\)'),
            (face.int(), 'torch.long'),
            (torch.tensor([[0], [1], [4]]), r'\[0, 4\] but there are only 4'),
            (torch.tensor([[-1], [1], [2]]), r'\[-1, 2\]'),
            (repeated, r'1 triangle\(s\) that repeat a vertex \(first: '
                       r'\[1\]\)')]:
        with pytest.raises(ValueError, match=match):
            C.check_faces(value, 4, POS)
    C.check_referenced(torch.tensor([0, 1, 2, 3]), 4, 'triangle', 'fix it')
    with pytest.raises(ValueError, match=r'2 vertex/vertices are not '
                                         r'referenced by any triangle '
                                         r'\(first: \[1, 3\]\); fix it'):
        C.check_referenced(torch.tensor([0, 2, 2]), 4, 'triangle', 'fix it')


def test_nondegenerate_is_relative_to_the_triangle_size():
    scale = torch.tensor([1e-20, 1.0], dtype=D64)
    # a tiny triangle is not degenerate if it is tiny in every direction
    C.check_nondegenerate(torch.tensor([1e-21, 0.4], dtype=D64), scale)
    with pytest.raises(ValueError, match=r'1 zero-area .* \(first: \[1\]\)'):
        C.check_nondegenerate(torch.tensor([1e-21, 1e-17], dtype=D64), scale)


def test_index_pairs_and_rows():
    edge = torch.tensor([[0, 3], [1, 2]])
    assert C.check_edge_index(edge, 4, POS) is edge
    for value, match in [(edge.t()[:1], r'\[2, E\]'),
                         (edge.float(), 'torch.long'),
                         (edge + 1, r'\[1, 4\], outside \[0, 4\): there '
                                    r'are only 4 points')]:
        with pytest.raises(ValueError, match=match):
            C.check_edge_index(value, 4, POS)
    cluster = torch.tensor([0, 1, 1, 0])
    assert C.check_index(cluster, 'cluster', 2, POS, size=4) is cluster
    with pytest.raises(ValueError, match=r"'cluster' must have shape \[4\]"):
        C.check_index(cluster[:3], 'cluster', 2, POS, size=4)
    with pytest.raises(ValueError, match='integer indices'):
        C.check_index(cluster.float(), 'cluster', 2, POS)
    with pytest.raises(ValueError, match=r'negative indices \(down to -1\)'):
        C.check_index(cluster - 1, 'cluster', None, POS)
    assert C.check_rows(POS, 'x', 4, 'the graph') is POS
    with pytest.raises(ValueError, match="'x' has 3 rows but there are 4 "
                                         "nodes in the graph"):
        C.check_rows(POS[:3], 'x', 4, 'the graph')


def test_float_tensors_directions_and_unit_interval():
    z = torch.zeros(2, 1, 3, dtype=torch.cfloat)
    assert C.check_streams(z) is z
    with pytest.raises(ValueError, match=r'complex stream features.*'
                                         r'unsqueeze\(1\)'):
        C.check_streams(torch.zeros(2, 3))
    w = torch.ones(5, dtype=D64)
    assert C.check_float_tensor(w, 'weight', (5, )) is w
    for value, match in [(w[:4], r'shape \[5\]'),
                         (w.long(), 'float tensor'),
                         (w * float('nan'), 'NaN or infinite')]:
        with pytest.raises(ValueError, match=match):
            C.check_float_tensor(value, 'weight', (5, ))
    directions = C.check_unit_rows(torch.tensor([[3.0, 0, 4]]), 'light',
                                   (1, 3))
    np.testing.assert_allclose(directions, [[0.6, 0, 0.8]])
    assert directions.dtype == np.float64
    with pytest.raises(ValueError, match='zero-length'):
        C.check_unit_rows(torch.zeros(1, 3), 'light', (1, 3))
    r = C.check_unit_interval(torch.tensor([0.0, 1.0]), 'roughness', (2, ))
    assert r.dtype == D64
    with pytest.raises(ValueError, match=r'\[0, 1\], got values in '
                                         r'\[-0.5, 1\]'):
        C.check_unit_interval(torch.tensor([-0.5, 1.0]), 'roughness', (2, ))


def test_seed_and_image_size():
    assert C.check_seed(np.int64(7)) == 7
    for seed in (-1, 1.0, True, '3'):
        with pytest.raises(ValueError, match='non-negative integer'):
            C.check_seed(seed)
    assert C.check_image_size([24, np.int64(32)]) == (24, 32)
    with pytest.raises(ValueError, match=r'\(height, width\)'):
        C.check_image_size(24)
    with pytest.raises(ValueError, match=r"'image_size\[1\]' must be at "
                                         r"least 1"):
        C.check_image_size((24, 0))


def test_cameras():
    K, E = camera_pair()
    Ks, Es = C.check_cameras(K, E, batched=False)
    assert Ks.shape == (1, 3, 3) and Es.shape == (1, 3, 4)
    Ks, Es = C.check_cameras(K.expand(3, 3, 3), E.expand(3, 3, 4))
    assert Ks.shape == (3, 3, 3)
    skew = K.clone()
    skew[0, 1] = 0.5  # a skewed pinhole is still a pinhole
    C.check_cameras(skew[None], E[None])
    scaled = E.clone()
    scaled[:, :3] *= 2
    mirrored = E.clone()
    mirrored[2, :3] *= -1
    flipped = K.clone()
    flipped[1, 1] = -50
    for k, e, match in [
            (K, E, r'\[V, 3, 3\].*\[V, 3, 4\]'),
            (K.expand(2, 3, 3), E[None], "2 views but 'extrinsics' has 1"),
            (K[None][:0], E[None][:0], r'no views \(0 cameras\)'),
            (K[None] * float('nan'), E[None], 'finite floating-point'),
            (flipped[None], E[None], 'fx, fy > 0'),
            (K[None], scaled[None], r'camera\(s\) \[0\] are not'),
            (K[None], mirrored[None], r'camera\(s\) \[0\] are not')]:
        with pytest.raises(ValueError, match=match):
            C.check_cameras(k, e)


def test_frames():
    frame = torch.stack([rotation_z(a).t() for a in (0.1, 0.2, 0.3, 0.4)])
    assert C.check_frames(frame, 4, POS) is frame
    for value, match in [
            (frame[:, :2], r'\[N, 3, 3\]'),
            (frame[:3], "'frame' has 9 rows but there are 12"),
            (2 * frame, 'orthonormal'),
            (torch.stack([frame[:, 1], frame[:, 0], frame[:, 2]], 1),
             'right-handed')]:
        with pytest.raises(ValueError, match=match):
            C.check_frames(value, 4, POS)


def test_prolongation():
    x = torch.zeros(4, 2, dtype=D64)
    index = torch.tensor([[0, 1, 2, 3], [0, 0, 1, 1]])
    weight = torch.ones(4, dtype=D64)
    C.check_prolongation(x, index, weight, 4, 'fine', other=2)
    C.check_prolongation(x[:2], index, weight, 2, 'coarse', other=4)
    for args, match in [
            ((x.long(), index, weight), 'float features'),
            ((x, index[:1], weight), r'\[2, nnz\]'),
            ((x, index, weight[:3]), 'one weight per column'),
            ((x, index, weight * float('nan')), 'NaN or infinite'),
            ((x[:3], index, weight), r'outside \[0, 3\).*fine points')]:
        with pytest.raises(ValueError, match=match):
            C.check_prolongation(*args, args[0].size(0), 'fine', other=2)
    with pytest.raises(ValueError, match=r'coarse points \(num_coarse\)'):
        C.check_prolongation(x, index, weight, 4, 'fine', other=1)


def test_vector_features():
    v = torch.zeros(4, 3, 2, dtype=D64)
    assert C.check_vector_features(v, 'v', 3) is v
    assert C.check_vector_features(v, 'v', 3, num=4) is v
    for value, channels, num in [(v[..., :1], 3, None), (v, 2, None),
                                 (v.long(), 3, None), (v[:3], 3, 4),
                                 (v.view(4, 6), 3, None)]:
        with pytest.raises(ValueError, match=r"'v' must be float tangent "
                                             r"vector features"):
            C.check_vector_features(value, 'v', channels, num)


def test_view_indices():
    assert C.check_view_indices([2, 0], 'views', 3) == [2, 0]
    assert C.check_view_indices(torch.tensor([1]), 'views', 3) == [1]
    assert C.check_view_indices([], 'views', 3) == []
    for views, match in [([0, 3], r'\[3\] outside \[0, 3\)'),
                         ([1, 1], 'more than once'),
                         ([-1], 'at least 0'),
                         (torch.tensor([0.5]), 'integer'),
                         (torch.tensor([True]), 'integer'),
                         (None, 'sequence of view indices')]:
        with pytest.raises(ValueError, match=match):
            C.check_view_indices(views, 'views', 3)
