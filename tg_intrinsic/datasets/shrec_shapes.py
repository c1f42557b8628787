"""Procedural articulated shapes for :class:`SyntheticSHREC` (private).

Every class is a function ``build(rng, pose) -> primitives`` that draws the
rest proportions of one instance from ``rng`` and poses its skeleton with
joint angles scaled by ``pose`` (``pose=0`` gives the rest pose, which is
designed to be free of contacts between parts). Parts are round cones along
bone chains and ellipsoids, blended by a smooth union (see
:mod:`._implicit`). Bones are rigid, so a new pose bends the surface at the
joints only: poses of one instance are near-isometric.

Coordinates: z up, shapes about two units across (scale is normalised
later). Part labels index :data:`PART_NAMES`.
"""
import numpy as np

from . import implicit_surfaces as imp
from .quadric_decimation import decimate, self_intersections

PART_NAMES = ('body', 'head', 'proximal', 'distal', 'extremity', 'tail')
BODY, HEAD, PROX, DIST, EXTR, TAIL = range(6)


def rot(axis, angle):
    """Rotation matrix about ``axis`` by ``angle`` (Rodrigues)."""
    axis = np.asarray(axis, float)
    axis = axis / np.linalg.norm(axis)
    x, y, z = axis
    K = np.array([[0, -z, y], [z, 0, -x], [-y, x, 0]])
    return np.eye(3) + np.sin(angle) * K + (1 - np.cos(angle)) * (K @ K)


def frame_from(d, up=(0, 0, 1)):
    """Rows (d, n, b): an orthonormal frame whose first axis is ``d``."""
    d = np.asarray(d, float)
    d = d / np.linalg.norm(d)
    up = np.asarray(up, float)
    if abs(np.dot(up, d)) > 0.95:
        up = np.array([1.0, 0, 0]) if abs(d[0]) < 0.9 else \
            np.array([0, 1.0, 0])
    n = up - np.dot(up, d) * d
    n /= np.linalg.norm(n)
    return np.stack([d, n, np.cross(d, n)])


class Builder:
    """Collects primitive rows."""

    def __init__(self, blend=0.5):
        self.rows = []
        self.blend = blend

    def cone(self, a, b, ra, rb, label, k=None):
        k = self.blend * min(ra, rb) if k is None else k
        self.rows.append(imp.cone(a, b, ra, rb, label, k))

    def ellipsoid(self, c, radii, R=np.eye(3), label=BODY, k=None):
        k = self.blend * min(radii) if k is None else k
        self.rows.append(imp.ellipsoid(np.asarray(c, float), radii, R, label,
                                       k))

    def chain(self, p, frame, lengths, radii, labels, alphas=None,
              betas=None):
        """A bone chain walked like a turtle.

        Before segment ``i`` the frame (rows: direction, hinge, binormal)
        turns by ``alphas[i]`` about the hinge and ``betas[i]`` about the
        binormal. Returns the end point and frame.
        """
        n = len(lengths)
        alphas = np.zeros(n) if alphas is None else alphas
        betas = np.zeros(n) if betas is None else betas
        frame = np.array(frame, float)
        p = np.asarray(p, float)
        for i in range(n):
            R = rot(frame[1], alphas[i]) @ rot(frame[2], betas[i])
            frame = frame @ R.T
            q = p + lengths[i] * frame[0]
            lab = labels[i] if np.ndim(labels) else labels
            self.cone(p, q, radii[i], radii[i + 1], lab)
            p = q
        return p, frame

    def array(self):
        return np.stack(self.rows)


def _u(rng, lo, hi, size=None):
    return rng.uniform(lo, hi, size)


def _deg(x):
    return np.deg2rad(x)


# ---------------------------------------------------------------- classes


def ant(rng, pose):
    """Insect: head, thorax, raised abdomen on a waist, six legs, antennae."""
    b = Builder()
    s = _u(rng, 0.8, 1.2)  # body length factor
    rt = _u(rng, 0.12, 0.16)
    thorax = np.array([0.0, 0, 0.5])
    b.ellipsoid(thorax, [0.25 * s, rt, rt * 0.9], label=BODY)
    ra = _u(rng, 0.17, 0.24)
    tilt = _deg(rng.uniform(-10, 20)) * pose + _deg(15)  # abdomen raised
    abd_dir = rot([0, 1, 0], -tilt) @ np.array([-1.0, 0, 0])
    # a narrow waist (petiole) between thorax and abdomen
    abd_c = thorax + abd_dir * (0.63 * s + _u(rng, 0.05, 0.1))
    b.ellipsoid(abd_c, [0.38 * s, ra, ra * 0.9], frame_from(abd_dir).T,
                label=TAIL)
    b.cone(thorax, abd_c, rt * 0.6, rt * 0.6, TAIL)
    head_dir = rot([0, 1, 0], _deg(rng.uniform(-30, 30)) * pose) @ np.array(
        [1.0, 0, 0.2])
    head_c = thorax + frame_from(head_dir)[0] * 0.4 * s
    rh = _u(rng, 0.1, 0.13)
    b.ellipsoid(head_c, [rh * 1.2, rh, rh], frame_from(head_dir).T, HEAD)
    b.cone(thorax, head_c, rt * 0.55, rh * 0.6, HEAD)
    # antennae
    for side in (-1, 1):
        d = np.array([0.6, side * 0.5, 0.8])
        fr = frame_from(d)
        L = _u(rng, 0.12, 0.2)
        b.chain(head_c + np.array([0.05, side * 0.05, 0.05]), fr, [L, L],
                [0.045, 0.045, 0.045], [HEAD, HEAD],
                alphas=np.array([0, _deg(rng.uniform(10, 50)) * pose]))
    # six legs
    leg_r = _u(rng, 0.05, 0.06)
    lf, lt = _u(rng, 0.3, 0.42), _u(rng, 0.35, 0.5)
    spacing = max(0.14 * s, 3.0 * leg_r)  # leg roots must not touch
    for side in (-1, 1):
        for i, x in enumerate((-1, 0, 1)):
            base = thorax + np.array([x * spacing, side * rt * 0.7, -0.02])
            yaw = _deg(40 * (i - 1)) + _deg(rng.uniform(-12, 12)) * pose
            _ant_leg(b, base, side, yaw, lf, lt, leg_r, rng, pose)
    return b.array()


def _ant_leg(b, base, side, yaw, lf, lt, r, rng, pose):
    # femur goes up and out, tibia comes down to the ground
    # yaw > 0 turns the leg to the front (+x), on both sides
    out = np.array([np.sin(yaw), side * np.cos(yaw), 0.0])
    up_angle = _deg(rng.uniform(25, 55))
    d1 = np.cos(up_angle) * out + np.sin(up_angle) * np.array([0, 0, 1])
    knee = base + 0.06 * out
    k1 = knee + lf * d1
    b.cone(base, knee, r * 1.2, r, PROX)
    b.cone(knee, k1, r, r, PROX)
    down = _deg(rng.uniform(40, 75) * (0.5 + 0.5 * pose) + 15)
    d2 = np.cos(down) * out - np.sin(down) * np.array([0, 0, 1])
    k2 = k1 + lt * d2
    b.cone(k1, k2, r, r * 0.85, DIST)
    return k2


def bird(rng, pose):
    """Bird: body, neck and beaked head, flat two-part wings, tail, legs."""
    b = Builder()
    L = _u(rng, 0.4, 0.55)
    rb = _u(rng, 0.17, 0.24)
    pitch = _deg(rng.uniform(-15, 25)) * pose
    d = rot([0, 1, 0], -pitch) @ np.array([1.0, 0, 0])
    fr = frame_from(d)
    c = np.zeros(3)
    b.ellipsoid(c, [L, rb, rb * 0.95], fr.T, BODY)
    # neck and head
    neck_len = _u(rng, 0.15, 0.35)
    nd = rot([0, 1, 0], -_deg(rng.uniform(30, 60))) @ d
    nd = rot([0, 0, 1], _deg(rng.uniform(-40, 40)) * pose) @ nd
    n0 = c + 0.8 * L * d
    n1 = n0 + neck_len * nd
    b.cone(n0, n1, rb * 0.55, rb * 0.45, HEAD)
    rh = _u(rng, 0.1, 0.14)
    b.ellipsoid(n1 + 0.3 * rh * nd, [rh * 1.1, rh, rh], frame_from(nd).T, HEAD)
    bd = rot([0, 1, 0], _deg(rng.uniform(30, 70))) @ nd
    bl = _u(rng, 0.12, 0.25)
    b.cone(n1 + rh * 0.8 * bd, n1 + (rh + bl) * bd, rh * 0.45, 0.045, EXTR)
    # tail fan
    td = -d
    tl = _u(rng, 0.2, 0.35)
    side_ax = np.cross([0, 0, 1.0], td)
    side_ax /= np.linalg.norm(side_ax)
    R = np.stack([td, side_ax, np.cross(td, side_ax)], 1)
    b.ellipsoid(c - (L * 0.9 + tl * 0.5) * d,
                [tl, _u(rng, 0.12, 0.18), 0.05], R, TAIL)
    # wings: two flat ellipsoids per side, elevated and folded
    span1, span2 = _u(rng, 0.35, 0.5), _u(rng, 0.35, 0.6)
    chord = _u(rng, 0.15, 0.22)
    elev = _deg(rng.uniform(-20, 50)) * pose + _deg(10)
    fold = _deg(rng.uniform(0, 50)) * pose
    for side in (-1, 1):
        root = c + np.array([0.1 * L, side * rb * 0.7, rb * 0.3])
        out = np.array([0, side, 0.0])
        w1 = rot(d, -side * elev) @ out
        mid = root + span1 * w1
        w2 = rot(d, -side * (elev * 0.3 - fold)) @ rot([0, 0, 1], -side * fold
                                                      * 0.5) @ out
        w2 = w2 / np.linalg.norm(w2)
        tip = mid + span2 * w2
        for a0, a1, cw, lab in ((root, mid, chord, PROX),
                                (mid, tip, chord * 0.8, DIST)):
            ax = (a1 - a0) / np.linalg.norm(a1 - a0)
            ch = d - np.dot(d, ax) * ax
            ch /= np.linalg.norm(ch)
            R = np.stack([ax, ch, np.cross(ax, ch)], 1)
            b.ellipsoid(0.5 * (a0 + a1), [0.5 * np.linalg.norm(a1 - a0) + 0.03,
                                          cw, 0.05], R, lab, k=0.03)
    # legs
    for side in (-1, 1):
        hip = c + np.array([-0.1 * L, side * max(rb * 0.4, 0.1), -rb * 0.6])
        ld = rot([0, 1, 0], _deg(rng.uniform(-40, 40)) * pose) @ np.array(
            [0, 0, -1.0])
        knee = hip + _u(rng, 0.15, 0.25) * ld
        b.cone(hip, knee, 0.06, 0.045, PROX)
        fd = d + 0.5 * ld  # toes forward and down, away from the body
        foot = knee + 0.12 * fd / np.linalg.norm(fd)
        b.cone(knee, foot, 0.045, 0.045, EXTR)
    return b.array()


def claw(rng, pose):
    """Three long curved talons on a narrow palm, no thumb."""
    b = Builder()
    r = _u(rng, 0.06, 0.075)
    pw, ph = _u(rng, 0.2, 0.28), _u(rng, 0.25, 0.35)
    pw = max(pw, 3.0 * r / 0.6)  # talons at least 3 r apart
    pt = _u(rng, 0.09, 0.12)
    b.ellipsoid([0, 0, 0], [pw, pt, ph], label=BODY)
    fl = _u(rng, 0.4, 0.6)
    b.cone([0, 0, -ph * 0.6], [0, 0, -ph - fl], pt * 0.9, pt * 0.8, TAIL)
    spread = _deg(rng.uniform(15, 30))
    for i in range(3):
        x = (i - 1) * pw * 0.6
        base = np.array([x, 0, ph * 0.8])
        yaw = (i - 1) * spread + _deg(rng.uniform(-10, 10)) * pose
        fr = frame_from(rot([0, 1, 0], yaw) @ np.array([0, 0, 1.0]),
                        up=[1, 0, 0])
        lens = np.array([0.3, 0.25, 0.22]) * _u(rng, 0.85, 1.25)
        curl = _deg(rng.uniform(10, 45, 3)) * pose + _deg(8)
        b.chain(base, fr, lens, [r, r * 0.9, r * 0.75, 0.045],
                [PROX, DIST, EXTR], alphas=-curl)
    return b.array()


def dinosaur(rng, pose):
    """Biped dinosaur: tilted body, neck and head, long tail, legs, arms."""
    b = Builder()
    L = _u(rng, 0.35, 0.5)
    rb = _u(rng, 0.18, 0.26)
    tilt = _deg(rng.uniform(-10, 35)) * pose + _deg(10)
    d = rot([0, 1, 0], -tilt) @ np.array([1.0, 0, 0])
    c = np.array([0, 0, 0.9])
    b.ellipsoid(c, [L, rb, rb * 1.05], frame_from(d).T, BODY)
    # neck + head
    nd = rot([0, 1, 0], -_deg(rng.uniform(20, 60))) @ d
    nd = rot([0, 0, 1], _deg(rng.uniform(-45, 45)) * pose) @ nd
    n0 = c + 0.7 * L * d
    n1 = n0 + _u(rng, 0.2, 0.45) * nd
    b.cone(n0, n1, rb * 0.6, rb * 0.4, HEAD)
    hd = rot([0, 1, 0], _deg(rng.uniform(50, 80))) @ nd
    hl = _u(rng, 0.15, 0.22)
    b.ellipsoid(n1 + hl * 0.7 * hd, [hl, hl * 0.5, hl * 0.6],
                frame_from(hd).T, HEAD)
    # tail: tapering chain, swaying
    n = 5
    tl = _u(rng, 0.9, 1.4)
    radii = np.linspace(rb * 0.7, 0.05, n + 1)
    sway = _deg(rng.normal(0, 18, n)) * pose
    droop = _deg(rng.uniform(-5, 20, n)) * pose
    b.chain(c - 0.7 * L * d, frame_from(-d, up=[0, 0, 1]),
            np.full(n, tl / n), radii, TAIL, alphas=droop, betas=sway)
    # legs
    lr = _u(rng, 0.09, 0.12)
    for side in (-1, 1):
        hip = c + np.array([0, side * max(rb * 0.6, 1.7 * lr), -rb * 0.3])
        swing = _deg(rng.uniform(-35, 35)) * pose
        ld = rot([0, 1, 0], swing) @ np.array([0, 0, -1.0])
        knee = hip + _u(rng, 0.35, 0.45) * ld + np.array([0.08, 0, 0])
        b.cone(hip, knee, lr * 1.3, lr, PROX)
        kd = rot([0, 1, 0], -_deg(rng.uniform(0, 40)) * pose - _deg(20)) @ ld
        ankle = knee + _u(rng, 0.3, 0.42) * kd
        b.cone(knee, ankle, lr, lr * 0.7, DIST)
        b.cone(ankle, ankle + np.array([0.18, 0, -0.03]), lr * 0.7, lr * 0.5,
               EXTR)
    # small arms
    for side in (-1, 1):
        sh = c + 0.55 * L * d + np.array([0, side * rb * 0.7, -rb * 0.3])
        ad = rot([0, 1, 0], _deg(rng.uniform(-30, 60)) * pose) @ np.array(
            [0.5, side * 0.4, -0.6])
        fr = frame_from(ad)
        b.chain(sh, fr, [0.14, 0.12], [0.055, 0.05, 0.045], [PROX, DIST],
                alphas=np.array([0, _deg(rng.uniform(10, 80)) * pose]))
    return b.array()


def _hand_like(rng, pose, n_fingers, thumb):
    b = Builder()
    r = _u(rng, 0.065, 0.08)
    pw, ph = _u(rng, 0.3, 0.4), _u(rng, 0.3, 0.4)
    # fingers at least 2.7 r apart at their roots
    pw = max(pw, (n_fingers - 1) * 2.7 * r / (2 * 0.72))
    pt = _u(rng, 0.1, 0.13)
    b.ellipsoid([0, 0, 0], [pw, pt, ph], label=BODY)
    fl = _u(rng, 0.3, 0.7)
    b.cone([0, 0, -ph * 0.6], [0, 0, -ph - fl], pt * 1.1, pt, TAIL)
    scale = _u(rng, 0.8, 1.2)
    spread = _deg(rng.uniform(0, 12)) * pose + _deg(6)
    xs = np.linspace(-1, 1, n_fingers) * pw * 0.72
    length_profile = 1.0 - 0.35 * np.abs(np.linspace(-1, 1, n_fingers)) + \
        0.15 * np.linspace(-1, 1, n_fingers) * _u(rng, -1, 1)
    for i in range(n_fingers):
        base = np.array([xs[i], 0, ph * 0.85])
        yaw = (i - (n_fingers - 1) / 2) * spread
        fr = frame_from(rot([0, 1, 0], yaw) @ np.array([0, 0, 1.0]),
                        up=[1, 0, 0])
        lens = np.array([0.32, 0.22, 0.16]) * scale * length_profile[i] * \
            _u(rng, 0.9, 1.1)
        curl = _deg(rng.uniform(0, 60, 3)) * pose
        b.chain(base, fr, lens, [r, r * 0.93, r * 0.86, r * 0.8],
                [PROX, DIST, EXTR], alphas=-curl)
    if thumb:
        base = np.array([pw * 0.8, 0, -ph * 0.1])
        d = rot([0, 1, 0], _deg(rng.uniform(30, 60))) @ np.array([0, 0, 1.0])
        d = rot([0, 0, 1], -_deg(rng.uniform(0, 50)) * pose) @ d
        fr = frame_from(d, up=[1, 0, 0])
        lens = np.array([0.22, 0.16, 0.12]) * scale
        b.chain(base, fr, lens, [r * 1.15, r * 1.05, r * 0.95, r * 0.85],
                [PROX, DIST, EXTR],
                alphas=-_deg(rng.uniform(0, 40, 3)) * pose)
    return b.array()


def hand(rng, pose):
    """Palm, wrist, four fingers of three phalanges and a thumb."""
    return _hand_like(rng, pose, 4, True)


def human(rng, pose):
    """Humanoid: torso, head, two arms with hands, two legs with feet."""
    b = Builder()
    Lt = _u(rng, 0.45, 0.6)
    rt = _u(rng, 0.13, 0.18)
    bend = _deg(rng.uniform(-15, 35)) * pose
    up = rot([0, 1, 0], bend) @ np.array([0, 0, 1.0])
    pelvis = np.array([0, 0, 1.0])
    chest = pelvis + Lt * up
    R = np.stack([np.cross([0, 1.0, 0], up), [0, 1.0, 0], up], 1)
    b.ellipsoid(pelvis + 0.5 * Lt * up, [rt * 1.35, rt * 0.8, 0.5 * Lt + 0.05],
                R, BODY)
    # head
    hd = rot([1, 0, 0], _deg(rng.uniform(-30, 30)) * pose) @ up
    neck = chest + 0.08 * up
    rh = _u(rng, 0.1, 0.13)
    b.cone(chest, neck + 0.08 * hd, 0.06, 0.06, HEAD)
    b.ellipsoid(neck + (0.08 + rh) * hd, [rh * 0.9, rh * 0.95, rh * 1.15],
                np.stack([np.cross([0, 1.0, 0], hd), [0, 1.0, 0], hd], 1),
                HEAD)
    ra = _u(rng, 0.05, 0.065)
    la1, la2 = _u(rng, 0.25, 0.33), _u(rng, 0.22, 0.3)
    side_axis = R[:, 0]
    for side in (-1, 1):
        sh = chest - 0.05 * up + side * (rt * 1.3 + ra) * side_axis
        b.cone(chest - 0.05 * up, sh, ra * 1.3, ra, BODY)  # shoulder
        abd = _deg(rng.uniform(10, 140)) * pose + _deg(25)
        flex = _deg(rng.uniform(-40, 80)) * pose
        d = rot(R[:, 1], -side * abd) @ (-up)
        d = rot(side_axis, -flex) @ d
        fr = frame_from(d, up=side_axis)
        el = _deg(rng.uniform(0, 120)) * pose
        end, fr = b.chain(sh, fr, [la1, la2], [ra, ra * 0.95, ra * 0.8],
                          [PROX, DIST], alphas=np.array([0, el]))
        b.ellipsoid(end + 0.06 * fr[0], [0.08, 0.05, 0.03], fr.T, EXTR)
    rl = _u(rng, 0.07, 0.085)
    ll1, ll2 = _u(rng, 0.38, 0.48), _u(rng, 0.36, 0.46)
    for side in (-1, 1):
        hip = pelvis + side * max(rt * 0.55, 1.7 * rl) * side_axis
        flex = _deg(rng.uniform(-30, 90)) * pose
        abd = _deg(rng.uniform(0, 30)) * pose + _deg(4)
        d = rot([0, 1.0, 0], -side * abd) @ np.array([0, 0, -1.0])
        d = np.cos(flex) * d + np.sin(flex) * np.array([1.0, 0, 0])
        d /= np.linalg.norm(d)
        fr = frame_from(d, up=[0, 1.0, 0])
        knee_angle = _deg(rng.uniform(0, 110)) * pose
        # knees bend backwards: rotate towards -x
        fr = np.stack([fr[0], np.cross(fr[0], [1.0, 0, 0])
                       / max(np.linalg.norm(np.cross(fr[0], [1.0, 0, 0])),
                             1e-9), fr[2]])
        fr[2] = np.cross(fr[0], fr[1])
        end, fr = b.chain(hip, fr, [ll1, ll2], [rl * 1.1, rl * 0.9, rl * 0.7],
                          [PROX, DIST], alphas=np.array([0, knee_angle]))
        foot_dir = np.array([1.0, 0, -0.2])
        b.cone(end, end + 0.16 * foot_dir / np.linalg.norm(foot_dir),
               rl * 0.7, rl * 0.6, EXTR)
    return b.array()


def octopus(rng, pose):
    """Octopus: mantle, body and eight tapering, curling tentacles."""
    b = Builder()
    rm = _u(rng, 0.2, 0.28)
    n = 8
    L = _u(rng, 0.7, 1.1)
    r0 = _u(rng, 0.06, 0.075)
    ring = max(0.7 * rm, 3.4 * r0)  # tentacle roots apart from each other
    b.ellipsoid([0, 0, 0.4], [rm, rm, rm * _u(rng, 1.2, 1.7)], label=HEAD)
    b.ellipsoid([0, 0, 0.0], [max(0.9 * rm, ring), max(0.9 * rm, ring),
                              rm * 0.6], label=BODY)
    phase = rng.uniform(0, 2 * np.pi)
    for i in range(n):
        ang = phase + 2 * np.pi * i / n
        out = np.array([np.cos(ang), np.sin(ang), 0.0])
        base = np.array([0, 0, -0.05]) + ring * out
        d = out * np.cos(_deg(35)) - np.array([0, 0, np.sin(_deg(35))])
        fr = frame_from(d, up=[0, 0, 1])
        k = 5
        # betas bend in the vertical plane (curl), alphas sideways
        curl = _deg(rng.normal(0, 25, k)) * pose + _deg(rng.uniform(-5, 15))
        side = _deg(rng.normal(0, 8, k)) * pose
        b.chain(base, fr, np.full(k, L / k), np.linspace(r0, 0.045, k + 1),
                [PROX, PROX, DIST, DIST, EXTR], alphas=side, betas=curl)
    return b.array()


def quadruped(rng, pose):
    """Four-legged animal: body, neck and head with ears, legs, tail."""
    b = Builder()
    L = _u(rng, 0.45, 0.65)
    rb = _u(rng, 0.16, 0.24)
    c = np.array([0, 0, 0.9])
    b.ellipsoid(c, [L, rb, rb * 1.05], label=BODY)
    # neck and head
    nd = rot([0, 1, 0], -_deg(rng.uniform(20, 70))) @ np.array([1.0, 0, 0])
    nd = rot([0, 0, 1], _deg(rng.uniform(-50, 50)) * pose) @ nd
    n0 = c + np.array([0.8 * L, 0, 0.2 * rb])
    n1 = n0 + _u(rng, 0.2, 0.55) * nd
    b.cone(n0, n1, rb * 0.55, rb * 0.4, HEAD)
    hd = rot([0, 1, 0], _deg(rng.uniform(40, 90))) @ nd
    hl = _u(rng, 0.13, 0.2)
    b.ellipsoid(n1 + hl * 0.6 * hd, [hl, hl * 0.55, hl * 0.6],
                frame_from(hd).T, HEAD)
    # ears
    for side in (-1, 1):
        b.cone(n1, n1 + np.array([-0.03, side * 0.06, 0.12]), 0.045, 0.045,
               HEAD)
    # tail
    n = 3
    b.chain(c - np.array([0.9 * L, 0, -0.3 * rb]),
            frame_from(np.array([-1.0, 0, 0.5]), up=[0, 0, 1]),
            np.full(n, _u(rng, 0.1, 0.2)), [0.06, 0.055, 0.05, 0.045], TAIL,
            alphas=_deg(rng.normal(0, 25, n)) * pose,
            betas=_deg(rng.normal(0, 25, n)) * pose)
    # legs
    lr = _u(rng, 0.06, 0.08)
    l1, l2 = _u(rng, 0.3, 0.45), _u(rng, 0.25, 0.4)
    for front in (1, -1):
        for side in (-1, 1):
            # legs apart: left and right thighs must not touch
            hip = c + np.array([front * 0.65 * L,
                                side * max(0.55 * rb, 1.7 * lr), -rb * 0.4])
            swing = _deg(rng.uniform(-30, 30)) * pose
            d = rot([0, 1, 0], swing) @ np.array([0, 0, -1.0])
            fr = frame_from(d, up=[0, 1, 0])
            knee = _deg(rng.uniform(0, 50)) * pose * front
            end, fr = b.chain(hip, fr, [l1, l2], [lr * 1.3, lr, lr * 0.85],
                              [PROX, DIST], alphas=np.array([0, knee]))
            b.cone(end, end + np.array([0.08, 0, -0.02]), lr * 0.85,
                   lr * 0.8, EXTR)
    return b.array()


def snake(rng, pose):
    """Snake: a long tapering bone chain bent by smooth random curvature."""
    b = Builder()
    n = 14
    L = _u(rng, 2.2, 3.2)
    rmax = _u(rng, 0.08, 0.12)
    s = np.linspace(0, 1, n + 1)
    radii = rmax * np.clip(np.sin(np.pi * (0.15 + 0.8 * s)) ** 0.6, 0, 1) + \
        0.045 * (1 - np.sin(np.pi * (0.15 + 0.8 * s)) ** 0.6)
    radii = np.maximum(radii, 0.045)
    # curvature: smooth random function of arc length
    t = (np.arange(n) + 0.5) / n
    ka = np.zeros(n)
    kb = np.zeros(n)
    for f in range(1, 4):
        ka += rng.normal(0, 1.0 / f) * np.sin(2 * np.pi * f * t
                                              + rng.uniform(0, 6.3))
        kb += rng.normal(0, 0.4 / f) * np.sin(2 * np.pi * f * t
                                              + rng.uniform(0, 6.3))
    total = _deg(rng.uniform(180, 540))
    alphas = ka / max(np.abs(ka).sum(), 1e-9) * total * pose
    betas = kb / max(np.abs(kb).sum() + np.abs(ka).sum(), 1e-9) * total \
        * pose
    labels = [BODY] * (n // 2) + [TAIL] * (n - n // 2)
    # build from the head backwards
    fr = frame_from([-1.0, 0, 0], up=[0, 0, 1])
    start = np.zeros(3)
    b.chain(start, fr, np.full(n, L / n), radii, labels, alphas=alphas,
            betas=betas)
    hl = _u(rng, 0.13, 0.2)
    b.ellipsoid(start + np.array([0.6 * hl, 0, 0]),
                [hl, radii[0] * 1.35, radii[0] * 1.0], label=HEAD)
    return b.array()


def starfish(rng, pose):
    """Starfish: flat disc with five tapering arms bending up or down."""
    b = Builder()
    rd = _u(rng, 0.22, 0.32)
    b.ellipsoid([0, 0, 0], [rd, rd, rd * 0.5], label=BODY)
    n = 5
    L = _u(rng, 0.6, 1.0)
    r0 = _u(rng, 0.13, 0.17)
    phase = rng.uniform(0, 2 * np.pi)
    for i in range(n):
        ang = phase + 2 * np.pi * i / n + _deg(rng.uniform(-8, 8))
        out = np.array([np.cos(ang), np.sin(ang), 0.0])
        fr = frame_from(out, up=[0, 0, 1])
        k = 4
        Li = L * _u(rng, 0.85, 1.15)
        b.chain(rd * 0.6 * out, fr, np.full(k, Li / k),
                np.linspace(r0, 0.05, k + 1), [PROX, PROX, DIST, EXTR],
                alphas=_deg(rng.normal(0, 8, k)) * pose,   # sideways
                betas=_deg(rng.normal(0, 22, k)) * pose)   # up and down
    return b.array()


def tree(rng, pose):
    """Tree: trunk with roots, two to four branches with twigs and buds."""
    b = Builder()
    h = _u(rng, 0.8, 1.3)
    r0 = _u(rng, 0.1, 0.15)
    sway = _deg(rng.normal(0, 8, 3)) * pose
    top, fr = b.chain([0, 0, 0], frame_from([0, 0, 1.0], up=[1.0, 0, 0]),
                      np.full(3, h / 3), np.linspace(r0, r0 * 0.7, 4), BODY,
                      alphas=sway)
    # roots
    for i in range(3):
        a = 2 * np.pi * i / 3 + rng.uniform(0, 1)
        b.cone([0, 0, 0.05], [0.25 * np.cos(a), 0.25 * np.sin(a), -0.08],
               r0 * 0.8, 0.05, TAIL)
    nb = rng.integers(2, 5)
    phase = rng.uniform(0, 2 * np.pi)
    for i in range(nb):
        a = phase + 2 * np.pi * i / nb + rng.uniform(-0.15, 0.15)
        out = np.array([np.cos(a), np.sin(a), 0])
        d = np.cos(_deg(50)) * fr[0] + np.sin(_deg(50)) * out
        bl = _u(rng, 0.35, 0.6)
        end, bfr = b.chain(top - 0.1 * fr[0], frame_from(d), [bl / 2, bl / 2],
                           [r0 * 0.65, r0 * 0.55, r0 * 0.45], PROX,
                           alphas=_deg(rng.normal(0, 15, 2)) * pose)
        for j in (-1, 1):
            # twigs fan out in the branch's vertical plane, away from the
            # neighbouring branches
            td = rot(bfr[2], j * _deg(rng.uniform(25, 45))) @ bfr[0]
            tl = _u(rng, 0.2, 0.35)
            e2, _ = b.chain(end, frame_from(td), [tl], [r0 * 0.45, 0.05],
                            DIST, alphas=_deg(rng.normal(0, 15, 1)) * pose)
            b.ellipsoid(e2, np.full(3, _u(rng, 0.07, 0.1)), label=EXTR)
    return b.array()


def vase(rng, pose):
    """A closed vase/bottle: round cones swept along a bendable axis."""
    b = Builder()
    foot = _u(rng, 0.2, 0.32)
    belly = _u(rng, 0.3, 0.5)
    shoulder = _u(rng, 0.5, 0.95) * belly
    neck = _u(rng, 0.1, 0.18)
    lip = neck * _u(rng, 1.1, 1.6)
    radii = np.array([foot, belly, shoulder, neck, neck, lip])
    heights = np.array([_u(rng, 0.3, 0.5), _u(rng, 0.15, 0.35),
                        _u(rng, 0.2, 0.35), _u(rng, 0.1, 0.3),
                        _u(rng, 0.06, 0.12)])
    labels = [EXTR, BODY, BODY, HEAD, HEAD]
    n = len(heights)
    bends = _deg(rng.normal(0, 8, n)) * pose
    twists = _deg(rng.normal(0, 8, n)) * pose
    b.chain(np.zeros(3), frame_from([0, 0, 1.0], up=[1.0, 0, 0]), heights,
            radii, labels, alphas=bends, betas=twists)
    return b.array()


CLASSES = {
    'ant': ant,
    'bird': bird,
    'claw': claw,
    'dinosaur': dinosaur,
    'hand': hand,
    'human': human,
    'octopus': octopus,
    'quadruped': quadruped,
    'snake': snake,
    'starfish': starfish,
    'tree': tree,
    'vase': vase,
}


# ------------------------------------------------------------- meshing

_MT_DENSITY = 4.3  # marching-tetrahedra vertices per h^2 of surface area


def _estimate(P):
    """(bounding box lo, hi, thinnest radius, rough surface area)."""
    o = imp.NUM_HEAD
    lo = (P[:, 3:6] - P[:, 6:7]).min(0)
    hi = (P[:, 3:6] + P[:, 6:7]).max(0)
    cone = P[:, 0] == imp.CONE
    rc = P[cone, o + 6:o + 8]
    length = np.linalg.norm(P[cone, o + 3:o + 6] - P[cone, o:o + 3], axis=1)
    re = P[~cone, o + 3:o + 6]
    r_min = min(rc.min() if rc.size else np.inf, re.min() if re.size else
                np.inf)
    area = (np.pi * rc.sum(1) * np.sqrt(length ** 2 + (rc[:, 0] - rc[:, 1])
                                        ** 2)).sum()
    p = 1.6075
    ab = (re[:, 0] * re[:, 1]) ** p
    ac = (re[:, 0] * re[:, 2]) ** p
    bc = (re[:, 1] * re[:, 2]) ** p
    area += (4 * np.pi * ((ab + ac + bc) / 3) ** (1 / p)).sum()
    return lo, hi, r_min, area


def extract_surface(P, fine_vertices=6000, min_cells_per_radius=1.25):
    """Closed manifold zero level set of the primitives ``P``."""
    lo, hi, r_min, area = _estimate(P)
    h = min(np.sqrt(_MT_DENSITY * area / fine_vertices),
            r_min / min_cells_per_radius)
    pad = 3 * h + P[:, 2].max()
    lo = lo - pad
    dims = np.ceil((hi + pad - lo) / h).astype(np.int64) + 1
    f = imp.eval_grid_banded(P, lo, h, int(dims[0]), int(dims[1]),
                             int(dims[2]), 3, 1.1)
    return imp.marching_tetrahedra(f, lo, h)


def mesh_topology(V, F):
    """(number of connected components, Euler characteristic)."""
    import scipy.sparse as sp
    from scipy.sparse.csgraph import connected_components
    n = V.shape[0]
    e = np.concatenate([F[:, [0, 1]], F[:, [1, 2]], F[:, [2, 0]]])
    A = sp.coo_matrix((np.ones(len(e)), (e[:, 0], e[:, 1])), shape=(n, n))
    ncomp, _ = connected_components(A, directed=False)
    chi = n - len(e) // 2 + len(F)
    return ncomp, chi


def vertex_normals_np(V, F):
    fn = np.cross(V[F[:, 1]] - V[F[:, 0]], V[F[:, 2]] - V[F[:, 0]])
    vn = np.zeros_like(V)
    for s in range(3):
        np.add.at(vn, F[:, s], fn)
    return vn / np.maximum(np.linalg.norm(vn, axis=1, keepdims=True), 1e-300)


def relax(V, F, P, iters=5, step=0.5, min_cos=0.2):
    """Improves triangle shapes without changing the surface.

    Every iteration moves each vertex by ``step`` times the tangential part
    of its offset to the centroid of its neighbours, then back onto the
    zero set of the field (one Newton step along the gradient). Vertices of
    triangles whose normal would turn by more than ``acos(min_cos)`` keep
    their position, so no triangle flips. The connectivity is unchanged.
    """
    import scipy.sparse as sp
    n = len(V)
    e = np.concatenate([F[:, [0, 1]], F[:, [1, 2]], F[:, [2, 0]]])
    A = sp.coo_matrix((np.ones(len(e)), (e[:, 0], e[:, 1])),
                      shape=(n, n)).tocsr()
    deg = np.asarray(A.sum(1)).ravel()
    h = 1e-5
    eye = np.eye(3)

    def normals(X):
        return np.cross(X[F[:, 1]] - X[F[:, 0]], X[F[:, 2]] - X[F[:, 0]])

    for _ in range(iters):
        fn = normals(V)
        vn = np.zeros_like(V)
        for s in range(3):
            np.add.at(vn, F[:, s], fn)
        vn /= np.maximum(np.linalg.norm(vn, axis=1, keepdims=True), 1e-300)
        d = A @ V / deg[:, None] - V
        d -= (d * vn).sum(1, keepdims=True) * vn
        W = V + step * d
        f = imp.eval_points(P, W)
        g = np.stack([(imp.eval_points(P, W + h * eye[k])
                       - imp.eval_points(P, W - h * eye[k])) / (2 * h)
                      for k in range(3)], 1)
        W = W - (f / np.maximum((g * g).sum(1), 1e-12))[:, None] * g
        l0 = np.linalg.norm(fn, axis=1)
        for _rep in range(4):
            fn2 = normals(W)
            cos = (fn * fn2).sum(1) / np.maximum(
                l0 * np.linalg.norm(fn2, axis=1), 1e-300)
            bad = cos < min_cos
            if not bad.any():
                break
            keep = np.unique(F[bad])
            W[keep] = V[keep]
        else:
            break
        V = W
    return V


def add_normal_noise(V, F, noise, rng):
    """Displaces every vertex along its normal by ``noise`` times the
    length of its shortest edge times a standard normal sample (clipped
    at 2.5), so that small triangles get small displacements."""
    if noise <= 0:
        return V
    e = np.concatenate([F[:, [0, 1]], F[:, [1, 2]], F[:, [2, 0]]])
    length = np.linalg.norm(V[e[:, 0]] - V[e[:, 1]], axis=1)
    local = np.full(len(V), np.inf)
    np.minimum.at(local, e[:, 0], length)
    np.minimum.at(local, e[:, 1], length)
    z = np.clip(rng.normal(size=len(V)), -2.5, 2.5)
    return V + vertex_normals_np(V, F) * (noise * local * z)[:, None]


def random_rotation(rng):
    q = rng.normal(size=4)
    q /= np.linalg.norm(q)
    w, x, y, z = q
    return np.array([
        [1 - 2 * (y * y + z * z), 2 * (x * y - z * w), 2 * (x * z + y * w)],
        [2 * (x * y + z * w), 1 - 2 * (x * x + z * z), 2 * (y * z - x * w)],
        [2 * (x * z - y * w), 2 * (y * z + x * w), 1 - 2 * (x * x + y * y)],
    ])


def make_shape(name, rng, num_vertices, pose=1.0, noise=0.05, rotate=True,
               fine_vertices=6000, max_tries=8):
    """One posed, meshed, labelled, normalised shape of class ``name``.

    Returns ``(V [N, 3] float64, F [M, 3] int64, labels [N] int64)`` with
    ``N == num_vertices``, a closed genus-0 surface of unit total area with
    its area-weighted centroid at the origin.
    """
    build = CLASSES[name]
    fine_vertices = max(fine_vertices, 3 * int(num_vertices))
    for attempt in range(max_tries + 4):
        # A pose whose parts touch changes the topology (a handle appears):
        # draw a new instance and pose; the last attempts use the rest pose,
        # which is designed to be contact free.
        P = build(rng, pose if attempt < max_tries else 0.0)
        V0, F0 = extract_surface(P, fine_vertices)
        if mesh_topology(V0, F0) != (1, 2) or len(V0) <= num_vertices:
            continue
        # The level set is embedded; decimation, relaxation and noise can
        # fold a few triangles over in tight creases: check and redo.
        for _ in range(3):
            V, F = decimate(V0, F0, int(num_vertices),
                            int(rng.integers(2 ** 31)))
            if len(V) != num_vertices:
                continue
            V = relax(V, F, P)
            V = add_normal_noise(V, F, noise, rng)
            if self_intersections(V, F) == 0:
                break
        else:
            continue
        break
    else:  # pragma: no cover - the rest poses are designed to be valid
        raise RuntimeError(f'could not build a valid {name} shape with '
                           f'{num_vertices} vertices')
    labels = imp.part_labels(P, V)
    # normalise: area-weighted centroid at 0, unit area, random rotation
    fa = 0.5 * np.linalg.norm(np.cross(V[F[:, 1]] - V[F[:, 0]],
                                       V[F[:, 2]] - V[F[:, 0]]), axis=1)
    centroid = (fa[:, None] * V[F].mean(1)).sum(0) / fa.sum()
    V = (V - centroid) / np.sqrt(fa.sum())
    if rotate:
        V = V @ random_rotation(rng).T
    return V, F, labels
