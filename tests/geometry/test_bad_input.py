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


def call(fn, *args, **kwargs):
    try:
        out = fn(*args, **kwargs)
    except ValueError as error:
        assert len(str(error)) > 15  # a sentence, not a bare code
        return None
    return out


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
        out = call(fn, pos, **kwargs)
        if out is not None:
            assert_valid(out, n)
            if out.dtype == torch.long:
                assert out.numel() == 0 or out.max() < n
                if batch is not None and out.dim() == 2:
                    assert torch.equal(batch[out[0]], batch[out[1]])
    out = call(G.tangent_frames, pos)
    if out is not None:
        assert_valid(out, n)


@SETTINGS
@given(data=st.data())
def test_mesh_functions_never_return_nan(data):
    pos = data.draw(point_arrays())
    n = pos.size(0) if pos.dim() > 0 else 0
    face = data.draw(face_arrays(n))
    for fn in [G.face_areas, G.face_normals, G.vertex_normals, G.lumped_mass,
               G.cotan_weights, G.cotan_laplacian,
               G.remove_unreferenced_vertices, G.normalize_area]:
        out = call(fn, pos, face)
        if out is not None:
            assert_valid(out, n)
    for fn in [G.mesh_edges, G.edge_face_counts, G.is_closed_manifold]:
        out = call(fn, face, n)
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
