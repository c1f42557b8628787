"""Implicit shapes made of smoothly blended parts, and their triangulation.

Private helpers of :class:`~tg_intrinsic.datasets.SyntheticSHREC`:

* a shape is a set of *primitives* (round cones between two joint positions,
  rotated ellipsoids), each with a part label and a blend radius;
* :func:`eval_grid` evaluates the smooth union of their signed distances on a
  regular grid (numba, with exact bounding-sphere culling);
  :func:`eval_grid_banded` does the same exactly only near the surface;
* :func:`marching_tetrahedra` extracts the zero level set with the Freudenthal
  (Kuhn) split of every grid cube into six tetrahedra. The level set of a
  piecewise-linear function at a value no grid node takes is a closed,
  embedded 2-manifold, so the output is watertight, manifold and free of
  self-intersections by construction (clamping the vertices along their
  edges keeps every triangle inside its tetrahedron and the pieces on a
  shared tetrahedron face identical, so this still holds); triangles are
  oriented so that their normals point to the outside (positive field).
"""
import numpy as np

from tg_intrinsic.geometry.jit import jit

CONE = 0
ELLIPSOID = 1
#: Row layout of a primitive: [kind, label, blend, bound_cx, bound_cy,
#: bound_cz, bound_r, params...]
NUM_HEAD = 7
NUM_COLS = NUM_HEAD + 15


def cone(a, b, ra, rb, label, blend):
    """Row of a round cone between ``a`` and ``b`` with end radii."""
    a, b = np.asarray(a, float), np.asarray(b, float)
    row = np.zeros(NUM_COLS)
    length = np.linalg.norm(b - a)
    # The round cone formula needs |ra - rb| < |b - a|.
    if abs(ra - rb) >= 0.95 * length:
        rb = ra - np.sign(ra - rb) * 0.95 * length
    row[:NUM_HEAD] = [CONE, label, blend, *(0.5 * (a + b)),
                      0.5 * length + max(ra, rb)]
    row[NUM_HEAD:NUM_HEAD + 8] = [*a, *b, ra, rb]
    return row


def ellipsoid(center, radii, rot, label, blend):
    """Row of an ellipsoid ``{x : |R^T (x - c) / radii| <= 1}``."""
    row = np.zeros(NUM_COLS)
    row[:NUM_HEAD] = [ELLIPSOID, label, blend, *center, max(radii)]
    row[NUM_HEAD:NUM_HEAD + 3] = center
    row[NUM_HEAD + 3:NUM_HEAD + 6] = radii
    row[NUM_HEAD + 6:NUM_HEAD + 15] = np.asarray(rot, float).ravel()
    return row


@jit(fastmath=False)
def _prim_sd(x, y, z, P, i):
    o = NUM_HEAD
    if P[i, 0] == CONE:
        ax, ay, az = P[i, o], P[i, o + 1], P[i, o + 2]
        bax, bay, baz = P[i, o + 3] - ax, P[i, o + 4] - ay, P[i, o + 5] - az
        r1, r2 = P[i, o + 6], P[i, o + 7]
        l2 = bax * bax + bay * bay + baz * baz
        rr = r1 - r2
        a2 = l2 - rr * rr
        il2 = 1.0 / l2
        pax, pay, paz = x - ax, y - ay, z - az
        yy = pax * bax + pay * bay + paz * baz
        zz = yy - l2
        qx = pax * l2 - bax * yy
        qy = pay * l2 - bay * yy
        qz = paz * l2 - baz * yy
        x2 = qx * qx + qy * qy + qz * qz
        y2 = yy * yy * l2
        z2 = zz * zz * l2
        k = np.sign(rr) * rr * rr * x2
        if np.sign(zz) * a2 * z2 > k:
            return np.sqrt(x2 + z2) * il2 - r2
        if np.sign(yy) * a2 * y2 < k:
            return np.sqrt(x2 + y2) * il2 - r1
        return (np.sqrt(x2 * a2 * il2) + yy * rr) * il2 - r1
    else:
        cx, cy, cz = P[i, o], P[i, o + 1], P[i, o + 2]
        rx, ry, rz = P[i, o + 3], P[i, o + 4], P[i, o + 5]
        dx, dy, dz = x - cx, y - cy, z - cz
        # local = R^T d, R stored row-major with the axes as columns
        lx = P[i, o + 6] * dx + P[i, o + 9] * dy + P[i, o + 12] * dz
        ly = P[i, o + 7] * dx + P[i, o + 10] * dy + P[i, o + 13] * dz
        lz = P[i, o + 8] * dx + P[i, o + 11] * dy + P[i, o + 14] * dz
        k0 = np.sqrt((lx / rx) ** 2 + (ly / ry) ** 2 + (lz / rz) ** 2)
        k1 = np.sqrt((lx / (rx * rx)) ** 2 + (ly / (ry * ry)) ** 2
                     + (lz / (rz * rz)) ** 2)
        if k1 < 1e-12:
            return -min(rx, min(ry, rz))
        return k0 * (k0 - 1.0) / k1


@jit
def _field(x, y, z, P):
    acc = 1e30
    for i in range(P.shape[0]):
        ddx = x - P[i, 3]
        ddy = y - P[i, 4]
        ddz = z - P[i, 5]
        k = P[i, 2]
        lower = np.sqrt(ddx * ddx + ddy * ddy + ddz * ddz) - P[i, 6]
        if lower >= acc + k:  # cannot change the smooth minimum
            continue
        d = _prim_sd(x, y, z, P, i)
        if acc > 1e29:
            acc = d
            continue
        h = k - abs(acc - d)
        if h > 0.0:
            h = h / k
            acc = min(acc, d) - h * h * k * 0.25
        else:
            acc = min(acc, d)
    return acc


@jit
def eval_grid(P, origin, h, nx, ny, nz):
    """Field values on the grid ``origin + h * (i, j, k)``."""
    out = np.empty((nx, ny, nz))
    for i in range(nx):
        x = origin[0] + h * i
        for j in range(ny):
            y = origin[1] + h * j
            for k in range(nz):
                out[i, j, k] = _field(x, y, origin[2] + h * k, P)
    return out


@jit
def eval_grid_banded(P, origin, h, nx, ny, nz, step=4, safety=2.0):
    """Like :func:`eval_grid`, but exact only in a band around the surface.

    The field is evaluated on every ``step``-th node first; a coarse cell
    whose corners are all farther than ``safety`` times the cell diagonal
    from the surface is filled with its corners' sign (the smooth union of
    distance bounds is 1-Lipschitz, so it cannot change sign inside), the
    other cells are evaluated at every fine node. Only the sign of the
    filled values is meaningful.
    """
    out = np.empty((nx, ny, nz))
    cx = (nx - 1 + step - 1) // step + 1
    cy = (ny - 1 + step - 1) // step + 1
    cz = (nz - 1 + step - 1) // step + 1
    coarse = np.empty((cx, cy, cz))
    for i in range(cx):
        for j in range(cy):
            for k in range(cz):
                coarse[i, j, k] = _field(origin[0] + h * i * step,
                                         origin[1] + h * j * step,
                                         origin[2] + h * k * step, P)
    bound = safety * np.sqrt(3.0) * h * step
    for i in range(cx - 1):
        for j in range(cy - 1):
            for k in range(cz - 1):
                lo = 1e30
                sgn = 1.0
                for di in range(2):
                    for dj in range(2):
                        for dk in range(2):
                            v = coarse[i + di, j + dj, k + dk]
                            if abs(v) < lo:
                                lo = abs(v)
                            if v < 0:
                                sgn = -1.0
                i1 = min((i + 1) * step, nx - 1)
                j1 = min((j + 1) * step, ny - 1)
                k1 = min((k + 1) * step, nz - 1)
                if lo > bound:
                    for a in range(i * step, i1 + 1):
                        for b in range(j * step, j1 + 1):
                            for c in range(k * step, k1 + 1):
                                out[a, b, c] = sgn * lo
                else:
                    for a in range(i * step, i1 + 1):
                        x = origin[0] + h * a
                        for b in range(j * step, j1 + 1):
                            y = origin[1] + h * b
                            for c in range(k * step, k1 + 1):
                                out[a, b, c] = _field(x, y, origin[2] + h * c,
                                                      P)
    return out


@jit
def eval_points(P, pts):
    out = np.empty(pts.shape[0])
    for n in range(pts.shape[0]):
        out[n] = _field(pts[n, 0], pts[n, 1], pts[n, 2], P)
    return out


@jit
def part_labels(P, pts):
    """Label of the nearest primitive per point.

    Nearest by signed distance plus, for round cones, the distance by which
    the point's projection overshoots the segment's end points, so that
    the joint spheres shared by consecutive bones split along the bisector
    of the two bones instead of at random.
    """
    out = np.empty(pts.shape[0], dtype=np.int64)
    o = NUM_HEAD
    for n in range(pts.shape[0]):
        x, y, z = pts[n, 0], pts[n, 1], pts[n, 2]
        best = 1e30
        lab = 0
        for i in range(P.shape[0]):
            d = _prim_sd(x, y, z, P, i)
            if P[i, 0] == CONE:
                bax = P[i, o + 3] - P[i, o]
                bay = P[i, o + 4] - P[i, o + 1]
                baz = P[i, o + 5] - P[i, o + 2]
                length = np.sqrt(bax * bax + bay * bay + baz * baz)
                t = ((x - P[i, o]) * bax + (y - P[i, o + 1]) * bay
                     + (z - P[i, o + 2]) * baz) / length
                if t < 0.0:
                    d -= t
                elif t > length:
                    d += t - length
            if d < best:
                best = d
                lab = int(P[i, 1])
        out[n] = lab
    return out


# Freudenthal split: tetrahedron t walks (0,0,0) -> +e_a -> +e_b -> (1,1,1).
_PERMS = np.array([[0, 1, 2], [0, 2, 1], [1, 0, 2], [1, 2, 0], [2, 0, 1],
                   [2, 1, 0]], dtype=np.int64)
_TET_OFFSETS = np.zeros((6, 4, 3), dtype=np.int64)
for _t in range(6):
    for _s in range(3):
        _TET_OFFSETS[_t, _s + 1] = _TET_OFFSETS[_t, _s]
        _TET_OFFSETS[_t, _s + 1, _PERMS[_t, _s]] += 1


def _case_table():
    """Triangles of every tetrahedron type ``t`` (of the six in a cube) and
    inside/outside pattern ``case`` of its four corners: up to two
    triangles, each as three corner pairs ``(s0, s1)`` with ``s0 < s1``
    (the edge runs from corner ``s0`` up to ``s1``), ordered so that the
    normal points from the inside to the outside.

    The zero set of a linear function in a tetrahedron is a planar
    triangle or convex quad whose vertices move along the edges as the
    values change, so the orientation depends on ``(t, case)`` only; it is
    decided here once, on edge midpoints.
    """
    tris = -np.ones((6, 16, 2, 3, 2), dtype=np.int64)
    for t in range(6):
        X = _TET_OFFSETS[t].astype(float)
        for case in range(1, 15):
            ins = [(case >> s) & 1 == 1 for s in range(4)]
            cnt = sum(ins)
            if cnt in (1, 3):
                p = ins.index(cnt == 1)
                cand = [[sorted((p, s)) for s in range(4) if s != p]]
            else:
                a, b = [s for s in range(4) if ins[s]]
                c, d = [s for s in range(4) if not ins[s]]
                # quad a-c, a-d, b-d, b-c in cyclic order
                cand = [[sorted((a, c)), sorted((a, d)), sorted((b, d))],
                        [sorted((a, c)), sorted((b, d)), sorted((b, c))]]
            g = X[ins.index(False)] - X[ins.index(True)]
            for k, tri in enumerate(cand):
                P = [0.5 * (X[e0] + X[e1]) for e0, e1 in tri]
                n = np.cross(P[1] - P[0], P[2] - P[0])
                if np.dot(n, g) < 0:
                    tri = [tri[0], tri[2], tri[1]]
                tris[t, case, k] = tri
    return tris


_CASE_TRIS = _case_table()
# direction code (0..6) of the edge from corner s0 to corner s1 > s0
_EDGE_DCODE = np.zeros((6, 4, 4), dtype=np.int64)
for _t in range(6):
    for _a in range(4):
        for _b in range(_a + 1, 4):
            _d = _TET_OFFSETS[_t, _b] - _TET_OFFSETS[_t, _a]
            _EDGE_DCODE[_t, _a, _b] = _d[0] * 4 + _d[1] * 2 + _d[2] - 1
_DCODE_STEP = np.array([[(c + 1) // 4, ((c + 1) // 2) % 2, (c + 1) % 2]
                        for c in range(7)], dtype=np.int64)


def marching_tetrahedra(f, origin, h, tclamp=0.02):
    """Zero level set of the grid field ``f`` (negative inside).

    Vectorised over the grid cubes that the surface crosses. Returns
    ``(V [N, 3] float64, F [M, 3] int64)`` with outward-facing triangles;
    vertices are shared through their grid edge, so the mesh is closed and
    manifold. Nodes on the grid boundary must be outside (positive).
    Interpolation parameters are clamped to ``[tclamp, 1 - tclamp]``, which
    keeps vertices on different grid edges apart.
    """
    f = np.asarray(f, dtype=np.float64)
    f = np.where(f == 0.0, 1e-12, f)  # the level set must avoid grid nodes
    origin = np.asarray(origin, dtype=np.float64)
    nx, ny, nz = f.shape
    flat = f.ravel()
    neg = f < 0
    n_in = np.zeros((nx - 1, ny - 1, nz - 1), dtype=np.int8)
    for di in (0, 1):
        for dj in (0, 1):
            for dk in (0, 1):
                n_in += neg[di:nx - 1 + di, dj:ny - 1 + dj, dk:nz - 1 + dk]
    ci, cj, ck = np.nonzero((n_in > 0) & (n_in < 8))
    cube = (ci * ny + cj) * nz + ck                           # [M]
    off = (_TET_OFFSETS[..., 0] * ny + _TET_OFFSETS[..., 1]) * nz \
        + _TET_OFFSETS[..., 2]                                # [6, 4]
    nodes = cube[:, None, None] + off[None]                   # [M, 6, 4]
    case = ((flat[nodes] < 0) * np.array([1, 2, 4, 8])).sum(-1)  # [M, 6]
    m, t = np.nonzero((case > 0) & (case < 15))
    tri = _CASE_TRIS[t, case[m, t]]                           # [T, 2, 3, 2]
    has = tri[:, :, 0, 0] >= 0                                # [T, 2]
    r, k = np.nonzero(has)
    e = tri[r, k]                                             # [K, 3, 2]
    tt = t[r][:, None]
    keys = (cube[m[r]][:, None] + off[tt, e[..., 0]]) * 7 \
        + _EDGE_DCODE[tt, e[..., 0], e[..., 1]]
    ukeys, inverse = np.unique(keys.ravel(), return_inverse=True)
    # vertex positions on their grid edges
    node0 = ukeys // 7
    step = _DCODE_STEP[ukeys % 7]
    i0 = np.stack(np.unravel_index(node0, f.shape), 1)
    i1 = i0 + step
    f0 = flat[node0]
    f1 = f[i1[:, 0], i1[:, 1], i1[:, 2]]
    w = np.clip(f0 / (f0 - f1), tclamp, 1.0 - tclamp)[:, None]
    verts = origin + h * (i0 + w * step)
    return verts, inverse.reshape(-1, 3).astype(np.int64)
