"""Quadric-error edge-collapse decimation of closed manifold triangle meshes.

Private helper of the synthetic datasets (numba). Garland-Heckbert quadrics
(area weighted) plus a small edge-length term that favours well shaped
triangles, with multiple-choice edge selection (no priority queue). A
collapse is only done when it keeps the mesh a closed 2-manifold of the same
topology (link condition: the two end points share exactly the two opposite
vertices of their common triangles), does not flip or nearly flip a
triangle, and does not create a needle triangle.
"""
import numpy as np

from tg_intrinsic.geometry.jit import jit


@jit
def _tri_normal(ax, ay, az, bx, by, bz, cx, cy, cz):
    ux, uy, uz = bx - ax, by - ay, bz - az
    vx, vy, vz = cx - ax, cy - ay, cz - az
    return uy * vz - uz * vy, uz * vx - ux * vz, ux * vy - uy * vx


@jit
def _quality(ax, ay, az, bx, by, bz, cx, cy, cz):
    nx, ny, nz = _tri_normal(ax, ay, az, bx, by, bz, cx, cy, cz)
    area2 = np.sqrt(nx * nx + ny * ny + nz * nz)  # twice the area
    s = ((bx - ax) ** 2 + (by - ay) ** 2 + (bz - az) ** 2
         + (cx - bx) ** 2 + (cy - by) ** 2 + (cz - bz) ** 2
         + (ax - cx) ** 2 + (ay - cy) ** 2 + (az - cz) ** 2)
    if s <= 0.0:
        return 0.0
    return 2.0 * np.sqrt(3.0) * area2 / s  # 1 for equilateral


@jit
def _qeval(Q, x, y, z):
    return (Q[0] * x * x + 2 * Q[1] * x * y + 2 * Q[2] * x * z + 2 * Q[3] * x
            + Q[4] * y * y + 2 * Q[5] * y * z + 2 * Q[6] * y
            + Q[7] * z * z + 2 * Q[8] * z + Q[9])


@jit
def _edge_cost(Q, V, u, v, lam, out, q):
    for t in range(10):
        q[t] = Q[u, t] + Q[v, t]
    a00, a01, a02, a11, a12, a22 = q[0], q[1], q[2], q[4], q[5], q[7]
    b0, b1, b2 = -q[3], -q[6], -q[8]
    c00 = a11 * a22 - a12 * a12
    c01 = a02 * a12 - a01 * a22
    c02 = a01 * a12 - a02 * a11
    det = a00 * c00 + a01 * c01 + a02 * c02
    scale = (a00 + a11 + a22)
    best = 1e300
    bx = by = bz = 0.0
    ex = V[u, 0] - V[v, 0]
    ey = V[u, 1] - V[v, 1]
    ez = V[u, 2] - V[v, 2]
    elen2 = ex * ex + ey * ey + ez * ez
    if scale > 0 and abs(det) > 1e-9 * scale * scale * scale:
        c11 = a00 * a22 - a02 * a02
        c12 = a01 * a02 - a00 * a12
        c22 = a00 * a11 - a01 * a01
        x = (c00 * b0 + c01 * b1 + c02 * b2) / det
        y = (c01 * b0 + c11 * b1 + c12 * b2) / det
        z = (c02 * b0 + c12 * b1 + c22 * b2) / det
        # keep the optimum close to the edge (robustness)
        mx = 0.5 * (V[u, 0] + V[v, 0])
        my = 0.5 * (V[u, 1] + V[v, 1])
        mz = 0.5 * (V[u, 2] + V[v, 2])
        if (x - mx) ** 2 + (y - my) ** 2 + (z - mz) ** 2 <= elen2:
            best = _qeval(q, x, y, z)
            bx, by, bz = x, y, z
    for s in range(3):
        t = 0.5 * s
        x = V[u, 0] * (1 - t) + V[v, 0] * t
        y = V[u, 1] * (1 - t) + V[v, 1] * t
        z = V[u, 2] * (1 - t) + V[v, 2] * t
        c = _qeval(q, x, y, z)
        if c < best:
            best = c
            bx, by, bz = x, y, z
    out[0] = bx
    out[1] = by
    out[2] = bz
    return max(best, 0.0) + lam * elen2 * elen2


@jit
def _plane_quadrics(V, F):
    Q = np.zeros((V.shape[0], 10))
    for f in range(F.shape[0]):
        a, b, c = F[f, 0], F[f, 1], F[f, 2]
        nx, ny, nz = _tri_normal(V[a, 0], V[a, 1], V[a, 2], V[b, 0], V[b, 1],
                                 V[b, 2], V[c, 0], V[c, 1], V[c, 2])
        l = np.sqrt(nx * nx + ny * ny + nz * nz)
        if l <= 0.0:
            continue
        area = 0.5 * l
        nx /= l
        ny /= l
        nz /= l
        d = -(nx * V[a, 0] + ny * V[a, 1] + nz * V[a, 2])
        for w in (a, b, c):
            Q[w, 0] += area * nx * nx
            Q[w, 1] += area * nx * ny
            Q[w, 2] += area * nx * nz
            Q[w, 3] += area * nx * d
            Q[w, 4] += area * ny * ny
            Q[w, 5] += area * ny * nz
            Q[w, 6] += area * ny * d
            Q[w, 7] += area * nz * nz
            Q[w, 8] += area * nz * d
            Q[w, 9] += area * d * d
    return Q


@jit
def _link_ok(F, falive, head, nxt, mark, mark2, stamp, u, v):
    """Link condition for a closed manifold: u and v share exactly the two
    opposite vertices of their two common triangles."""
    c = head[u]
    while c >= 0:
        f = c // 3
        if falive[f]:
            for s in range(3):
                mark[F[f, s]] = stamp
        c = nxt[c]
    common = 0
    shared = 0
    c = head[v]
    while c >= 0:
        f = c // 3
        if falive[f]:
            if F[f, 0] == u or F[f, 1] == u or F[f, 2] == u:
                shared += 1
            for s in range(3):
                w = F[f, s]
                if w != u and w != v and mark[w] == stamp \
                        and mark2[w] != stamp:
                    mark2[w] = stamp
                    common += 1
        c = nxt[c]
    return common == 2 and shared == 2


@jit
def _geometry_ok(V, F, falive, head, nxt, u, v, px, py, pz, min_quality,
                 max_normal_turn):
    """No triangle around the collapse flips (turns by more than
    acos(max_normal_turn)) or becomes a needle worse than ``min_quality``."""
    for rep in range(2):
        w0 = u if rep == 0 else v
        c = head[w0]
        while c >= 0:
            f = c // 3
            c = nxt[c]
            if not falive[f]:
                continue
            a, b, cc = F[f, 0], F[f, 1], F[f, 2]
            if (a == u or b == u or cc == u) and (a == v or b == v or cc == v):
                continue  # removed by the collapse
            ax, ay, az = V[a, 0], V[a, 1], V[a, 2]
            bx, by, bz = V[b, 0], V[b, 1], V[b, 2]
            cx, cy, cz = V[cc, 0], V[cc, 1], V[cc, 2]
            n0x, n0y, n0z = _tri_normal(ax, ay, az, bx, by, bz, cx, cy, cz)
            q0 = _quality(ax, ay, az, bx, by, bz, cx, cy, cz)
            if a == w0:
                ax, ay, az = px, py, pz
            elif b == w0:
                bx, by, bz = px, py, pz
            else:
                cx, cy, cz = px, py, pz
            n1x, n1y, n1z = _tri_normal(ax, ay, az, bx, by, bz, cx, cy, cz)
            q1 = _quality(ax, ay, az, bx, by, bz, cx, cy, cz)
            l0 = np.sqrt(n0x * n0x + n0y * n0y + n0z * n0z)
            l1 = np.sqrt(n1x * n1x + n1y * n1y + n1z * n1z)
            if q1 < min_quality and q1 < q0:
                return False
            if l1 <= 0.0:
                return False
            if q0 > 1e-3 and (n0x * n1x + n0y * n1y + n0z * n1z) \
                    < max_normal_turn * l0 * l1:
                return False
    return True


@jit
def decimate(V, F, target, seed=0, lam=0.05, min_quality=0.05,
             max_normal_turn=0.3, choices=8):
    """Collapses edges of the closed manifold mesh ``(V, F)`` until it has
    ``target`` vertices (or no valid collapse can be found).

    Multiple-choice scheme (Wu and Kobbelt 2002): every step draws
    ``choices`` random edges and collapses the one of smallest cost (area
    weighted quadric error plus ``lam`` times the fourth power of the
    edge length) to its optimal position, if the collapse is valid.
    Deterministic for a given ``seed``. Returns ``(V', F')`` compacted.
    """
    np.random.seed(seed)
    V = V.copy()
    F = F.copy()
    nv = V.shape[0]
    nf = F.shape[0]
    Q = _plane_quadrics(V, F)
    # corner linked lists: corner c = 3 f + s belongs to vertex F[f, s]
    head = -np.ones(nv, dtype=np.int64)
    tail = -np.ones(nv, dtype=np.int64)
    nxt = -np.ones(3 * nf, dtype=np.int64)
    for c in range(3 * nf - 1, -1, -1):
        w = F[c // 3, c % 3]
        if head[w] < 0:
            tail[w] = c
        nxt[c] = head[w]
        head[w] = c
    falive = np.ones(nf, dtype=np.bool_)
    valive = np.ones(nv, dtype=np.bool_)
    # alive faces as a list with O(1) removal, to draw random edges
    flist = np.arange(nf)
    fpos = np.arange(nf)
    nfl = nf
    mark = np.zeros(nv, dtype=np.int64)
    mark2 = np.zeros(nv, dtype=np.int64)
    stamp = 0
    opt = np.empty(3)
    best_opt = np.empty(3)
    qbuf = np.empty(10)

    alive = nv
    failures = 0
    while alive > target and alive > 4 and failures < 2000:
        best = 1e300
        bu = -1
        bv = -1
        for k in range(choices):
            f = flist[np.random.randint(nfl)]
            s = np.random.randint(3)
            u = F[f, s]
            v = F[f, (s + 1) % 3]
            cost = _edge_cost(Q, V, u, v, lam, opt, qbuf)
            if cost < best:
                best = cost
                bu = u
                bv = v
                best_opt[0] = opt[0]
                best_opt[1] = opt[1]
                best_opt[2] = opt[2]
        u = bu
        v = bv
        stamp += 1
        if not _link_ok(F, falive, head, nxt, mark, mark2, stamp, u, v):
            failures += 1
            continue
        px, py, pz = best_opt[0], best_opt[1], best_opt[2]
        if not _geometry_ok(V, F, falive, head, nxt, u, v, px, py, pz,
                            min_quality, max_normal_turn):
            failures += 1
            continue
        failures = 0
        # ---- collapse v into u ----
        c = head[v]
        while c >= 0:
            f = c // 3
            if falive[f]:
                if F[f, 0] == u or F[f, 1] == u or F[f, 2] == u:
                    falive[f] = False
                    nfl -= 1
                    last = flist[nfl]
                    flist[fpos[f]] = last
                    fpos[last] = fpos[f]
                else:
                    F[f, c % 3] = u
            c = nxt[c]
        nxt[tail[u]] = head[v]
        tail[u] = tail[v]
        head[v] = -1
        valive[v] = False
        alive -= 1
        V[u, 0] = px
        V[u, 1] = py
        V[u, 2] = pz
        for t in range(10):
            Q[u, t] += Q[v, t]
        # drop dead corners from the list of u
        prev = -1
        c = head[u]
        while c >= 0:
            cn = nxt[c]
            if not falive[c // 3]:
                if prev < 0:
                    head[u] = cn
                else:
                    nxt[prev] = cn
            else:
                prev = c
            c = cn
        tail[u] = prev

    # compact
    remap = -np.ones(nv, dtype=np.int64)
    k = 0
    for w in range(nv):
        if valive[w]:
            remap[w] = k
            k += 1
    Vout = np.empty((k, 3))
    for w in range(nv):
        if valive[w]:
            Vout[remap[w]] = V[w]
    Fout = np.empty((nfl, 3), dtype=np.int64)
    m = 0
    for f in range(nf):
        if falive[f]:
            Fout[m, 0] = remap[F[f, 0]]
            Fout[m, 1] = remap[F[f, 1]]
            Fout[m, 2] = remap[F[f, 2]]
            m += 1
    return Vout, Fout


@jit
def _segment_hits_triangle(V, p, q, a, b, c):
    """Whether segment V[p]V[q] crosses triangle (a, b, c) (Moller-Trumbore,
    parallel configurations count as no hit)."""
    ox, oy, oz = V[p, 0], V[p, 1], V[p, 2]
    dx, dy, dz = V[q, 0] - ox, V[q, 1] - oy, V[q, 2] - oz
    e1x, e1y, e1z = V[b, 0] - V[a, 0], V[b, 1] - V[a, 1], V[b, 2] - V[a, 2]
    e2x, e2y, e2z = V[c, 0] - V[a, 0], V[c, 1] - V[a, 1], V[c, 2] - V[a, 2]
    hx = dy * e2z - dz * e2y
    hy = dz * e2x - dx * e2z
    hz = dx * e2y - dy * e2x
    det = e1x * hx + e1y * hy + e1z * hz
    scale = (abs(e1x) + abs(e1y) + abs(e1z)) * (abs(e2x) + abs(e2y)
                                                + abs(e2z)) \
        * (abs(dx) + abs(dy) + abs(dz))
    if abs(det) <= 1e-12 * scale:
        return False
    inv = 1.0 / det
    sx, sy, sz = ox - V[a, 0], oy - V[a, 1], oz - V[a, 2]
    u = (sx * hx + sy * hy + sz * hz) * inv
    if u < 0.0 or u > 1.0:
        return False
    qx = sy * e1z - sz * e1y
    qy = sz * e1x - sx * e1z
    qz = sx * e1y - sy * e1x
    v = (dx * qx + dy * qy + dz * qz) * inv
    if v < 0.0 or u + v > 1.0:
        return False
    t = (e2x * qx + e2y * qy + e2z * qz) * inv
    return 0.0 <= t <= 1.0


@jit
def _triangles_intersect(V, F, f, g):
    for s in range(3):
        if _segment_hits_triangle(V, F[f, s], F[f, (s + 1) % 3], F[g, 0],
                                  F[g, 1], F[g, 2]):
            return True
        if _segment_hits_triangle(V, F[g, s], F[g, (s + 1) % 3], F[f, 0],
                                  F[f, 1], F[f, 2]):
            return True
    return False


@jit
def _count_intersecting(V, F, pairs):
    hits = 0
    for k in range(pairs.shape[0]):
        a = pairs[k, 0]
        b = pairs[k, 1]
        shared = False
        for x in range(3):
            for y in range(3):
                if F[a, x] == F[b, y]:
                    shared = True
        if not shared and _triangles_intersect(V, F, a, b):
            hits += 1
    return hits


def self_intersections(V, F):
    """Number of pairs of triangles without a common vertex that intersect
    (an edge of one crosses the other). Candidate pairs come from a k-d
    tree on the triangle centroids."""
    from scipy.spatial import cKDTree
    cen = V[F].mean(1)
    rad = np.linalg.norm(V[F] - cen[:, None], axis=2).max()
    pairs = cKDTree(cen).query_pairs(2 * rad, output_type='ndarray')
    return int(_count_intersecting(V, F.astype(np.int64),
                                   pairs.astype(np.int64)))
