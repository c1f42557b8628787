"""Property test: malformed input to any public geometry function raises a
ValueError that says what is wrong, or gives a finite, valid result."""
import numpy as np
import pytest
import torch
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from tg_intrinsic import geometry as G


@st.composite
def point_arrays(draw):
    n = draw(st.sampled_from([0, 1, 2, 3, 5, 12, 40]))
    dim = draw(st.sampled_from([3, 3, 3, 2, None]))  # None: a 1-D array
    dtype = draw(st.sampled_from([torch.float32, torch.float64,
                                  torch.float64, torch.float16, torch.int64]))
    seed = draw(st.integers(0, 2 ** 16))
    rng = np.random.default_rng(seed)
    values = rng.normal(size=(n, 3 if dim is None else dim))
    if n > 1 and draw(st.booleans()):  # duplicate points
        values[rng.integers(n, size=n // 2)] = values[0]
    if n > 0 and draw(st.booleans()):  # collapse to a line or a point
        values[:, 1:] = 0.0 if draw(st.booleans()) else values[:1, 1:]
    if n > 0 and draw(st.booleans()):
        values[rng.integers(n)] = draw(st.sampled_from(
            [np.nan, np.inf, -np.inf]))
    pos = torch.tensor(values)
    if dim is None:
        pos = pos[:, 0]
    return pos.to(dtype) if dtype != torch.int64 else pos.round().long()


@st.composite
def face_arrays(draw, n):
    f = draw(st.sampled_from([0, 1, 4, 20]))
    rng = np.random.default_rng(draw(st.integers(0, 2 ** 16)))
    m = max(n, 3)
    # Three distinct corners per triangle (an argsort of random keys).
    face = torch.tensor(np.argsort(rng.random((f, m)), axis=1)[:, :3].T.copy())
    defect = draw(st.sampled_from(['none', 'none', 'repeat', 'past_end',
                                   'negative', 'transposed', 'float']))
    if f > 0 and defect == 'repeat':
        face[2, 0] = face[0, 0]
    elif f > 0 and defect == 'past_end':
        face[1, 0] = n + 2
    elif f > 0 and defect == 'negative':
        face[0, 0] = -1
    elif defect == 'transposed':
        face = face.t()
    elif defect == 'float':
        face = face.double()
    return face


@st.composite
def batches(draw, n):
    kind = draw(st.sampled_from(['none', 'ok', 'unsorted', 'short', 'int32']))
    if kind == 'none' or n == 0:
        return None
    cut = draw(st.integers(0, n))
    batch = torch.cat([torch.zeros(cut), torch.ones(n - cut)]).long()
    if kind == 'unsorted':
        batch = batch.flip(0)
    elif kind == 'short':
        batch = batch[1:]
    elif kind == 'int32':
        batch = batch.int()
    return batch


def assert_valid(out, n):
    outs = out if isinstance(out, tuple) else (out, )
    for value in outs:
        if isinstance(value, torch.Tensor):
            if value.is_sparse:
                value = value.coalesce().values()
            if value.is_floating_point():
                assert torch.isfinite(value).all(), 'silent NaN/inf'
            elif value.dtype == torch.long and value.numel() > 0:
                assert value.min() >= 0


def call(fn, *args, inputs, **kwargs):
    """``fn(*args, **kwargs)``, or :obj:`None` when it raised a
    :class:`ValueError` whose message names a defect that ``inputs`` (the
    arrays and arguments passed, by name) really have. Any other
    :class:`ValueError`, such as one a broken check raises for valid input,
    fails the test: a ValueError is no proof of "no silent NaN" unless it
    is the right one."""
    try:
        out = fn(*args, **kwargs)
    except ValueError as error:
        message = str(error)
        assert explained(message, inputs), \
            f'{fn.__name__} raised a ValueError that names no defect of ' \
            f'its input: {message!r}'
        return None
    return out


def _ints(text):
    return [int(v) for v in text.replace(' ', '').split(',') if v]


def _rows_not_finite(x):
    return (~torch.isfinite(x)).reshape(x.size(0), -1).any(1)


def _areas(pos, face):
    """Triangle areas and squared longest edges, in float64."""
    p = pos.double()[face]
    cross = torch.linalg.cross(p[1] - p[0], p[2] - p[0])
    edges = torch.stack([(p[1] - p[0]).pow(2).sum(-1),
                         (p[2] - p[1]).pow(2).sum(-1),
                         (p[0] - p[2]).pow(2).sum(-1)])
    return 0.5 * cross.norm(dim=-1), edges.amax(0)


def _example(inputs, index):
    """The points of example ``index`` (all of them without a batch)."""
    x, batch = inputs['pos'], inputs.get('batch')
    return x if batch is None else x[batch == index]


def _degenerate_neighbourhood(inputs, centre, size):
    """Whether point ``centre`` and its ``size - 1`` nearest neighbours in
    its example lie on a line (or coincide), by brute force in float64."""
    x, batch = inputs['pos'].double(), inputs.get('batch')
    same = torch.ones(x.size(0), dtype=torch.bool) if batch is None else \
        batch == batch[centre]
    distance = (x - x[centre]).pow(2).sum(-1)
    distance[~same] = float('inf')
    distance[centre] = -1.0  # the centre first
    patch = x[distance.argsort()[:size]]
    evals = torch.linalg.eigvalsh((patch - patch.mean(0)).T @
                                  (patch - patch.mean(0)))
    return bool(evals[1] <= 1e-9 * evals[2].clamp_min(1e-300))


def explained(message, inputs):
    """Whether ``message`` names a defect that ``inputs`` really have: the
    tensor it names has that dtype or shape, the NaN rows, the repeated or
    out-of-range corners, the zero-area triangles, the unreferenced
    vertices, the vertices whose triangles' normals cancel, the degenerate
    neighbourhoods, the bad ``k``, ``r`` or ``ratio`` it reports."""
    import re
    pos, face = inputs.get('pos'), inputs.get('face')
    batch, n = inputs.get('batch'), inputs.get('n')
    match = re.match(r"'(x|pos|normal)' must be float32 or float64, got "
                     r"torch\.(\w+); convert it", message)
    if match:
        return str(pos.dtype) == f'torch.{match[2]}' and \
            pos.dtype not in (torch.float32, torch.float64)
    match = re.match(r"'(x|pos|normal)' must have shape \[N, (\d|D)\], got "
                     r"\[([-\d, ]*)\]$", message)
    if match:
        wrong = pos.dim() != 2 or (match[2] != 'D' and
                                   pos.size(1) != int(match[2]))
        return _ints(match[3]) == list(pos.shape) and wrong
    match = re.match(r"'(x|pos|normal)' contains NaN or infinite values at "
                     r"(\d+) row\(s\) \(first: \[([\d, ]*)\]\)", message)
    if match:
        bad = _rows_not_finite(pos)
        return int(match[2]) == int(bad.sum()) and \
            bool(bad[_ints(match[3])].all())
    match = re.match(r"'(x|pos)' has (\d+) points but at least (\d+) are "
                     r"needed$", message)
    if match:
        return int(match[2]) == pos.size(0) < int(match[3])
    match = re.match(r"'k' must be at least (-?\d+), got (-?\d+)$", message)
    if match:
        return int(match[2]) == inputs['k'] < int(match[1])
    match = re.match(r"knn: example (\d+) has (\d+) point\(s\)(.*), fewer "
                     r"than k=(\d+); (lower k|remove that example)",
                     message)
    if match:
        size = _example(inputs, int(match[1])).size(0)
        candidates = size - 1 if 'loop=False' in match[3] else size
        return int(match[2]) == size and \
            int(match[4]) == inputs['k'] > candidates
    if message.startswith("'batch' must be sorted"):
        return batch is not None and bool((batch.diff() < 0).any())
    match = re.match(r"'batch' must be torch\.long, got torch\.(\w+)$",
                     message)
    if match:
        return batch is not None and str(batch.dtype) == f'torch.{match[1]}'
    match = re.match(r"'batch' must have shape \[(\d+)\] \(one example "
                     r"index per point\), got \[(\d*)\]$", message)
    if match:
        return int(match[1]) == pos.size(0) and \
            _ints(match[2]) == list(batch.shape) != [pos.size(0)]
    if message == "'r' must be finite, got nan":
        return inputs['r'] != inputs['r']
    match = re.match(r"'(r|ratio)' must be positive, got (.*)$", message)
    if match:
        value = inputs[match[1]]
        return value <= 0 and float(match[2]) == value
    match = re.match(r"'ratio' must be in \(0, 1\] \(the fraction of points "
                     r"to keep\), got (.*)$", message)
    if match:
        return inputs['ratio'] > 1 and float(match[1]) == inputs['ratio']
    match = re.match(r"'face' must have shape \[3, F\] \(PyG layout\), got "
                     r"\[([\d, ]*)\]", message)
    if match:
        return _ints(match[1]) == list(face.shape) and \
            (face.dim() != 2 or face.size(0) != 3)
    match = re.match(r"'face' must be torch\.long vertex indices, got "
                     r"torch\.(\w+);", message)
    if match:
        return str(face.dtype) == f'torch.{match[1]}' != 'torch.int64'
    match = re.match(r"'face' indexes vertices in \[(-?\d+), (-?\d+)\] but "
                     r"there are only (\d+) vertices$", message)
    if match:
        lo, hi, count = int(match[1]), int(match[2]), int(match[3])
        return (lo, hi, count) == (int(face.min()), int(face.max()), n) \
            and (lo < 0 or hi >= count)
    match = re.match(r"'face' has (\d+) triangle\(s\) that repeat a vertex "
                     r"\(first: \[([\d, ]*)\]\); remove them$", message)
    if match:
        repeated = (face[0] == face[1]) | (face[1] == face[2]) | \
            (face[0] == face[2])
        return int(match[1]) == int(repeated.sum()) and \
            bool(repeated[_ints(match[2])].all())
    match = re.match(r"'face' has (\d+) zero-area \(degenerate\) triangle\(s\)"
                     r" \(first: \[([\d, ]*)\]\)", message)
    if match:
        area, longest = _areas(pos, face)
        first = _ints(match[2])
        # (numerically) zero: tiny against the triangle's longest edge
        return len(first) > 0 and bool(
            (area[first] <= 1e-5 * longest[first]).all())
    match = re.match(r"(\d+) vertex/vertices are not referenced by any "
                     r"triangle \(first: \[([\d, ]*)\]\)", message)
    if match:
        used = torch.zeros(n, dtype=torch.bool)
        used[face.reshape(-1)] = True
        return int(match[1]) == int((~used).sum()) and \
            not bool(used[_ints(match[2])].any())
    match = re.match(r"the normal of (\d+) vertex/vertices \(first: "
                     r"\[([\d, ]*)\]\) is undefined: their incident "
                     r"triangles cancel out", message)
    if match:
        p = pos.double()[face]
        cross = torch.linalg.cross(p[1] - p[0], p[2] - p[0])
        total = torch.zeros(n, 3, dtype=torch.float64)
        for corner in range(3):
            total.index_add_(0, face[corner], cross)
        first = _ints(match[2])
        return len(first) > 0 and bool(
            (total[first].norm(dim=-1) <= 1e-4 * cross.norm(dim=-1).max()
             ).all())
    if message == ("'face' holds no triangles, so there is no Laplacian "
                   "to build") or message.startswith("'face' has no "
                                                     "triangles"):
        return face is not None and face.dim() == 2 and face.size(1) == 0
    match = re.match(r"'(eps|radius)' must be (finite|positive), got (.*)$",
                     message)
    if match:
        value = inputs[match[1]]
        return not (value == value and abs(value) != float('inf')) \
            if match[2] == 'finite' else value <= 0
    match = re.match(r"(\d+) point\(s\) \(first: \[([\d, ]*)\]\) have an "
                     r"empty Voronoi cell: their (\d+) nearest neighbours "
                     r"project onto them in the tangent plane", message)
    if match:
        p, normal = pos.double(), inputs['normal'].double()
        normal = normal / normal.norm(dim=1, keepdim=True)
        scale = float((p - p.mean(0)).norm(dim=1).max()) + 1e-300
        for i in _ints(match[2]):
            offset = p - p[i]
            flat = offset - (offset @ normal[i])[:, None] * normal[i]
            near = offset.norm(dim=1).argsort()[1:int(match[3]) + 1]
            if bool((flat[near].norm(dim=1) > 1e-9 * scale).any()):
                return False
        return True
    match = re.match(r"'pos' has (\d+) points but k=(\d+) neighbours are "
                     r"needed per point; lower k", message)
    if match:
        return int(match[1]) == pos.size(0) <= int(match[2])
    match = re.match(r"eps=(\S+) is smaller than the spacing of the "
                     r"points: every disc holds only its centre", message)
    if match:
        p = pos.double()
        if face is None:
            gaps = torch.cdist(p, p) + torch.diag(
                torch.full((p.size(0), ), float('inf'), dtype=p.dtype))
        else:
            gaps = (p[face] - p[face.roll(1, 0)]).norm(dim=-1)
        return float(match[1]) == inputs['eps'] and \
            bool((gaps >= inputs['eps']).all())
    if message == 'the mesh has zero surface area; cannot normalise it':
        area, longest = _areas(pos, face)
        return bool(area.sum() <= 1e-12 * longest.max().clamp_min(1e-300)) \
            if face.size(1) else True
    match = re.match(r"the neighbourhoods of (\d+) point\(s\) \(first: "
                     r"\[([\d, ]*)\]\) are degenerate: their (\d+) points "
                     r"coincide or lie on a line", message)
    if match:
        return int(match[3]) == inputs['k'] + 1 and all(
            _degenerate_neighbourhood(inputs, i, int(match[3]))
            for i in _ints(match[2]))
    return False


SETTINGS = settings(max_examples=60, deadline=None,
                    suppress_health_check=[HealthCheck.too_slow])


@SETTINGS
@given(data=st.data())
def test_point_functions_never_return_nan(data):
    pos = data.draw(point_arrays())
    n = pos.size(0) if pos.dim() > 0 else 0
    batch = data.draw(batches(n))
    k = data.draw(st.sampled_from([-1, 0, 1, 3, 8, 50]))
    for fn, kwargs in [
        (G.knn, dict(k=k, batch=batch)),
        (G.knn, dict(k=k, batch=batch, loop=True)),
        (G.radius, dict(r=data.draw(st.sampled_from([-1.0, 0.0, 0.5,
                                                     float('nan'), 3.0])),
                        batch=batch)),
        (G.fps, dict(ratio=data.draw(st.sampled_from([0.0, 0.3, 1.0, 1.5])),
                     batch=batch)),
        (G.estimate_normals, dict(k=k, batch=batch)),
    ]:
        out = call(fn, pos, inputs=dict(kwargs, pos=pos, n=n), **kwargs)
        if out is not None:
            assert_valid(out, n)
            if out.dtype == torch.long:
                assert out.numel() == 0 or out.max() < n
                if batch is not None and out.dim() == 2:
                    assert torch.equal(batch[out[0]], batch[out[1]])
    out = call(G.tangent_frames, pos, inputs=dict(pos=pos, n=n))
    if out is not None:
        assert_valid(out, n)


@SETTINGS
@given(data=st.data())
def test_mesh_functions_never_return_nan(data):
    pos = data.draw(point_arrays())
    n = pos.size(0) if pos.dim() > 0 else 0
    face = data.draw(face_arrays(n))
    inputs = dict(pos=pos, face=face, n=n)
    for fn in [G.face_areas, G.face_normals, G.vertex_normals, G.lumped_mass,
               G.cotan_weights, G.cotan_laplacian,
               G.remove_unreferenced_vertices, G.normalize_area]:
        out = call(fn, pos, face, inputs=inputs)
        if out is not None:
            assert_valid(out, n)
    for fn in [G.mesh_edges, G.edge_face_counts, G.is_closed_manifold]:
        out = call(fn, face, n, inputs=inputs)
        if out is not None and not isinstance(out, bool):
            assert_valid(out, n)


@pytest.mark.parametrize('fn,args,match', [
    (G.knn, (np.zeros((4, 3)), 2), 'torch.Tensor'),
    (G.knn, (torch.zeros(4, 3, dtype=torch.float16), 2), 'float32 or float64'),
    (G.estimate_normals, (torch.randn(5, 3), 10), 'k'),
    (G.cotan_laplacian, (torch.randn(3, 3), torch.tensor([[0], [1], [1]])),
     'repeat a vertex'),
    (G.lumped_mass, (torch.randn(4, 3), torch.tensor([[0], [1], [2]])),
     'not referenced'),
    (G.face_areas, (torch.randn(4, 3).double(),
                    torch.tensor([[0], [1], [2]]).int()), 'torch.long'),
])
def test_messages_name_the_problem(fn, args, match):
    with pytest.raises(ValueError, match=match):
        fn(*args)


def test_only_the_right_value_error_counts():
    # A check that wrongly rejects valid input (or names a defect the
    # input does not have) fails the property tests above.
    pos = torch.tensor([[0., 0, 0], [1, 0, 0], [0, 1, 0], [0, 0, 1]])
    face = torch.tensor([[0, 0, 0, 1], [2, 1, 3, 2], [1, 3, 2, 3]])
    inputs = dict(pos=pos, face=face, n=4)

    def wrong(pos, face):
        raise ValueError("'face' has 1 triangle(s) that repeat a vertex "
                         "(first: [0]); remove them")

    with pytest.raises(AssertionError, match='names no defect'):
        call(wrong, pos, face, inputs=inputs)
    assert call(G.face_normals, pos, face, inputs=inputs) is not None
    bad = face.clone()
    bad[2, 0] = bad[0, 0]  # now triangle 0 repeats a vertex: explained
    assert call(wrong, pos, bad, inputs=dict(inputs, face=bad)) is None
    assert call(G.face_normals, pos, bad, inputs=dict(inputs, face=bad)) \
        is None
