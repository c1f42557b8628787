"""Rigid objects built from primitives for :class:`SyntheticModelNet`
(private).

A shape is a list of closed primitive meshes (boxes, cylinders, spheres,
solids of revolution, tori, hollow tubes), each the image of a unit
primitive under an affine map ``x -> A x + t``. Surface points are drawn
area-weighted from all triangles; points that lie inside another primitive
(hidden by the union) or on a face pressed against another primitive
(touching parts) are discarded, so the samples cover the outer surface of
the union. Every point carries the normal of the triangle it was drawn
from. Coordinates: z up, like ModelNet's aligned release.
"""
import numpy as np

# ------------------------------------------------------ unit primitives


def _box_mesh():
    V = np.array([[x, y, z] for x in (-1, 1) for y in (-1, 1)
                  for z in (-1, 1)], float)
    # vertex index = 4 * (x > 0) + 2 * (y > 0) + (z > 0)
    quads = [(0, 1, 3, 2), (4, 6, 7, 5), (0, 4, 5, 1), (2, 3, 7, 6),
             (0, 2, 6, 4), (1, 5, 7, 3)]
    F = []
    for a, b, c, d in quads:
        F += [(a, b, c), (a, c, d)]
    return V, np.array(F, dtype=np.int64)


def _revolve(zs, rs, seg=32):
    """Closed surface of revolution of the profile (z_i, r_i) about z.

    End points with r = 0 become poles, others are closed by flat caps.
    Normals point outwards for increasing ``zs``.
    """
    zs = np.asarray(zs, float)
    rs = np.asarray(rs, float)
    phi = 2 * np.pi * np.arange(seg) / seg
    V = []
    rings = []
    for z, r in zip(zs, rs):
        if r <= 0:
            rings.append([len(V)])
            V.append([0, 0, z])
        else:
            rings.append(list(range(len(V), len(V) + seg)))
            V += [[r * np.cos(p), r * np.sin(p), z] for p in phi]
    F = []
    for a, b in zip(rings[:-1], rings[1:]):
        if len(a) == 1 and len(b) == 1:
            continue
        if len(a) == 1:
            F += [(a[0], b[(i + 1) % seg], b[i]) for i in range(seg)]
        elif len(b) == 1:
            F += [(a[i], a[(i + 1) % seg], b[0]) for i in range(seg)]
        else:
            for i in range(seg):
                j = (i + 1) % seg
                F += [(a[i], b[j], b[i]), (a[i], a[j], b[j])]
    if len(rings[0]) > 1:  # bottom cap, normal -z
        c = len(V)
        V.append([0, 0, zs[0]])
        a = rings[0]
        F += [(c, a[(i + 1) % seg], a[i]) for i in range(seg)]
    if len(rings[-1]) > 1:  # top cap, normal +z
        c = len(V)
        V.append([0, 0, zs[-1]])
        a = rings[-1]
        F += [(c, a[i], a[(i + 1) % seg]) for i in range(seg)]
    return np.array(V, float), np.array(F, dtype=np.int64)


def _sphere_mesh(n_lat=12, seg=24):
    t = np.linspace(0, np.pi, n_lat + 1)
    return _revolve(-np.cos(t), np.sin(t) * (np.arange(n_lat + 1) % n_lat > 0),
                    seg)


def _tube_mesh(r_in, seg=32):
    """Hollow cylinder r_in < rho < 1, |z| < 1 (walls, rims)."""
    phi = 2 * np.pi * np.arange(seg) / seg
    c, s = np.cos(phi), np.sin(phi)
    V = np.concatenate([
        np.stack([c, s, -np.ones(seg)], 1),             # outer bottom 0
        np.stack([c, s, np.ones(seg)], 1),              # outer top    1
        np.stack([r_in * c, r_in * s, -np.ones(seg)], 1),  # inner bottom 2
        np.stack([r_in * c, r_in * s, np.ones(seg)], 1),   # inner top 3
    ])
    ob, ot, ib, it = (np.arange(seg) + k * seg for k in range(4))
    nx = np.roll(np.arange(seg), -1)
    F = []
    for i in range(seg):
        j = nx[i]
        F += [(ob[i], ob[j], ot[j]), (ob[i], ot[j], ot[i])]     # outer wall
        F += [(ib[i], it[j], ib[j]), (ib[i], it[i], it[j])]     # inner wall
        F += [(ot[i], ot[j], it[j]), (ot[i], it[j], it[i])]     # top rim
        F += [(ob[i], ib[j], ob[j]), (ob[i], ib[i], ib[j])]     # bottom rim
    return V, np.array(F, dtype=np.int64)


def _torus_mesh(R, r, arc, seg=32, tube_seg=12):
    """Tube of radius r around the arc of radius R in the xy plane,
    angles [0, arc], with flat end caps."""
    n = seg + 1
    u = np.linspace(0, arc, n)
    v = 2 * np.pi * np.arange(tube_seg) / tube_seg
    U, W = np.meshgrid(u, v, indexing='ij')
    V = np.stack([(R + r * np.cos(W)) * np.cos(U),
                  (R + r * np.cos(W)) * np.sin(U), r * np.sin(W)], -1)
    V = V.reshape(-1, 3)
    idx = np.arange(n * tube_seg).reshape(n, tube_seg)
    F = []
    for i in range(n - 1):
        for k in range(tube_seg):
            k1 = (k + 1) % tube_seg
            a, b, c, d = idx[i, k], idx[i + 1, k], idx[i + 1, k1], idx[i, k1]
            F += [(a, b, c), (a, c, d)]
    # caps at both ends
    c0 = len(V)
    c1 = c0 + 1
    V = np.concatenate([V, [[R, 0, 0], [R * np.cos(arc), R * np.sin(arc), 0]]])
    for k in range(tube_seg):
        k1 = (k + 1) % tube_seg
        F.append((c0, idx[0, k], idx[0, k1]))
        F.append((c1, idx[-1, k1], idx[-1, k]))
    return V, np.array(F, dtype=np.int64)


def _inside_local(kind, params, q, eps):
    """Strictly-inside test in the unit primitive's coordinates."""
    x, y, z = q[:, 0], q[:, 1], q[:, 2]
    if kind == 'box':
        return (np.abs(q) < 1 - eps).all(1)
    if kind == 'cylinder':
        return (x * x + y * y < (1 - eps) ** 2) & (np.abs(z) < 1 - eps)
    if kind == 'sphere':
        return (q * q).sum(1) < (1 - eps) ** 2
    if kind == 'lathe':
        zs, rs = params
        inz = (z > zs[0] + eps) & (z < zs[-1] - eps)
        r = np.interp(z, zs, rs)
        return inz & (np.sqrt(x * x + y * y) < r - eps)
    if kind == 'tube':
        rho = np.sqrt(x * x + y * y)
        return (rho < 1 - eps) & (rho > params + eps) & (np.abs(z) < 1 - eps)
    if kind == 'torus':
        R, r, arc = params
        ang = np.mod(np.arctan2(y, x), 2 * np.pi)
        d = np.sqrt((np.sqrt(x * x + y * y) - R) ** 2 + z * z)
        return (d < r - eps) & (ang > eps) & (ang < arc - eps)
    raise ValueError(kind)


class Part:
    """A unit primitive placed by ``x -> A x + t``."""

    def __init__(self, kind, A, t, params=None):
        self.kind = kind
        self.name = None  # the semantic part, where a builder names it
        self.A = np.asarray(A, float)
        self.t = np.asarray(t, float)
        self.params = params

    def mesh(self):
        k = self.kind
        if k == 'box':
            V, F = _box_mesh()
        elif k == 'cylinder':
            V, F = _revolve([-1, 1], [1, 1])
        elif k == 'sphere':
            V, F = _sphere_mesh()
        elif k == 'lathe':
            V, F = _revolve(*self.params)
        elif k == 'tube':
            V, F = _tube_mesh(self.params)
        elif k == 'torus':
            V, F = _torus_mesh(*self.params)
        else:
            raise ValueError(k)
        # every unit primitive is closed: orient it outwards by the sign of
        # its volume, then account for mirroring maps
        vol = np.einsum('ij,ij->i', V[F[:, 0]],
                        np.cross(V[F[:, 1]], V[F[:, 2]])).sum()
        if (vol < 0) != (np.linalg.det(self.A) < 0):
            F = F[:, [0, 2, 1]]
        return V @ self.A.T + self.t, F

    def inside(self, p, eps=1e-3):
        q = np.linalg.solve(self.A, (p - self.t).T).T
        return _inside_local(self.kind, self.params, q, eps)


# ---------------------------------------------------------- part helpers


def box(center, size, yaw=0.0):
    c, s = np.cos(yaw), np.sin(yaw)
    R = np.array([[c, -s, 0], [s, c, 0], [0, 0, 1.0]])
    return Part('box', R @ np.diag(np.asarray(size, float) / 2), center)


def _axis_frame(d):
    d = d / np.linalg.norm(d)
    a = np.array([1.0, 0, 0]) if abs(d[0]) < 0.9 else np.array([0, 1.0, 0])
    u = np.cross(d, a)
    u /= np.linalg.norm(u)
    return u, np.cross(d, u), d


def cylinder(p0, p1, r, r2=None):
    """Cylinder (or elliptic cylinder with radii r, r2) from p0 to p1."""
    p0, p1 = np.asarray(p0, float), np.asarray(p1, float)
    u, v, d = _axis_frame(p1 - p0)
    r2 = r if r2 is None else r2
    A = np.stack([u * r, v * r2, (p1 - p0) / 2], 1)
    return Part('cylinder', A, (p0 + p1) / 2)


def lathe(base, zs, rs, axis=(0, 0, 1.0), sx=1.0, sy=1.0):
    """Solid of revolution of the profile (zs, rs) along ``axis`` from
    ``base``; sx, sy scale the cross section (elliptic sections)."""
    u, v, d = _axis_frame(np.asarray(axis, float))
    A = np.stack([u * sx, v * sy, d], 1)
    return Part('lathe', A, base,
                (np.asarray(zs, float), np.asarray(rs, float)))


def ellipsoid(center, radii):
    return Part('sphere', np.diag(radii), center)


def tube(center, r_out, r_in, height):
    A = np.diag([r_out, r_out, height / 2])
    return Part('tube', A, center, r_in / r_out)


def torus(center, R, r, arc, R_axis=np.eye(3)):
    return Part('torus', R_axis, center, (R, r, arc))


def rot_x(a):
    c, s = np.cos(a), np.sin(a)
    return np.array([[1, 0, 0], [0, c, -s], [0, s, c]])


def rot_z(a):
    c, s = np.cos(a), np.sin(a)
    return np.array([[c, -s, 0], [s, c, 0], [0, 0, 1.0]])


def named(name, *parts):
    """Gives ``parts`` the semantic part ``name`` (read by
    :class:`~tg_intrinsic.datasets.SyntheticShapeParts`); returns them as a
    list."""
    for part in parts:
        part.name = name
    return list(parts)


def _u(rng, lo, hi):
    return float(rng.uniform(lo, hi))


# --------------------------------------------------------------- classes


def airplane(rng):
    L = _u(rng, 1.6, 2.2)
    R = _u(rng, 0.09, 0.14)
    zs = np.array([0, 0.08, 0.25, 0.75, 0.95, 1.0]) * L
    rs = np.array([0, 0.6, 1.0, 1.0, 0.5, 0.15]) * R
    parts = named('body', lathe([-L / 2, 0, 0], zs, rs, axis=(1.0, 0, 0)))
    span = _u(rng, 1.4, 2.2)
    chord = _u(rng, 0.22, 0.35)
    sweep = _u(rng, 0.0, 0.5)
    wx = _u(rng, -0.15, 0.1) * L
    wz = _u(rng, -0.6, 0.6) * R  # low or high wing
    for side in (-1, 1):
        parts += named('wing', box(
            [wx - sweep * span / 4, side * span / 4, wz],
            [chord, span / 2, 0.035], yaw=side * sweep * 0.5))
    # tail plane and fin
    ts = span * _u(rng, 0.25, 0.4)
    parts += named('tail', box([-0.42 * L, 0, R * 0.3],
                               [chord * 0.6, ts, 0.03]))
    fh = _u(rng, 0.18, 0.35)
    parts += named('tail', box([-0.42 * L, 0, R * 0.5 + fh / 2],
                               [chord * 0.7, 0.03, fh]))
    n_eng = int(rng.choice([0, 2, 4]))
    for k in range(n_eng // 2):
        y = span * (0.15 + 0.15 * k)
        for side in (-1, 1):
            x0 = wx - sweep * y / 2 + chord * 0.6
            parts += named('engine', cylinder(
                [x0, side * y, wz - 0.09],
                [x0 - chord * 1.2, side * y, wz - 0.09], 0.06))
    return parts


def bed(rng):
    L, W = _u(rng, 1.8, 2.2), _u(rng, 0.9, 1.8)
    h = _u(rng, 0.25, 0.45)
    mt = _u(rng, 0.15, 0.25)
    parts = [box([0, 0, h / 2], [L, W, h]),
             box([0.02, 0, h + mt / 2], [L - 0.1, W - 0.06, mt])]
    hh = _u(rng, 0.5, 1.0)
    parts.append(box([-L / 2 - 0.03, 0, hh / 2], [0.06, W + 0.04, hh]))
    if rng.random() < 0.6:
        fh = _u(rng, 0.35, 0.6)
        parts.append(box([L / 2 + 0.03, 0, fh / 2], [0.06, W + 0.04, fh]))
    n_pillows = int(rng.integers(1, 3))
    for k in range(n_pillows):
        y = (k - (n_pillows - 1) / 2) * W / max(n_pillows, 1)
        parts.append(ellipsoid([-L / 2 + 0.25, y, h + mt + 0.05],
                               [0.15, W / (2.4 * n_pillows), 0.07]))
    return parts


def bench(rng):
    L, D = _u(rng, 1.4, 2.2), _u(rng, 0.35, 0.5)
    h = _u(rng, 0.4, 0.5)
    t = 0.05
    parts = [box([0, 0, h], [L, D, t])]
    legs = int(rng.choice([2, 3]))
    for x in np.linspace(-L / 2 + 0.1, L / 2 - 0.1, legs):
        if rng.random() < 0.5:  # slab legs
            parts.append(box([x, 0, h / 2], [0.06, D * 0.9, h]))
        else:
            for y in (-D / 2 + 0.05, D / 2 - 0.05):
                parts.append(box([x, y, h / 2], [0.05, 0.05, h]))
    if rng.random() < 0.5:  # backrest
        bh = _u(rng, 0.3, 0.5)
        parts.append(box([0, -D / 2, h + bh / 2 + 0.05], [L, 0.04, bh]))
        for x in (-L / 2 + 0.1, L / 2 - 0.1):
            parts.append(box([x, -D / 2, h + 0.05], [0.04, 0.04, 0.1]))
    return parts


def bookshelf(rng):
    W, D, H = _u(rng, 0.6, 1.4), _u(rng, 0.25, 0.4), _u(rng, 1.0, 2.0)
    t = _u(rng, 0.025, 0.045)
    parts = [box([-W / 2 + t / 2, 0, H / 2], [t, D, H]),
             box([W / 2 - t / 2, 0, H / 2], [t, D, H]),
             box([0, D / 2 - 0.01, H / 2], [W, 0.02, H])]  # back
    n = int(rng.integers(3, 7))
    for z in np.linspace(t / 2, H - t / 2, n):
        parts.append(box([0, 0, z], [W - 2 * t, D, t]))
    if rng.random() < 0.4:  # a vertical divider
        parts.append(box([_u(rng, -0.2, 0.2) * W, 0, H / 2], [t, D, H]))
    return parts


def bottle(rng):
    H = _u(rng, 0.8, 1.3)
    R = _u(rng, 0.12, 0.22)
    neck = _u(rng, 0.25, 0.45) * R
    body = _u(rng, 0.45, 0.65)
    shoulder = body + _u(rng, 0.08, 0.2)
    zs = np.array([0, 0.02, body, shoulder, 0.92, 0.93, 1.0]) * H
    rs = np.array([R * 0.9, R, R, neck * 1.2, neck, neck * 1.25, neck * 1.25])
    if rng.random() < 0.5:  # waisted body
        zs = np.insert(zs, 2, body * H * 0.5)
        rs = np.insert(rs, 2, R * _u(rng, 0.75, 0.95))
    return [lathe([0, 0, 0], zs, rs)]


def chair(rng):
    W, D = _u(rng, 0.4, 0.6), _u(rng, 0.4, 0.6)
    h = _u(rng, 0.4, 0.5)
    t = 0.05
    parts = named('seat', box([0, 0, h], [W, D, t]))
    if rng.random() < 0.75:
        lr = _u(rng, 0.015, 0.03)
        for x in (-1, 1):
            for y in (-1, 1):
                parts += named('leg', cylinder(
                    [x * (W / 2 - 0.04), y * (D / 2 - 0.04), 0],
                    [x * (W / 2 - 0.04), y * (D / 2 - 0.04), h], lr))
    else:  # office chair: column and star base
        parts += named('leg', cylinder([0, 0, 0.08], [0, 0, h], 0.03))
        for k in range(5):
            a = 2 * np.pi * k / 5
            parts += named('leg', box(
                [0.15 * np.cos(a), 0.15 * np.sin(a), 0.06],
                [0.3, 0.04, 0.04], yaw=a))
    bh = _u(rng, 0.35, 0.6)
    tilt = _u(rng, 0.0, 0.25)
    back = box([0, 0, 0], [W, 0.04, bh])
    back.A = rot_x(-tilt) @ back.A
    back.t = np.array([0, -D / 2 + 0.02 - np.sin(tilt) * bh / 2,
                       h + bh / 2 * np.cos(tilt)])
    parts += named('back', back)
    if rng.random() < 0.4:  # armrests
        for x in (-1, 1):
            parts += named('arm', box([x * W / 2, 0, h + 0.2],
                                      [0.05, D * 0.9, 0.04]),
                           box([x * W / 2, D / 2 - 0.06, h + 0.1],
                               [0.04, 0.04, 0.2]))
    return parts


def cup(rng):
    R = _u(rng, 0.25, 0.4)
    H = _u(rng, 0.5, 0.9)
    th = _u(rng, 0.02, 0.04)
    parts = named('body', tube([0, 0, H / 2], R, R - th, H),
                  cylinder([0, 0, 0], [0, 0, th * 1.5], R - th * 0.5))
    if rng.random() < 0.8:  # handle
        hr = _u(rng, 0.15, 0.25) * H
        parts += named('handle', torus(
            [R + hr * 0.3, 0, H * _u(rng, 0.45, 0.6)], hr,
            _u(rng, 0.02, 0.04), np.pi * 1.2,
            R_axis=rot_x(np.pi / 2) @ rot_z(-0.6 * np.pi)))
    return parts


def guitar(rng):
    L = _u(rng, 0.45, 0.6)
    r1, r2 = _u(rng, 0.28, 0.36), _u(rng, 0.2, 0.28)
    thick = _u(rng, 0.06, 0.1)
    parts = [cylinder([0, 0, 0], [0, 0, thick], r1),
             cylinder([0, 0, 0], [0, 0, thick], r2)]
    parts[0].t = parts[0].t + np.array([-0.2, 0, 0])
    parts[1].t = parts[1].t + np.array([-0.2 + L, 0, 0])
    neck_len = _u(rng, 0.7, 1.0)
    x0 = -0.2 + L + r2 * 0.8
    parts.append(box([x0 + neck_len / 2, 0, thick * 0.7], [neck_len, 0.08,
                                                           0.05]))
    parts.append(box([x0 + neck_len + 0.1, 0, thick * 0.7],
                     [0.22, 0.12, 0.05]))  # headstock
    parts.append(cylinder([-0.05, 0, thick], [-0.05, 0, thick + 0.01],
                          _u(rng, 0.06, 0.1)))  # sound hole rim
    # stand it up: body down, neck up (like ModelNet's guitars)
    R = np.array([[0, 0, -1.0], [0, 1.0, 0], [1.0, 0, 0]])
    for p in parts:
        p.A = R @ p.A
        p.t = R @ p.t
    return parts


def lamp(rng):
    base_r = _u(rng, 0.15, 0.25)
    H = _u(rng, 0.7, 1.4)
    parts = named('base', cylinder([0, 0, 0], [0, 0, 0.05], base_r))
    if rng.random() < 0.5:  # straight stem
        top = np.array([0, 0, H])
        parts += named('tube', cylinder([0, 0, 0.05], top, 0.02))
    else:  # arm with an elbow
        elbow = np.array([0, 0, H * 0.6])
        top = elbow + np.array([_u(rng, 0.2, 0.4), 0, H * 0.4])
        parts += named('tube', cylinder([0, 0, 0.05], elbow, 0.02),
                       cylinder(elbow, top, 0.02),
                       ellipsoid(elbow, [0.035] * 3))
    sr0, sr1 = _u(rng, 0.08, 0.15), _u(rng, 0.18, 0.35)
    sh = _u(rng, 0.15, 0.3)
    if rng.random() < 0.5:  # conical shade around the bulb
        parts += named('shade', lathe(top - np.array([0, 0, sh * 0.6]),
                                      [0, 0.005, sh], [sr1, sr1, sr0]))
    else:  # globe
        parts += named('shade', ellipsoid(top, [sr1 * 0.8] * 3))
    return parts


def monitor(rng):
    W, H = _u(rng, 0.9, 1.4), _u(rng, 0.55, 0.85)
    d = _u(rng, 0.03, 0.08)
    z0 = _u(rng, 0.15, 0.3)
    parts = [box([0, 0, z0 + H / 2], [W, d, H]),
             box([0, 0.04, z0 + H / 2], [W * 0.5, 0.06, H * 0.5])]
    parts.append(box([0, 0.05, z0 / 2 + 0.02], [0.06, 0.04, z0 + 0.04]))
    if rng.random() < 0.5:
        parts.append(box([0, 0.05, 0.01], [_u(rng, 0.3, 0.5), 0.25, 0.02]))
    else:
        parts.append(cylinder([0, 0.05, 0], [0, 0.05, 0.02],
                              _u(rng, 0.12, 0.2)))
    return parts


def sofa(rng):
    n = int(rng.integers(2, 4))
    sw = _u(rng, 0.55, 0.7)
    D = _u(rng, 0.8, 1.0)
    W = n * sw + 0.3
    h = _u(rng, 0.2, 0.3)
    parts = [box([0, 0, h / 2], [W, D, h])]
    for k in range(n):
        x = (k - (n - 1) / 2) * sw
        parts.append(box([x, 0.08, h + 0.08], [sw - 0.02, D - 0.2, 0.16]))
    bh = _u(rng, 0.35, 0.55)
    parts.append(box([0, -D / 2 + 0.1, h + bh / 2], [W, 0.2, bh]))
    ah = _u(rng, 0.15, 0.3)
    for x in (-1, 1):
        parts.append(box([x * (W / 2 - 0.075), 0, h + ah / 2], [0.15, D,
                                                                ah]))
    return parts


def table(rng):
    W, D = _u(rng, 0.8, 1.8), _u(rng, 0.6, 1.0)
    h = _u(rng, 0.6, 0.8)
    t = _u(rng, 0.03, 0.06)
    round_top = rng.random() < 0.35
    if round_top:
        parts = named('top', cylinder([0, 0, h - t], [0, 0, h], D / 2 * 1.1))
    else:
        parts = named('top', box([0, 0, h - t / 2], [W, D, t]))
    if round_top or rng.random() < 0.3:  # pedestal
        parts += named('leg', cylinder([0, 0, 0.03], [0, 0, h - t], 0.05))
        parts += named('support', cylinder([0, 0, 0], [0, 0, 0.03],
                                           _u(rng, 0.2, 0.35)))
    else:
        lw = _u(rng, 0.03, 0.07)
        x, y = (W if not round_top else D) / 2 - 0.06, D / 2 - 0.06
        for sx in (-1, 1):
            for sy in (-1, 1):
                parts += named('leg', box([sx * x, sy * y, (h - t) / 2],
                                          [lw, lw, h - t]))
        if rng.random() < 0.4:  # lower shelf
            parts += named('support', box([0, 0, 0.15],
                                          [2 * x, 2 * y, 0.02]))
    return parts


CLASSES = {
    'airplane': airplane,
    'bed': bed,
    'bench': bench,
    'bookshelf': bookshelf,
    'bottle': bottle,
    'chair': chair,
    'cup': cup,
    'guitar': guitar,
    'lamp': lamp,
    'monitor': monitor,
    'sofa': sofa,
    'table': table,
}


# -------------------------------------------------------------- sampling


def shape_mesh(parts):
    """Concatenated triangle soup of the parts and the part id per face."""
    Vs, Fs, ids = [], [], []
    off = 0
    for i, p in enumerate(parts):
        V, F = p.mesh()
        Vs.append(V)
        Fs.append(F + off)
        ids.append(np.full(len(F), i))
        off += len(V)
    return np.concatenate(Vs), np.concatenate(Fs), np.concatenate(ids)


#: Step along a face's outward normal (in shape units) of the contact test.
_CONTACT_STEP = 1e-3


def sample_surface(parts, num, rng, max_rounds=20):
    """``num`` area-weighted samples on the visible surface of the union:
    samples inside another part are dropped, and so are samples on a face
    that lies against another part (where parts touch), whose points would
    otherwise coincide with the other part's with opposite normals.

    Returns points, the unit normals of their triangles and the face
    indices into :func:`shape_mesh`'s triangles.
    """
    V, F, pid = shape_mesh(parts)
    a, b, c = V[F[:, 0]], V[F[:, 1]], V[F[:, 2]]
    cr = np.cross(b - a, c - a)
    area = 0.5 * np.linalg.norm(cr, axis=1)
    normal = cr / np.maximum(2 * area, 1e-300)[:, None]
    prob = area / area.sum()
    pts, nrm, fid = [], [], []
    have = 0
    for _ in range(max_rounds):
        m = int(1.3 * (num - have)) + 16
        f = rng.choice(len(F), size=m, p=prob)
        r1 = np.sqrt(rng.random(m))[:, None]
        r2 = rng.random(m)[:, None]
        p = (1 - r1) * a[f] + r1 * (1 - r2) * b[f] + r1 * r2 * c[f]
        # hidden: inside another part, or on a face pressed against another
        # part (touching parts: a step off the face along its outward normal
        # enters the other part), so that no contact faces remain
        ahead = p + _CONTACT_STEP * normal[f]
        hidden = np.zeros(m, dtype=bool)
        for i, part in enumerate(parts):
            other = pid[f] != i
            if other.any():
                hidden[other] |= part.inside(p[other]) \
                    | part.inside(ahead[other], eps=0.0)
        keep = ~hidden
        pts.append(p[keep])
        nrm.append(normal[f[keep]])
        fid.append(f[keep])
        have += int(keep.sum())
        if have >= num:
            break
    pts = np.concatenate(pts)[:num]
    nrm = np.concatenate(nrm)[:num]
    fid = np.concatenate(fid)[:num]
    if len(pts) < num:  # pragma: no cover - only for fully hidden parts
        raise RuntimeError('could not sample enough visible surface points')
    return pts, nrm, fid
