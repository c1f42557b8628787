"""knn / radius / fps against brute force, on both the tree (CPU) path and the
dense (GPU-style, cdist + topk) path run on CPU."""
import math
from fractions import Fraction

import numpy as np
import pytest
import torch
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from tg_intrinsic.geometry.pointcloud import neighbors as nb
from tg_intrinsic.geometry.pointcloud.neighbors import fps, knn, radius


# --------------------------------------------------------------------------
# helpers
# --------------------------------------------------------------------------
@pytest.fixture(params=['tree', 'dense'])
def path(request, monkeypatch):
    """Runs a test on the cKDTree path and on the dense (GPU) path."""
    if request.param == 'dense':
        monkeypatch.setattr(nb, '_use_dense', lambda x: True)
    return request.param


@pytest.fixture(params=['tree', 'dense', 'ball'])
def radius_path(request, monkeypatch):
    """radius() on the cKDTree k-query path, the dense path, and the ball-query
    path (used on CPU for large max_num_neighbors)."""
    if request.param == 'dense':
        monkeypatch.setattr(nb, '_use_dense', lambda x: True)
    if request.param == 'ball':
        monkeypatch.setattr(nb, '_BALL_QUERY_K', 0)
    return request.param


def sqdist(a, b):
    """All-pairs squared distances in float64, summed coordinate-wise."""
    a, b = a.double(), b.double()
    d = (a[:, None, 0] - b[None, :, 0]) ** 2
    for j in range(1, a.size(1)):
        d += (a[:, None, j] - b[None, :, j]) ** 2
    return d


def sqdist_rows(a, b):
    a, b = a.double(), b.double()
    d = (a[:, 0] - b[:, 0]) ** 2
    for j in range(1, a.size(1)):
        d += (a[:, j] - b[:, j]) ** 2
    return d


def brute(x, batch, loop, query=None, query_batch=None):
    """Masked all-pairs squared distances [M, N] (inf = not allowed)."""
    graph = query is None
    if batch is None:
        batch = torch.zeros(x.size(0), dtype=torch.long)
    if graph:
        query, query_batch = x, batch
    elif query_batch is None:
        query_batch = torch.zeros(query.size(0), dtype=torch.long)
    d = sqdist(query, x)
    d[query_batch[:, None] != batch[None, :]] = float('inf')
    if graph and not loop:
        d.fill_diagonal_(float('inf'))
    return d, batch, query_batch


def uneven_batch(sizes):
    return torch.cat([torch.full((s,), i, dtype=torch.long)
                      for i, s in enumerate(sizes)])


def check_knn(ei, x, k, batch=None, loop=False, query=None,
              query_batch=None, exact=True):
    d, batch, query_batch = brute(x, batch, loop, query, query_batch)
    m = d.size(0)
    q = x if query is None else query
    assert ei.dtype == torch.long and ei.shape == (2, m * k)
    # centres ascending, exactly k each
    assert torch.equal(ei[1], torch.arange(m).repeat_interleave(k))
    nbr = ei[0]
    assert int(nbr.min()) >= 0 and int(nbr.max()) < x.size(0)
    # never across examples, no self loop unless allowed, no duplicate edge
    assert torch.equal(batch[nbr], query_batch[ei[1]])
    if query is None and not loop:
        assert bool((nbr != ei[1]).all())
    assert torch.unique(ei[1] * x.size(0) + nbr).numel() == ei.size(1)
    # the r-th returned neighbour is at the r-th smallest brute distance
    got = sqdist_rows(q[ei[1]], x[nbr]).view(m, k)
    want = d.sort(dim=1).values[:, :k]
    if exact:
        assert torch.equal(got, want)
        # equal distances: ascending neighbour index (deterministic ties)
        tie = got[:, 1:] == got[:, :-1]
        nbr = nbr.view(m, k)
        assert bool((nbr[:, 1:] > nbr[:, :-1])[tie].all())
    else:
        tol = 1e-5 if x.dtype == torch.float32 else 1e-12
        torch.testing.assert_close(got, want, rtol=tol, atol=tol)
        assert bool((got[:, 1:] >= got[:, :-1] - tol).all())


def check_radius(ei, x, r, cap, batch=None, loop=False, query=None,
                 query_batch=None):
    d, batch, query_batch = brute(x, batch, loop, query, query_batch)
    m = d.size(0)
    q = x if query is None else query
    assert ei.dtype == torch.long and ei.dim() == 2 and ei.size(0) == 2
    within = (d <= r * r) & torch.isfinite(d)
    counts = within.sum(1)
    got_counts = torch.bincount(ei[1], minlength=m)
    assert torch.equal(got_counts, counts.clamp(max=cap))
    assert bool((ei[1][1:] >= ei[1][:-1]).all())  # sorted by centre
    nbr = ei[0]
    assert torch.equal(batch[nbr], query_batch[ei[1]])
    assert bool(within[ei[1], nbr].all())
    assert torch.unique(ei[1] * x.size(0) + nbr).numel() == ei.size(1)
    got = sqdist_rows(q[ei[1]], x[nbr])
    # within a centre distances ascending, and the kept ones are the nearest
    sorted_d = d.sort(dim=1).values
    start = 0
    for i in range(m):
        c = int(got_counts[i])
        gi = got[start:start + c]
        assert bool((gi[1:] >= gi[:-1]).all())
        ni = nbr[start:start + c]
        assert bool((ni[1:] > ni[:-1])[gi[1:] == gi[:-1]].all())
        assert torch.equal(gi, sorted_d[i, :c])
        start += c
    uncapped = counts <= cap
    pairs = set(zip(ei[1].tolist(), nbr.tolist()))
    want = {(i, j) for i, j in within.nonzero().tolist() if uncapped[i]}
    assert want == {(i, j) for i, j in pairs if uncapped[i]}


def fps_reference(pos, ratio, batch, starts=None):
    """Plain numpy farthest point sampling, one example at a time."""
    pos = pos.double().numpy()
    batch = np.zeros(len(pos), np.int64) if batch is None else batch.numpy()
    out = []
    for b in range(int(batch.max()) + 1):
        idx = np.nonzero(batch == b)[0]
        if idx.size == 0:
            continue
        p = pos[idx]
        m = math.ceil(Fraction(str(ratio)) * len(idx))
        cur = 0 if starts is None else int(starts[b])
        chosen = [cur]
        dist = np.full(len(idx), np.inf)
        for _ in range(m - 1):
            dist = np.minimum(dist, ((p - p[cur]) ** 2).sum(1))
            dist[chosen] = -1
            cur = int(np.argmax(dist))
            chosen.append(cur)
        out.extend(idx[chosen].tolist())
    return torch.tensor(out, dtype=torch.long)


# --------------------------------------------------------------------------
# knn
# --------------------------------------------------------------------------
@pytest.mark.parametrize('dtype', [torch.float32, torch.float64])
@pytest.mark.parametrize('loop', [False, True])
@pytest.mark.parametrize('batched', [False, True])
def test_knn_matches_brute_force(path, dtype, loop, batched):
    torch.manual_seed(0)
    sizes = [37, 5, 120, 3, 64] if batched else [200]
    x = torch.randn(sum(sizes), 3, dtype=dtype)
    batch = uneven_batch(sizes) if batched else None
    most = min(sizes) - (0 if loop else 1)  # k == available candidates
    for k in sorted({1, min(4, most), most}):
        ei = knn(x, k, batch, loop=loop)
        check_knn(ei, x, k, batch, loop, exact=path == 'tree')


@pytest.mark.parametrize('dtype', [torch.float32, torch.float64])
def test_knn_batched_uneven(path, dtype):
    torch.manual_seed(1)
    sizes = [30, 7, 100, 12]
    x = torch.rand(sum(sizes), 3, dtype=dtype)
    batch = uneven_batch(sizes)
    for loop in (False, True):
        ei = knn(x, 6, batch, loop=loop)
        check_knn(ei, x, 6, batch, loop, exact=path == 'tree')


@pytest.mark.parametrize('dim', [1, 2, 5])
def test_knn_any_dimension(path, dim):
    torch.manual_seed(2)
    x = torch.randn(150, dim, dtype=torch.float64)
    batch = uneven_batch([50, 100])
    check_knn(knn(x, 7, batch), x, 7, batch, exact=path == 'tree')


@pytest.mark.parametrize('dtype', [torch.float32, torch.float64])
def test_knn_query_mode(path, dtype):
    torch.manual_seed(3)
    x = torch.randn(150, 3, dtype=dtype)
    q = torch.randn(60, 3, dtype=dtype)
    bx, bq = uneven_batch([40, 10, 100]), uneven_batch([20, 25, 15])
    ei = knn(x, 10, bx, query=q, query_batch=bq)
    check_knn(ei, x, 10, bx, query=q, query_batch=bq, exact=path == 'tree')
    # unbatched query, and a query that coincides with a point of x
    q2 = torch.cat([q, x[:3]])
    ei = knn(x, 3, query=q2)
    check_knn(ei, x, 3, query=q2, exact=path == 'tree')
    assert ei[0, -3].item() == 2  # distance 0 to itself: first neighbour


def test_knn_integer_lattice_ties(path):
    g = torch.arange(6, dtype=torch.float64)
    x = torch.cartesian_prod(g, g, g)  # 216 points, massive distance ties
    x = torch.cat([x, x[:20]])  # plus exact duplicates
    for loop in (False, True):
        for k in (1, 6, 19, 27):
            ei = knn(x, k, loop=loop)
            check_knn(ei, x, k, loop=loop, exact=True)
    # a duplicate point is a valid neighbour at distance 0 even without loops
    ei = knn(x, 1, loop=False)
    assert ei[0, 0].item() == 216 and ei[0, 216].item() == 0


def test_knn_many_duplicates(path):
    # 40 copies of one point: the centre itself may not be among the tree's
    # k + 1 hits, yet it must be dropped and exactly k neighbours returned
    x = torch.cat([torch.zeros(40, 3), torch.randn(10, 3)]).double()
    for k in (1, 5, 39, 49):
        check_knn(knn(x, k), x, k, exact=True)
    batch = uneven_batch([45, 5])
    check_knn(knn(x, 4, batch), x, 4, batch, exact=True)
    with pytest.raises(ValueError, match='example 1 has 5 point'):
        knn(x, 5, batch)
    for cap in (1, 5, 39):
        ei = radius(x, 1e-3, batch, max_num_neighbors=cap)
        check_radius(ei, x, 1e-3, cap, batch)


def test_knn_k_equals_cluster_size(path):
    torch.manual_seed(4)
    sizes = [5, 8, 5]
    x = torch.randn(sum(sizes), 3)
    batch = uneven_batch(sizes)
    ei = knn(x, 5, batch, loop=True)
    check_knn(ei, x, 5, batch, loop=True, exact=path == 'tree')
    # examples 0 and 2 (5 points each) return all their points, every time
    for i in list(range(5)) + list(range(13, 18)):
        want = set((batch == batch[i]).nonzero().flatten().tolist())
        assert set(ei[0, ei[1] == i].tolist()) == want
    with pytest.raises(ValueError, match=r'example 0 has 5 point.*lower k'):
        knn(x, 5, batch, loop=False)
    with pytest.raises(ValueError, match=r'example 0.*k=6'):
        knn(x, 6, batch, loop=True)


def test_knn_query_empty_example_raises(path):
    x = torch.randn(10, 3)
    bx = torch.zeros(10, dtype=torch.long)
    q = torch.randn(4, 3)
    bq = torch.tensor([0, 0, 1, 1])
    with pytest.raises(ValueError, match=r"query example 1 .* 0 point"):
        knn(x, 2, bx, query=q, query_batch=bq)
    # no queries at all: no edges
    assert knn(x, 2, query=torch.empty(0, 3)).shape == (2, 0)


def test_knn_dense_equals_tree(monkeypatch):
    torch.manual_seed(5)
    sizes = [100, 4, 250, 40]
    x = torch.randn(sum(sizes), 3, dtype=torch.float64)
    batch = uneven_batch(sizes)
    q = torch.randn(90, 3, dtype=torch.float64)
    bq = uneven_batch([30, 0, 50, 10])
    tree = [knn(x, 3, batch), knn(x, 3, batch, loop=True),
            knn(x, 3, batch, query=q, query_batch=bq)]
    monkeypatch.setattr(nb, '_use_dense', lambda t: True)
    monkeypatch.setattr(nb, '_CHUNK_BYTES', 4096)  # force many chunks
    dense = [knn(x, 3, batch), knn(x, 3, batch, loop=True),
             knn(x, 3, batch, query=q, query_batch=bq)]
    for a, b in zip(tree, dense):
        assert torch.equal(a, b)


# --------------------------------------------------------------------------
# radius
# --------------------------------------------------------------------------
@pytest.mark.parametrize('dtype', [torch.float32, torch.float64])
@pytest.mark.parametrize('loop', [False, True])
def test_radius_matches_brute_force(radius_path, dtype, loop):
    torch.manual_seed(6)
    sizes = [80, 1, 150, 30]
    x = torch.rand(sum(sizes), 3, dtype=dtype)
    batch = uneven_batch(sizes)
    for cap in (1000, 7):  # cap not hit / cap hit
        ei = radius(x, 0.3, batch, max_num_neighbors=cap, loop=loop)
        check_radius(ei, x, 0.3, cap, batch, loop)
    ei = radius(x, 0.3, None, max_num_neighbors=5, loop=loop)
    check_radius(ei, x, 0.3, 5, None, loop)


def test_radius_cap_keeps_nearest(radius_path):
    torch.manual_seed(7)
    x = torch.rand(300, 3, dtype=torch.float64)
    ei = radius(x, 0.5, max_num_neighbors=10)
    d, _, _ = brute(x, None, False)
    assert torch.bincount(ei[1], minlength=300).eq(10).all()
    kth = d.sort(dim=1).values[:, 9]  # 10th nearest distance per centre
    got = sqdist_rows(x[ei[1]], x[ei[0]])
    assert bool((got <= kth[ei[1]]).all())


def test_radius_query_mode_and_large_cap(radius_path):
    torch.manual_seed(8)
    x = torch.randn(200, 3, dtype=torch.float64)
    q = torch.randn(50, 3, dtype=torch.float64)
    bx, bq = uneven_batch([120, 80]), uneven_batch([0, 50])
    for cap in (3, 100, 10 ** 6):  # 10**6 uses the ball-query fallback
        ei = radius(x, 1.0, bx, cap, query=q, query_batch=bq)
        check_radius(ei, x, 1.0, cap, bx, query=q, query_batch=bq)
        ei = radius(x, 1.0, bx, cap)
        check_radius(ei, x, 1.0, cap, bx)
    ei = radius(x, 1.0, bx, 10 ** 6, loop=True)
    check_radius(ei, x, 1.0, 10 ** 6, bx, loop=True)


def test_radius_lattice_and_duplicates(radius_path):
    g = torch.arange(5, dtype=torch.float64)
    x = torch.cartesian_prod(g, g, g)
    x = torch.cat([x, x[:10]])
    # r = 1 and r = 2 are hit exactly by lattice distances: <= r is inclusive
    for r, cap in ((1.0, 100), (1.5, 100), (1.5, 4), (2.0, 200), (2.5, 30)):
        for loop in (False, True):
            check_radius(radius(x, r, None, cap, loop), x, r, cap, None, loop)


def test_radius_empty_and_isolated(radius_path):
    assert radius(torch.empty(0, 3), 1.0).shape == (2, 0)
    x = torch.tensor([[0., 0, 0], [10, 0, 0], [10.5, 0, 0]])
    ei = radius(x, 1.0)
    assert ei.tolist() == [[2, 1], [1, 2]]
    assert radius(x, 1.0, query=torch.empty(0, 3)).shape == (2, 0)


def test_radius_huge_radius_stays_in_example(radius_path):
    torch.manual_seed(9)
    x = torch.randn(40, 2)
    batch = uneven_batch([15, 25])
    for r in (1e30, 1e300):  # 1e300 overflows float32: still no padding
        ei = radius(x, r, batch, max_num_neighbors=100)
        check_radius(ei, x, r, 100, batch)
        assert ei.size(1) == 15 * 14 + 25 * 24


def test_radius_dense_equals_tree(monkeypatch):
    torch.manual_seed(10)
    sizes = [100, 3, 250, 40]
    x = torch.rand(sum(sizes), 3, dtype=torch.float64)
    batch = uneven_batch(sizes)
    q = torch.rand(90, 3, dtype=torch.float64)
    bq = uneven_batch([30, 0, 50, 10])
    calls = [dict(), dict(loop=True), dict(max_num_neighbors=5),
             dict(query=q, query_batch=bq)]
    tree = [radius(x, 0.2, batch, **c) for c in calls]
    monkeypatch.setattr(nb, '_use_dense', lambda t: True)
    monkeypatch.setattr(nb, '_CHUNK_BYTES', 4096)
    dense = [radius(x, 0.2, batch, **c) for c in calls]
    for a, b in zip(tree, dense):
        assert a.size(1) > 0 and torch.equal(a, b)


# --------------------------------------------------------------------------
# fps
# --------------------------------------------------------------------------
@pytest.mark.parametrize('dtype', [torch.float32, torch.float64])
@pytest.mark.parametrize('ratio', [0.1, 0.25, 0.5, 1.0])
def test_fps_matches_reference(path, dtype, ratio):
    torch.manual_seed(11)
    sizes = [30, 1, 77, 0, 50]
    x = torch.randn(sum(sizes), 3, dtype=dtype)
    batch = uneven_batch(sizes)
    idx = fps(x, ratio, batch, random_start=False)
    assert torch.equal(idx, fps_reference(x, ratio, batch))
    idx = fps(x, ratio, None, random_start=False)
    assert torch.equal(idx, fps_reference(x, ratio, None))


def test_fps_duplicates_and_ties(path):
    g = torch.arange(4, dtype=torch.float64)
    x = torch.cartesian_prod(g, g)
    x = torch.cat([x, x, x[:3]])  # every point twice or thrice
    idx = fps(x, 1.0, random_start=False)
    assert idx.numel() == x.size(0) and idx.unique().numel() == x.size(0)
    assert torch.equal(idx, fps_reference(x, 1.0, None))
    assert torch.equal(fps(x, 0.3, random_start=False),
                       fps_reference(x, 0.3, None))


def test_fps_random_start(path):
    torch.manual_seed(12)
    sizes = [30, 1, 77, 50, 9]
    x = torch.randn(sum(sizes), 3)
    batch = uneven_batch(sizes)
    ptr = [0] + np.cumsum(sizes).tolist()
    torch.manual_seed(123)
    a = fps(x, 0.3, batch)
    torch.manual_seed(123)
    b = fps(x, 0.3, batch)
    assert torch.equal(a, b)
    counts = [math.ceil(Fraction('0.3') * s) for s in sizes]
    assert a.numel() == sum(counts)
    assert a.unique().numel() == a.numel()
    firsts = []
    start = 0
    for e, c in enumerate(counts):
        chunk = a[start:start + c]
        assert bool((batch[chunk] == e).all())
        firsts.append(int(chunk[0]) - ptr[e])
        start += c
    # the random starts follow the reference from those starts
    assert torch.equal(a, fps_reference(x, 0.3, batch, firsts))
    # different seeds give different starts (with high probability)
    others = set()
    for seed in range(5):
        torch.manual_seed(seed)
        others.add(tuple(fps(x, 0.3, batch).tolist()))
    assert len(others) > 1


@pytest.mark.parametrize('ratio', [0.3, 1.0])
def test_fps_dense_equals_numba(monkeypatch, ratio):
    torch.manual_seed(13)
    sizes = [60, 1, 0, 140, 25]
    x = torch.randn(sum(sizes), 3, dtype=torch.float64)
    batch = uneven_batch(sizes)
    torch.manual_seed(0)
    numba_out = [fps(x, ratio, batch, random_start=False),
                 fps(x, ratio, batch), fps(x, ratio)]
    monkeypatch.setattr(nb, '_use_dense', lambda t: True)
    torch.manual_seed(0)
    dense_out = [fps(x, ratio, batch, random_start=False),
                 fps(x, ratio, batch), fps(x, ratio)]
    for a, b in zip(numba_out, dense_out):
        assert torch.equal(a, b)


def test_fps_count_rounding():
    x = torch.randn(100, 3)
    assert fps(x, 0.07).numel() == 7  # 0.07 * 100 is 7.000000000000001
    assert fps(x[:30], 0.11).numel() == 4
    assert fps(x[:1], 0.01).numel() == 1


# --------------------------------------------------------------------------
# bad input
# --------------------------------------------------------------------------
X = torch.randn(20, 3)
B2 = uneven_batch([10, 10])

BAD_CALLS = {
    'x not a tensor': lambda: knn(X.tolist(), 2),
    'x int64': lambda: knn(X.long(), 2),
    'x float16': lambda: radius(X.half(), 0.5),
    'x 1-d': lambda: knn(X[:, 0], 2),
    'x no columns': lambda: knn(X[:, :0], 2),
    'x nan': lambda: knn(torch.cat([X, torch.full((1, 3), math.nan)]), 2),
    'x inf': lambda: radius(torch.cat([X, torch.full((1, 3), math.inf)]), 1),
    'x huge': lambda: knn(X * 1e30, 2),
    'knn empty': lambda: knn(torch.empty(0, 3), 1),
    'k zero': lambda: knn(X, 0),
    'k negative': lambda: knn(X, -1),
    'k float': lambda: knn(X, 2.5),
    'k too large': lambda: knn(X, 20),
    'k too large batched': lambda: knn(X, 10, B2),
    'k too large one point': lambda: knn(X[:1], 1),
    'query dim': lambda: knn(X, 2, query=torch.randn(4, 2)),
    'query dtype': lambda: knn(X, 2, query=torch.randn(4, 3).double()),
    'query nan': lambda: knn(X, 2, query=torch.full((4, 3), math.nan)),
    'query_batch alone': lambda: knn(X, 2, query_batch=B2),
    'query_batch length': lambda: knn(X, 2, query=X, query_batch=B2[:5]),
    'batch int32': lambda: knn(X, 2, B2.int()),
    'batch float': lambda: radius(X, 1.0, B2.float()),
    'batch unsorted': lambda: knn(X, 2, B2.flip(0)),
    'batch length': lambda: knn(X, 2, B2[:-1]),
    'batch 2-d': lambda: knn(X, 2, B2[None]),
    'batch negative': lambda: knn(X, 2, B2 - 1),
    'batch device': lambda: knn(X, 2, B2.to('meta')),
    'r zero': lambda: radius(X, 0.0),
    'r negative': lambda: radius(X, -1.0),
    'r nan': lambda: radius(X, math.nan),
    'r inf': lambda: radius(X, math.inf),
    'r string': lambda: radius(X, 'big'),
    'max_num_neighbors zero': lambda: radius(X, 1.0, max_num_neighbors=0),
    'fps empty': lambda: fps(torch.empty(0, 3), 0.5),
    'fps ratio zero': lambda: fps(X, 0.0),
    'fps ratio big': lambda: fps(X, 1.5),
    'fps ratio nan': lambda: fps(X, math.nan),
    'fps ratio bool': lambda: fps(X, True),
    'fps int': lambda: fps(X.long(), 0.5),
    'fps nan': lambda: fps(torch.cat([X, torch.full((1, 3), math.nan)]), .5),
    'fps batch unsorted': lambda: fps(X, 0.5, B2.flip(0)),
}


@pytest.mark.parametrize('name', list(BAD_CALLS))
def test_bad_input_raises(path, name):
    with pytest.raises(ValueError) as info:
        BAD_CALLS[name]()
    assert len(str(info.value)) > 20  # a sentence, not a bare code


def test_error_messages_say_what_to_do():
    with pytest.raises(ValueError, match='lower k to at most 9'):
        knn(X, 10, B2)
    with pytest.raises(ValueError, match="'query_batch' must be sorted"):
        knn(X, 2, query=X, query_batch=B2.flip(0))
    with pytest.raises(ValueError, match="NaN or infinite"):
        knn(torch.cat([X, torch.full((1, 3), math.nan)]), 2)
    with pytest.raises(ValueError, match=r"'ratio' must be in \(0, 1\]"):
        fps(X, 2.0)


# --------------------------------------------------------------------------
# property test: malformed input -> ValueError or a valid result
# --------------------------------------------------------------------------
VALUES = [0.0, 1.0, -1.0, 0.5, 2.0, 1e-3, math.nan, math.inf, -math.inf]


@st.composite
def clouds(draw):
    n = draw(st.integers(0, 12))
    d = draw(st.sampled_from([1, 2, 3]))
    vals = draw(st.lists(st.sampled_from(VALUES) | st.floats(-3, 3),
                         min_size=n * d, max_size=n * d))
    dtype = draw(st.sampled_from([torch.float32, torch.float64,
                                  torch.float16, torch.int64]))
    x = torch.tensor(vals, dtype=torch.float64).view(n, d)
    if dtype == torch.int64:
        x = torch.nan_to_num(x).clamp(-5, 5).long()
    else:
        x = x.to(dtype)
    if draw(st.booleans()) and n > 0:  # duplicate rows
        x = torch.cat([x, x[:draw(st.integers(1, n))]])
    if draw(st.integers(0, 9)) == 0:  # wrong shape
        x = x.reshape(-1)
    num = x.size(0) if x.dim() > 0 else 0
    kind = draw(st.sampled_from(['none', 'sorted', 'unsorted', 'short']))
    batch = None
    if kind != 'none':
        batch = torch.tensor(sorted(draw(st.lists(
            st.integers(0, 3), min_size=num, max_size=num))),
            dtype=torch.long)
        if kind == 'unsorted' and num > 1:
            batch = batch.flip(0)
        if kind == 'short':
            batch = batch[:-1] if num > 0 else torch.zeros(1, dtype=torch.long)
    return x, batch


@settings(max_examples=80, deadline=None,
          suppress_health_check=[HealthCheck.too_slow])
@given(data=clouds(), k=st.integers(-1, 6), loop=st.booleans(),
       fn=st.sampled_from(['knn', 'radius', 'fps', 'knn_query']),
       dense=st.booleans(), r=st.sampled_from([0.0, 0.3, 1.5, 1e9, -1.0]),
       ratio=st.sampled_from([0.0, 0.3, 1.0, 1.2]))
def test_property_malformed_inputs(data, k, loop, fn, dense, r, ratio):
    x, batch = data
    old = nb._use_dense
    nb._use_dense = (lambda t: True) if dense else old
    try:
        if fn == 'knn':
            out = knn(x, k, batch, loop=loop)
        elif fn == 'knn_query':
            out = knn(x, k, batch, query=x[:3] if x.dim() == 2 else x,
                      query_batch=None if batch is None else batch[:3])
        elif fn == 'radius':
            out = radius(x, r, batch, max_num_neighbors=k, loop=loop)
        else:
            out = fps(x, ratio, batch)
    except ValueError:
        return
    finally:
        nb._use_dense = old
    # a result: the input was valid
    assert x.dtype in (torch.float32, torch.float64) and x.dim() == 2
    assert bool(torch.isfinite(x).all())
    num = x.size(0)
    b = torch.zeros(num, dtype=torch.long) if batch is None else batch
    assert out.dtype == torch.long
    if fn == 'fps':
        assert 0 < ratio <= 1 and out.numel() >= 1
        assert out.unique().numel() == out.numel()
        assert int(out.min()) >= 0 and int(out.max()) < num
        counts = torch.bincount(b[out], minlength=int(b.max()) + 1)
        sizes = torch.bincount(b, minlength=int(b.max()) + 1)
        want = torch.tensor([math.ceil(Fraction(str(ratio)) * int(s))
                             for s in sizes])
        assert torch.equal(counts, want)
        return
    assert out.dim() == 2 and out.size(0) == 2
    if out.numel() == 0:
        assert fn == 'radius' or num == 0
        return
    assert int(out[0].min()) >= 0 and int(out[0].max()) < num
    if fn == 'knn_query':
        qb = torch.zeros(min(3, num), dtype=torch.long) if batch is None \
            else b[:3]
        assert torch.equal(b[out[0]], qb[out[1]])
        check_knn(out, x, k, b, query=x[:3], query_batch=qb, exact=False)
    else:
        assert torch.equal(b[out[0]], b[out[1]])
        if fn == 'knn':
            check_knn(out, x, k, b, loop, exact=False)
        else:
            assert int(torch.bincount(out[1]).max()) <= k
            assert torch.unique(out[1] * num + out[0]).numel() == out.size(1)
            if not loop:
                assert bool((out[0] != out[1]).all())
            if not (dense and x.dtype == torch.float32):  # exact on CPU
                check_radius(out, x, r, k, b, loop)


def test_radius_finds_coincident_points():
    # all points in one place: the search reach used to collapse to zero
    # and even the self-pairs were lost
    from tg_intrinsic.geometry import radius
    for n in (1, 2, 5):
        edge_index = radius(torch.zeros(n, 3, dtype=torch.float64), 0.5,
                            max_num_neighbors=n, loop=True)
        assert edge_index.size(1) == n * n
        assert radius(torch.zeros(n, 3), 0.5, max_num_neighbors=n,
                      loop=False).size(1) == n * (n - 1)


# ----------------------------------------------------------------------
# One tie-break rule: the tree (CPU) and the grid (GPU) give one graph

def _brute_knn(x, k, batch=None, loop=False, query=None, query_batch=None):
    """The rule by brute force: float64 squared distance summed coordinate
    by coordinate, ties by index, within the example."""
    xn = x.double().numpy()
    qn = xn if query is None else query.double().numpy()
    bx = np.zeros(len(xn), int) if batch is None else batch.numpy()
    bq = bx if query is None else (np.zeros(len(qn), int)
                                   if query_batch is None
                                   else query_batch.numpy())
    nbr = []
    for i in range(len(qn)):
        key = (xn[:, 0] - qn[i, 0]) ** 2
        for j in range(1, xn.shape[1]):
            key += (xn[:, j] - qn[i, j]) ** 2
        key[bx != bq[i]] = np.inf
        if query is None and not loop:
            key[i] = np.inf
        nbr.append(np.lexsort((np.arange(len(xn)), key))[:k])
    nbr = np.concatenate(nbr)
    return torch.from_numpy(np.stack([nbr, np.repeat(np.arange(len(qn)),
                                                     k)]))


def _lattice(n=6):
    axis = torch.arange(n, dtype=torch.float64)
    return torch.cartesian_prod(axis, axis, axis)


CLOUDS = {
    'random': lambda: (torch.randn(600, 3, dtype=torch.float64), None),
    'sphere surface': lambda: (torch.nn.functional.normalize(
        torch.randn(800, 3), dim=1), None),
    'lattice (ties)': lambda: (_lattice(), None),
    'duplicates': lambda: (torch.randn(100, 3).repeat(3, 1), None),
    'batch of sizes': lambda: (torch.randn(450, 3, dtype=torch.float64),
                               torch.tensor([0] * 100 + [1] * 300
                                            + [2] * 50)),
    'flat': lambda: (torch.cat([torch.rand(300, 2), torch.zeros(300, 1)],
                               1), None),
}


@pytest.mark.parametrize('name', list(CLOUDS))
@pytest.mark.parametrize('loop', [False, True])
def test_tree_and_grid_follow_one_rule(name, loop):
    torch.manual_seed(0)
    x, batch = CLOUDS[name]()
    k = 7
    expected = _brute_knn(x, k, batch, loop)
    assert torch.equal(knn(x, k, batch, loop), expected)  # the tree
    length = 1 if batch is None else int(batch.max()) + 1
    grid = nb._knn_grid(x, k, batch, loop, None, None, length)
    assert torch.equal(grid, expected)


def test_grid_with_queries_outside_and_small_cells(monkeypatch):
    torch.manual_seed(1)
    x = torch.randn(500, 3, dtype=torch.float64)
    batch = torch.tensor([0] * 200 + [1] * 300)
    query = 3 * torch.randn(90, 3, dtype=torch.float64)  # many outside
    query_batch = torch.tensor([0] * 40 + [1] * 50)
    expected = _brute_knn(x, 5, batch, query=query, query_batch=query_batch)
    assert torch.equal(knn(x, 5, batch, query=query,
                           query_batch=query_batch), expected)
    # tiny chunks and cells: the rings, the fallback and the chunking
    monkeypatch.setattr(nb, '_GRID_CHUNK', 64)
    monkeypatch.setattr(nb, '_CELL_SHARE', 0.05)
    grid = nb._knn_grid(x, 5, batch, False, query, query_batch, 2)
    assert torch.equal(grid, expected)
