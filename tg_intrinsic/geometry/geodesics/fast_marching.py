r"""Truncated fast marching on triangle meshes (numba), the geodesic distance
behind :func:`tg_intrinsic.geometry.geodesic_neighbourhoods` and the patches
of the vector heat log maps.

Dijkstra's order over vertices, with the update of Kimmel and Sethian (1998)
through triangles: when two corners :math:`a, b` of a triangle are final,
the triangle is unfolded into the plane, a virtual point source :math:`s` is
placed at distances :math:`d_a, d_b` from :math:`a, b` on the far side of
edge :math:`ab`, and the third corner :math:`c` gets

.. math::
    d_c = \min\left(\|c - s\|,\; d_a + \|c - a\|,\; d_b + \|c - b\|\right),

where :math:`\|c - s\|` only counts if the straight segment from :math:`s` to
:math:`c` crosses edge :math:`ab` (otherwise the shortest path runs through
a corner, which the edge terms cover). Marching fixes a vertex before the
far corners of an obtuse triangle on its shortest path are known and then
takes a longer path; such vertices are updated again when those corners
become final, and a few relaxation sweeps over the marched vertices (in
marching order) redo all triangle updates with final corners. The result is
exact on flat meshes except for rare pairs whose path crosses several
obtuse triangles (at most 2 % too long on a strongly jittered grid), and
first-order accurate on curved ones; plain Dijkstra on edges overestimates
distances by up to 15 % even on regular meshes.
"""
import numpy as np
from numba import get_num_threads, prange

from ..heap import sift_down, sift_up
from ..jit import jit

# At most this many relaxation sweeps after marching (see :func:`march`):
# on a jittered flat grid 3 leave 2 % worst-case error (16 leave none) and
# cost about as much as the marching itself.
SWEEPS = 3


def surface_index(pos: np.ndarray, face: np.ndarray):
    """What marching needs: CSR lists of the (triangle, corner) pairs around
    every vertex and the length of every triangle edge (``length[f, k]``
    from corner k to corner k + 1). ``face`` is [F, 3]."""
    num = pos.shape[0]
    corner_vertex = face.reshape(-1)
    order = np.argsort(corner_vertex, kind='stable')
    ptr = np.zeros(num + 1, dtype=np.int64)
    np.cumsum(np.bincount(corner_vertex, minlength=num), out=ptr[1:])
    length = np.linalg.norm(pos[np.roll(face, -1, axis=1)] - pos[face],
                            axis=2)
    return (ptr, (order // 3).astype(np.int64),
            (order % 3).astype(np.int64), np.ascontiguousarray(length))


@jit
def _unfold(ab, ac, bc, da, db):  # pragma: no cover (numba)
    """Distance to corner c of a triangle with edge lengths ``ab``, ``ac``,
    ``bc`` from a virtual source seen at ``da`` from a and ``db`` from b;
    inf when the straight path misses edge ab."""
    xc = (ac * ac - bc * bc + ab * ab) / (2.0 * ab)
    yc2 = ac * ac - xc * xc
    yc = np.sqrt(yc2) if yc2 > 0.0 else 0.0
    xs = (da * da - db * db + ab * ab) / (2.0 * ab)
    ys2 = da * da - xs * xs
    if ys2 < 0.0:  # da, db, |ab| violate the triangle inequality
        return np.inf
    ys = -np.sqrt(ys2)  # the source lies on the other side of ab than c
    dy = yc - ys
    if dy <= 0.0:
        return np.inf
    x_cross = xs + (xc - xs) * (-ys / dy)
    if x_cross < 0.0 or x_cross > ab:
        return np.inf
    return np.sqrt((xc - xs) ** 2 + dy * dy)


@jit
def march(face, length, vf_ptr, vf_face, vf_corner, sources, limit, cap,
          tol, dist, final, touched, where, out_v,
          out_d):  # pragma: no cover (numba)
    """Fast marching from the vertices ``sources`` (all at distance 0) until
    the next distance is ``>= limit`` or ``cap`` vertices are final, then
    relaxation sweeps until no distance drops by more than ``tol`` (at most
    :data:`SWEEPS`). Writes the final vertices and their distances (in the
    order they became final) to ``out_v``/``out_d`` and returns how many.
    ``dist`` (all inf), ``final`` (all False), ``touched`` and ``where``
    are scratch arrays of length N; the first two are restored on return.

    For vertex v at corner s of triangle f, the other corners are
    a = corner s + 1 and b = corner s + 2, with |va| = length[f, s],
    |ab| = length[f, s + 1] and |bv| = length[f, s + 2] (indices mod 3)."""
    size = 64
    while size < sources.shape[0]:
        size *= 2
    hd = np.empty(size)
    hv = np.empty(size, dtype=np.int64)
    heap = 0
    num_touched = 0
    count = 0
    for k in range(sources.shape[0]):
        v = sources[k]
        if dist[v] == 0.0:
            continue  # a repeated source
        dist[v] = 0.0
        touched[num_touched] = v
        num_touched += 1
        hd[heap] = 0.0
        hv[heap] = v
        heap += 1
    while heap > 0:
        d = hd[0]
        v = hv[0]
        heap -= 1
        hd[0] = hd[heap]
        hv[0] = hv[heap]
        sift_down(hd, hv, 0, heap)
        if final[v] or d > dist[v]:
            continue  # a stale heap entry (lazy deletion)
        if d >= limit:
            break
        final[v] = True
        where[v] = count
        out_v[count] = v
        out_d[count] = d
        count += 1
        if count >= cap:
            break
        for e in range(vf_ptr[v], vf_ptr[v + 1]):
            f = vf_face[e]
            s = vf_corner[e]
            s1 = (s + 1) % 3
            s2 = (s + 2) % 3
            va = length[f, s]
            ab = length[f, s1]
            bv = length[f, s2]
            for side in range(2):
                if side == 0:  # update a through (v, b)
                    w, o, vw, vo = face[f, s1], face[f, s2], va, bv
                else:  # update b through (v, a)
                    w, o, vw, vo = face[f, s2], face[f, s1], bv, va
                if final[w]:
                    # A vertex fixed before both far corners of this
                    # (obtuse) triangle were known: improve it now.
                    if final[o] and dist[w] > 0.0:
                        t = _unfold(vo, vw, ab, d, dist[o])
                        if t < dist[w]:
                            dist[w] = t
                            out_d[where[w]] = t
                    continue
                cand = d + vw
                if final[o]:
                    t = _unfold(vo, vw, ab, d, dist[o])
                    if t < cand:
                        cand = t
                if cand < dist[w]:
                    if dist[w] == np.inf:
                        touched[num_touched] = w
                        num_touched += 1
                    dist[w] = cand
                    if heap == size:
                        size *= 2
                        hd2 = np.empty(size)
                        hv2 = np.empty(size, dtype=np.int64)
                        hd2[:heap] = hd[:heap]
                        hv2[:heap] = hv[:heap]
                        hd = hd2
                        hv = hv2
                    hd[heap] = cand
                    hv[heap] = w
                    sift_up(hd, hv, heap)
                    heap += 1
    # Relaxation sweeps (Gauss-Seidel in marching order) for what the
    # updates above did not reach: redo every triangle update with final
    # corners, until no distance drops by more than ``tol``.
    for _ in range(SWEEPS):
        changed = False
        for t in range(count):
            v = out_v[t]
            before = dist[v]
            if before == 0.0:
                continue
            for e in range(vf_ptr[v], vf_ptr[v + 1]):
                f = vf_face[e]
                s = vf_corner[e]
                a = face[f, (s + 1) % 3]
                b = face[f, (s + 2) % 3]
                if final[a] and final[b]:
                    t2 = _unfold(length[f, (s + 1) % 3], length[f, s],
                                 length[f, (s + 2) % 3], dist[a], dist[b])
                    if t2 < dist[v]:
                        dist[v] = t2
            out_d[t] = dist[v]
            if before - dist[v] > tol:
                changed = True
        if not changed:
            break
    for t in range(num_touched):
        dist[touched[t]] = np.inf
        final[touched[t]] = False
    return count


@jit(parallel=True)
def march_many(face, length, vf_ptr, vf_face, vf_corner, num, sources, limit,
               keep, cap, tol, slot, out_v, out_d, count,
               blocks):  # pragma: no cover (numba)
    """:func:`march` from every source in parallel. Row ``k`` of
    ``out_v``/``out_d`` (width ``slot``) receives the first ``slot`` results
    of source ``k`` closer than ``keep`` sorted by distance (marching runs
    to ``limit >= keep``); ``count[k]`` the full count, so that rows that
    did not fit can be redone with a wider slot. The sources are split into
    ``blocks`` parallel tasks; ``num`` is the number of vertices."""
    m = sources.shape[0]
    blocks = max(1, min(m, blocks))
    for blk in prange(blocks):
        # Scratch per block, not per source: O(N) allocations stay rare.
        dist = np.full(num, np.inf)
        final = np.zeros(num, dtype=np.bool_)
        touched = np.empty(num, dtype=np.int64)
        where = np.empty(num, dtype=np.int64)
        acc_v = np.empty(num, dtype=np.int64)
        acc_d = np.empty(num)
        for k in range(blk * m // blocks, (blk + 1) * m // blocks):
            got = march(face, length, vf_ptr, vf_face, vf_corner,
                        sources[k:k + 1], limit, cap, tol, dist, final,
                        touched, where, acc_v, acc_d)
            order = np.argsort(acc_d[:got], kind='mergesort')
            # Marched past ``keep`` so that the sweeps near it have final
            # corners on both sides; keep only what is within ``keep``.
            while got > 0 and acc_d[order[got - 1]] >= keep:
                got -= 1
            count[k] = got
            for t in range(min(got, slot)):
                out_v[k, t] = acc_v[order[t]]
                out_d[k, t] = acc_d[order[t]]


def _blocks() -> int:
    # A few tasks per thread balance uneven neighbourhood sizes.
    return 8 * get_num_threads()


def march_from(face: np.ndarray, index, sources: np.ndarray, limit: float,
               cap: int, slack: float = 0.0, tol: float = 0.0):
    """Truncated fast marching from every source (``index`` from
    :func:`surface_index`). Returns ``(ptr, nbr, dist)``: the vertices of
    source ``k`` closer than ``limit`` (at most ``cap``, the nearest) are
    ``nbr[ptr[k]:ptr[k + 1]]``, sorted by distance. Marching goes ``slack``
    further, so that the relaxation sweeps can also correct vertices near
    ``limit``; sweeps stop when no distance drops by more than ``tol``."""
    vf_ptr, vf_face, vf_corner, length = index
    n = vf_ptr.shape[0] - 1
    m = sources.shape[0]
    cap = int(min(cap, n))
    if m == 0:
        return (np.zeros(1, dtype=np.int64), np.zeros(0, dtype=np.int64),
                np.zeros(0))

    def run(src, slot, out_v, out_d, cnt):
        march_many(face, length, vf_ptr, vf_face, vf_corner, n, src,
                   limit + slack, limit, cap, tol, slot, out_v, out_d, cnt,
                   8 * get_num_threads())  # a few tasks per thread

    # Size the output rows from a sample, then redo the few that overflow.
    probe = sources[np.linspace(0, m - 1, min(m, 32)).astype(np.int64)]
    cnt = np.zeros(probe.shape[0], dtype=np.int64)
    run(probe, 0, np.empty((probe.shape[0], 0), np.int64),
        np.empty((probe.shape[0], 0)), cnt)
    slot = int(min(cap, int(cnt.max() * 1.25) + 8))
    rows = max(1, (1 << 24) // max(slot, 1))  # about 256 MB per chunk
    parts_v, parts_d, counts = [], [], []
    for start in range(0, m, rows):
        src = sources[start:start + rows]
        out_v = np.empty((src.shape[0], slot), dtype=np.int64)
        out_d = np.empty((src.shape[0], slot))
        cnt = np.zeros(src.shape[0], dtype=np.int64)
        run(src, slot, out_v, out_d, cnt)
        over = np.flatnonzero(cnt > slot)
        mask = np.arange(slot)[None, :] < cnt[:, None]
        vals_v, vals_d = out_v[mask], out_d[mask]
        if over.size:
            wide = int(cnt[over].max())
            ov = np.empty((over.size, wide), dtype=np.int64)
            od = np.empty((over.size, wide))
            run(src[over], wide, ov, od, np.zeros(over.size, np.int64))
            # Splice the redone rows in place of their truncated versions.
            row_ptr = np.concatenate([[0], np.cumsum(np.minimum(cnt, slot))])
            pieces_v, pieces_d, last = [], [], 0
            for t, r in enumerate(over):  # a loop over the few overflows
                pieces_v += [vals_v[row_ptr[last]:row_ptr[r]],
                             ov[t, :cnt[r]]]
                pieces_d += [vals_d[row_ptr[last]:row_ptr[r]],
                             od[t, :cnt[r]]]
                last = r + 1
            pieces_v.append(vals_v[row_ptr[last]:])
            pieces_d.append(vals_d[row_ptr[last]:])
            vals_v, vals_d = np.concatenate(pieces_v), np.concatenate(pieces_d)
        parts_v.append(vals_v)
        parts_d.append(vals_d)
        counts.append(cnt)
    count = np.concatenate(counts)
    ptr = np.zeros(m + 1, dtype=np.int64)
    np.cumsum(count, out=ptr[1:])
    return ptr, np.concatenate(parts_v), np.concatenate(parts_d)


def march_one(face: np.ndarray, index, sources, limit: float,
              tol: float = 0.0):
    """Vertices within ``limit`` of the nearest of ``sources`` and their
    distances, in marching order."""
    vf_ptr, vf_face, vf_corner, length = index
    n = vf_ptr.shape[0] - 1
    out_v = np.empty(n, dtype=np.int64)
    out_d = np.empty(n)
    sources = np.atleast_1d(np.asarray(sources, dtype=np.int64))
    got = march(face, length, vf_ptr, vf_face, vf_corner, sources,
                float(limit), n, tol, np.full(n, np.inf),
                np.zeros(n, dtype=np.bool_), np.empty(n, dtype=np.int64),
                np.empty(n, dtype=np.int64), out_v, out_d)
    return out_v[:got], out_d[:got]
