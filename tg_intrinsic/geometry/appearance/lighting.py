r"""The reference lighting integral for synthetic SVBRDF scenes: the full
reflection integral of a Lambert + Torrance-Sparrow (GGX) surface under a
distant environment map. Pure numpy/numba kernels behind torch-in,
torch-out functions.

It is the ground truth for the frequency-domain SVBRDF method, so it
makes none of that method's approximations (no spherical harmonics, no lobe
filter): the outgoing radiance is the hemispherical integral

.. math::
    B(\mathbf{p}, \omega_o) = \int_{\Omega^+} f_r(\omega_i, \omega_o)\,
    L(\omega_i) \cos\theta_i \, d\omega_i, \qquad
    f_r = \frac{K_d}{\pi} + \frac{D(\mathbf{h})\,G_1(\omega_i)\,
    G_1(\omega_o)\,F(\omega_o \cdot \mathbf{h})}{4 \cos\theta_i
    \cos\theta_o},

with GGX :math:`D(\mathbf{h}) = \alpha^2 / (\pi ((\mathbf{n} \cdot
\mathbf{h})^2 (\alpha^2 - 1) + 1)^2)`, the separable Smith GGX
:math:`G_1` (:func:`~tg_intrinsic.geometry.appearance.sh.smith_g1`) and Schlick's
:math:`F` (:func:`~tg_intrinsic.geometry.appearance.sh.schlick_fresnel`), per RGB
channel. It is a *direct-lighting* renderer of a *distant* environment: the
object casts no shadow onto itself from the environment and there are no
interreflections, so :math:`B` depends on the point only through its normal
and material.
"""
import math

import numpy as np
import torch
from numba import prange
from torch import Tensor

from ..checks import (check_points, check_positive_int, check_seed,
                      check_tensor, check_unit_interval, check_unit_rows)
from ..jit import jit
from .envmap import bilinear_rgb, check_envmap, env_coords, equirect_lookup
from .sh import principled_to_torrance_sparrow

__all__ = ['render_radiance']


# ----------------------------------------------------------- small kernels
@jit(inline='always')
def _mix64(x):  # pragma: no cover (numba)
    # splitmix64 finaliser: a well-mixed 64-bit hash of a 64-bit integer
    x = (x ^ (x >> np.uint64(30))) * np.uint64(0xBF58476D1CE4E5B9)
    x = (x ^ (x >> np.uint64(27))) * np.uint64(0x94D049BB133111EB)
    return x ^ (x >> np.uint64(31))


@jit(inline='always')
def _hash_uniform(seed, i, j, k):  # pragma: no cover (numba)
    """A uniform number in [0, 1) determined by four integers: the random
    lattice shift of one (point, view) pair, independent of threading."""
    x = _mix64(np.uint64(seed) + np.uint64(0x9E3779B97F4A7C15))
    x = _mix64(x ^ np.uint64(i))
    x = _mix64(x ^ (np.uint64(j) + np.uint64(0x632BE59BD9B4E019)))
    x = _mix64(x ^ (np.uint64(k) + np.uint64(0x85157AF5)))
    return np.float64(x >> np.uint64(11)) * (1.0 / 9007199254740992.0)


def _lookup(env: np.ndarray, dirs: np.ndarray) -> np.ndarray:
    """The appearance package's bilinear equirectangular lookup on numpy
    arrays (the kernels inline the same rule per sample: env_coords,
    bilinear_rgb)."""
    return equirect_lookup(torch.from_numpy(np.asarray(env, np.float64)),
                           torch.from_numpy(np.asarray(dirs, np.float64))
                           ).numpy()


@jit(inline='always')
def _ggx_d(cos_h, alpha2):  # pragma: no cover (numba)
    k = cos_h * cos_h * (alpha2 - 1.0) + 1.0
    return alpha2 / (math.pi * k * k)


@jit(inline='always')
def _smith_g1(c, alpha2):  # pragma: no cover (numba)
    if c <= 0.0:
        return 0.0
    c = min(c, 1.0)
    return 2.0 * c / (c + math.sqrt(alpha2 + (1.0 - alpha2) * c * c))


@jit(inline='always')
def _onb(nx, ny, nz):  # pragma: no cover (numba)
    # Duff et al. 2017: a continuous-almost-everywhere tangent frame
    sign = 1.0 if nz >= 0.0 else -1.0
    a = -1.0 / (sign + nz)
    b = nx * ny * a
    return (1.0 + sign * nx * nx * a, sign * b, -sign * nx,
            b, sign + ny * ny * a, -ny)


@jit(inline='always')
def _sample_vndf(wx, wy, wz, alpha, u1, u2):  # pragma: no cover (numba)
    """A GGX normal (local frame, z = normal) distributed as the normals
    visible from ``w``, :math:`D_{\\omega}(h) = G_1(\\omega)
    \\max(0, \\omega \\cdot h) D(h) / \\cos\\theta` (Heitz 2018): the
    stretched view sees a hemisphere; sample its projected disk, with
    the half of the disk hidden behind the view squeezed away."""
    vx, vy, vz = alpha * wx, alpha * wy, wz
    inv = 1.0 / math.sqrt(vx * vx + vy * vy + vz * vz)
    vx, vy, vz = vx * inv, vy * inv, vz * inv
    lensq = vx * vx + vy * vy
    if lensq > 1e-24:
        il = 1.0 / math.sqrt(lensq)
        t1x, t1y = -vy * il, vx * il
    else:
        t1x, t1y = 1.0, 0.0
    # t2 = v x t1 (t1 has no z component)
    t2x, t2y, t2z = -vz * t1y, vz * t1x, vx * t1y - vy * t1x
    r = math.sqrt(u1)
    ang = 2.0 * math.pi * u2
    p1 = r * math.cos(ang)
    p2 = r * math.sin(ang)
    s = 0.5 * (1.0 + vz)
    p2 = (1.0 - s) * math.sqrt(max(0.0, 1.0 - p1 * p1)) + s * p2
    p3 = math.sqrt(max(0.0, 1.0 - p1 * p1 - p2 * p2))
    hx = p1 * t1x + p2 * t2x + p3 * vx
    hy = p1 * t1y + p2 * t2y + p3 * vy
    hz = p2 * t2z + p3 * vz
    hx, hy, hz = alpha * hx, alpha * hy, max(hz, 0.0)
    inv = 1.0 / math.sqrt(hx * hx + hy * hy + hz * hz)
    return hx * inv, hy * inv, hz * inv


# --------------------------------------------------------------- diffuse
def _diffuse_tables(env: np.ndarray, min_rows: int):
    """Pixel quadrature of the cosine-weighted environment, grouped into
    cells. The quadrature map is the environment map itself, or, when it
    has fewer than ``min_rows`` rows, its bilinear resampling at an integer
    multiple of the resolution (so the quadrature integrates the same
    bilinear radiance the specular lookups see)."""
    height, width = env.shape[:2]
    factor = max(1, -(-min_rows // height))
    hq, wq = height * factor, width * factor
    from .envmap import equirect_directions, equirect_solid_angles
    dirs = equirect_directions(hq, wq).numpy()
    if factor == 1:
        radiance = env
    else:
        radiance = _lookup(env, dirs.reshape(-1, 3)).reshape(hq, wq, 3)
    weight = radiance * equirect_solid_angles(hq, wq).numpy()[..., None]
    # Cells of b x b pixels: a cell entirely above (below) the horizon of
    # a normal contributes n . (sum of w_p d_p) (nothing), because the
    # cosine is linear; only cells crossing the horizon are summed pixel by
    # pixel. b ~ (2H/3)^(1/3) balances the two costs.
    b = max(1, int(round((2 * hq / 3) ** (1 / 3))))
    row_edges = np.append(np.arange(0, hq, b), hq)
    col_edges = np.append(np.arange(0, wq, b), wq)
    cells = []
    for r in range(len(row_edges) - 1):
        for c in range(len(col_edges) - 1):
            cells.append((row_edges[r], row_edges[r + 1], col_edges[c],
                          col_edges[c + 1]))
    cells = np.array(cells, dtype=np.int64)
    return (np.ascontiguousarray(dirs), np.ascontiguousarray(weight),
            cells, hq, wq)


@jit
def _cell_summaries(dirs, weight, cells, hq, wq):  # pragma: no cover
    num = cells.shape[0]
    moment = np.zeros((num, 3, 3))  # channel, xyz
    centre = np.empty((num, 3))
    sin_radius = np.empty(num)
    for c in range(num):
        r0, r1, c0, c1 = cells[c, 0], cells[c, 1], cells[c, 2], cells[c, 3]
        for i in range(r0, r1):
            for j in range(c0, c1):
                for ch in range(3):
                    for a in range(3):
                        moment[c, ch, a] += weight[i, j, ch] * dirs[i, j, a]
        # centre and corners of the cell's (theta, phi) rectangle; the
        # farthest point of such a rectangle from its centre is a corner
        t_lo, t_hi = math.pi * r0 / hq, math.pi * r1 / hq
        p_lo = 2 * math.pi * c0 / wq - math.pi
        p_hi = 2 * math.pi * c1 / wq - math.pi
        tc, pc = 0.5 * (t_lo + t_hi), 0.5 * (p_lo + p_hi)
        cx = math.sin(tc) * math.cos(pc)
        cy = math.sin(tc) * math.sin(pc)
        cz = math.cos(tc)
        centre[c, 0], centre[c, 1], centre[c, 2] = cx, cy, cz
        min_cos = 1.0
        for t in (t_lo, t_hi):
            for p in (p_lo, p_hi):
                dot = (math.sin(t) * math.cos(p) * cx
                       + math.sin(t) * math.sin(p) * cy + math.cos(t) * cz)
                min_cos = min(min_cos, dot)
        min_cos = max(-1.0, min(1.0, min_cos))
        # a little slack against rounding: a wrong 'fully above' would
        # add negative cosines
        sin_radius[c] = min(1.0, math.sqrt(1.0 - min_cos * min_cos) + 1e-9) \
            if min_cos > 0 else 1.0
    return moment, centre, sin_radius


@jit(parallel=True)
def _irradiance_kernel(normal, dirs, weight, cells, moment, centre,
                       sin_radius):  # pragma: no cover (numba)
    """:math:`E(\\mathbf{n}) = \\sum_p L_p \\Omega_p \\max(0, \\mathbf{n}
    \\cdot \\omega_p)` over every quadrature pixel, per point."""
    num = normal.shape[0]
    out = np.zeros((num, 3))
    for k in prange(num):
        nx, ny, nz = normal[k, 0], normal[k, 1], normal[k, 2]
        e0 = 0.0
        e1 = 0.0
        e2 = 0.0
        for c in range(cells.shape[0]):
            dot = nx * centre[c, 0] + ny * centre[c, 1] + nz * centre[c, 2]
            if dot < -sin_radius[c]:
                continue
            if dot > sin_radius[c]:
                e0 += (nx * moment[c, 0, 0] + ny * moment[c, 0, 1]
                       + nz * moment[c, 0, 2])
                e1 += (nx * moment[c, 1, 0] + ny * moment[c, 1, 1]
                       + nz * moment[c, 1, 2])
                e2 += (nx * moment[c, 2, 0] + ny * moment[c, 2, 1]
                       + nz * moment[c, 2, 2])
                continue
            for i in range(cells[c, 0], cells[c, 1]):
                for j in range(cells[c, 2], cells[c, 3]):
                    cos = nx * dirs[i, j, 0] + ny * dirs[i, j, 1] \
                        + nz * dirs[i, j, 2]
                    if cos > 0.0:
                        e0 += cos * weight[i, j, 0]
                        e1 += cos * weight[i, j, 1]
                        e2 += cos * weight[i, j, 2]
        out[k, 0], out[k, 1], out[k, 2] = e0, e1, e2
    return out


# -------------------------------------------------------------- specular
def _light_tables(env: np.ndarray):
    """A piecewise-constant sampling density over the environment's pixels,
    proportional to solid angle times the largest mean radiance in the
    pixel's 3 x 3 neighbourhood, as cumulative tables (the marginal over
    rows, the conditional over columns). The bilinear radiance inside a
    pixel blends its neighbours, so this bounds radiance / density: a sun
    one pixel wide leaks into its neighbours' areas, which a density of
    the pixel's own value would leave almost unsampled."""
    from .envmap import equirect_solid_angles
    height, width = env.shape[:2]
    lum = env.mean(-1)
    padded = np.concatenate([lum[:1], lum, lum[-1:]], 0)
    dilated = lum.copy()
    for dr in (-1, 0, 1):
        rows = padded[1 + dr:1 + dr + height]
        for dc in (-1, 0, 1):
            dilated = np.maximum(dilated, np.roll(rows, dc, axis=1))
    mass = dilated * equirect_solid_angles(height, width).numpy()
    total = mass.sum()
    if not total > 0:
        return None
    row_mass = mass.sum(1)
    row_cdf = np.concatenate([[0.0], np.cumsum(row_mass)]) / total
    row_cdf[-1] = 1.0
    col_cdf = np.zeros((height, width + 1))
    col_cdf[:, 1:] = np.cumsum(mass, 1)
    nonzero = row_mass > 0
    col_cdf[nonzero] /= row_mass[nonzero, None]
    col_cdf[~nonzero] = np.linspace(0, 1, width + 1)
    col_cdf[:, -1] = 1.0
    # density per unit solid angle inside each pixel
    density = mass / total / equirect_solid_angles(height, width).numpy()
    return row_cdf, col_cdf, np.ascontiguousarray(density)


@jit(inline='always')
def _search(cdf, u):  # pragma: no cover (numba)
    """Largest k with cdf[k] <= u < cdf[k + 1] and a non-empty interval."""
    lo, hi = 0, cdf.shape[0] - 1
    while hi - lo > 1:
        mid = (lo + hi) // 2
        if cdf[mid] <= u:
            lo = mid
        else:
            hi = mid
    return lo


@jit(inline='always')
def _env_density(density, row, col):  # pragma: no cover (numba)
    height, width = density.shape
    i = min(max(np.int64(math.floor(row)), 0), height - 1)
    j = np.int64(math.floor(col)) % width
    return density[i, j]


@jit(parallel=True, fastmath=True)
def _specular_kernel(normal, r0, alpha, view, mask, env, num_brdf,
                     num_light, row_cdf, col_cdf, density,
                     seed):  # pragma: no cover (numba)
    """Specular radiance by multiple importance sampling (balance
    heuristic) of GGX visible normals (per point and view) and of the
    environment (per point, shared by its views), each from a 2D Fibonacci
    lattice with a random shift."""
    num, num_views = view.shape[0], view.shape[1]
    height, width = env.shape[0], env.shape[1]
    golden = 0.5 * (math.sqrt(5.0) - 1.0)
    out = np.zeros((num, num_views, 3))
    for k in prange(num):
        nx, ny, nz = normal[k, 0], normal[k, 1], normal[k, 2]
        tx, ty, tz, bx, by, bz = _onb(nx, ny, nz)
        a = max(alpha[k], 1e-3)
        a2 = a * a
        any_view = False
        for v in range(num_views):
            any_view = any_view or mask[k, v]
        if not any_view:
            continue
        # Environment samples above the horizon: direction, density,
        # G1(wi) times radiance. They do not depend on the view.
        light = np.empty((num_light, 7))
        used = 0
        s2 = _hash_uniform(seed, k, 0xFFFFFFFF, 2)
        s3 = _hash_uniform(seed, k, 0xFFFFFFFF, 3)
        for s in range(num_light):
            u1 = (s + s2) / num_light
            u2 = (s * golden + s3) % 1.0
            i = _search(row_cdf, u1)
            f1 = (u1 - row_cdf[i]) / (row_cdf[i + 1] - row_cdf[i])
            j = _search(col_cdf[i], u2)
            f2 = (u2 - col_cdf[i, j]) / (col_cdf[i, j + 1] - col_cdf[i, j])
            f1 = min(max(f1, 0.0), 1.0)
            f2 = min(max(f2, 0.0), 1.0)
            # uniform in solid angle inside pixel (i, j)
            z_hi = math.cos(math.pi * i / height)
            z_lo = math.cos(math.pi * (i + 1) / height)
            dz = z_hi + f1 * (z_lo - z_hi)
            phi = 2 * math.pi * (j + f2) / width - math.pi
            st = math.sqrt(max(0.0, 1.0 - dz * dz))
            dx = st * math.cos(phi)
            dy = st * math.sin(phi)
            cos_i = dx * nx + dy * ny + dz * nz
            if cos_i <= 0.0:
                continue
            row, col = env_coords(dx, dy, dz, height, width)
            lr, lg, lb = bilinear_rgb(env, row, col)
            g1i = _smith_g1(cos_i, a2)
            light[used, 0], light[used, 1], light[used, 2] = dx, dy, dz
            light[used, 3] = density[i, j]
            light[used, 4] = g1i * lr
            light[used, 5] = g1i * lg
            light[used, 6] = g1i * lb
            used += 1
        for v in range(num_views):
            if not mask[k, v]:
                continue
            ox, oy, oz = view[k, v, 0], view[k, v, 1], view[k, v, 2]
            cos_o = ox * nx + oy * ny + oz * nz
            if cos_o <= 0.0:
                continue
            lx = ox * tx + oy * ty + oz * tz
            ly = ox * bx + oy * by + oz * bz
            # VNDF density of wi: G1(wo) D(h) / (4 cos_o)
            pdf_scale = _smith_g1(cos_o, a2) / (4.0 * cos_o)
            s0 = _hash_uniform(seed, k, v, 0)
            s1 = _hash_uniform(seed, k, v, 1)
            acc0 = 0.0
            acc1 = 0.0
            acc2 = 0.0
            for s in range(num_brdf):
                u1 = (s + s0) / num_brdf
                u2 = (s * golden + s1) % 1.0
                hx, hy, hz = _sample_vndf(lx, ly, cos_o, a, u1, u2)
                wh = lx * hx + ly * hy + cos_o * hz
                if wh <= 0.0:
                    continue
                # reflect in the local frame, then to the world
                ix = 2 * wh * hx - lx
                iy = 2 * wh * hy - ly
                iz = 2 * wh * hz - cos_o
                if iz <= 0.0:
                    continue
                dx = ix * tx + iy * bx + iz * nx
                dy = ix * ty + iy * by + iz * ny
                dz = ix * tz + iy * bz + iz * nz
                row, col = env_coords(dx, dy, dz, height, width)
                lr, lg, lb = bilinear_rgb(env, row, col)
                # estimator F G1(wi) L, times the balance-heuristic weight
                weight = _smith_g1(iz, a2)
                if num_light > 0:
                    p_b = pdf_scale * _ggx_d(hz, a2)
                    p_l = _env_density(density, row, col)
                    weight *= p_b / (num_brdf * p_b + num_light * p_l)
                else:
                    weight /= num_brdf
                f5 = (1.0 - min(wh, 1.0)) ** 5
                acc0 += weight * (r0[k, 0] + (1 - r0[k, 0]) * f5) * lr
                acc1 += weight * (r0[k, 1] + (1 - r0[k, 1]) * f5) * lg
                acc2 += weight * (r0[k, 2] + (1 - r0[k, 2]) * f5) * lb
            for s in range(used):
                dx, dy, dz = light[s, 0], light[s, 1], light[s, 2]
                hx, hy, hz = dx + ox, dy + oy, dz + oz
                inv = 1.0 / math.sqrt(hx * hx + hy * hy + hz * hz)
                wh = (ox * hx + oy * hy + oz * hz) * inv
                cos_h = (nx * hx + ny * hy + nz * hz) * inv
                p_b = pdf_scale * _ggx_d(cos_h, a2)
                # f cos_i L / (sum of the weighted densities)
                weight = p_b / (num_brdf * p_b + num_light * light[s, 3])
                f5 = (1.0 - min(max(wh, 0.0), 1.0)) ** 5
                acc0 += weight * (r0[k, 0] + (1 - r0[k, 0]) * f5) \
                    * light[s, 4]
                acc1 += weight * (r0[k, 1] + (1 - r0[k, 1]) * f5) \
                    * light[s, 5]
                acc2 += weight * (r0[k, 2] + (1 - r0[k, 2]) * f5) \
                    * light[s, 6]
            out[k, v, 0], out[k, v, 1], out[k, v, 2] = acc0, acc1, acc2
    return out


def _env_numpy(envmap):
    envmap = check_envmap(envmap)
    return np.ascontiguousarray(envmap.detach().double().cpu().numpy())



def render_radiance(normal: Tensor, base_color: Tensor, metallic: Tensor,
                    roughness: Tensor, view_dirs: Tensor, envmap: Tensor,
                    specular_samples: int = 96, light_samples: int = 128,
                    diffuse_resolution: int = 256, mask: Tensor = None,
                    seed: int = 0, separate: bool = False,
                    irradiance_table: bool = False):
    r"""Outgoing radiance of surface points with principled materials under
    a distant environment map, by an independent estimate of the full
    reflection integral (see the module docstring for :math:`f_r`). It
    estimates

    .. math::
        B(\omega_o) = \frac{K_d}{\pi} \sum_p L_p \Omega_p
        \max(0, \mathbf{n} \cdot \omega_p)
        + \int_{\Omega^+} \frac{D\,G_1(\omega_i)\,G_1(\omega_o)\,F}
        {4 \cos\theta_o} L(\omega_i)\, d\omega_i,

    with :math:`K_d = b(1 - m)`, :math:`R_0 = 0.04 + (b - 0.04)m`,
    :math:`\alpha = \max(r^2, 10^{-3})`
    (:func:`~tg_intrinsic.geometry.appearance.sh.principled_to_torrance_sparrow`).

    * Diffuse: a quadrature over *every* pixel :math:`p` (direction
      :math:`\omega_p`, exact solid angle :math:`\Omega_p`) of the
      environment map, or of its bilinear resampling at an integer multiple
      of the resolution when the map has fewer than
      :obj:`diffuse_resolution` rows. Linearity of the cosine makes it
      cheap: whole blocks of pixels above the horizon are one dot product.
    * Specular: multiple importance sampling (balance heuristic) of GGX
      visible normals (Heitz 2018; estimator :math:`F\,G_1(\omega_i) L`)
      and of the environment's pixels (density proportional to solid angle
      times the brightest radiance of the pixel's 3 x 3 neighbourhood, so
      that a one-pixel sun is found), with bilinear lookups in the
      full-resolution map. Each strategy uses a 2D Fibonacci lattice
      shifted by a random offset drawn from :obj:`seed` per (point, view)
      for the visible normals and per point for the environment samples,
      which all views of a point share (randomised quasi-Monte Carlo:
      unbiased, no structured aliasing, deterministic and independent of
      the number of threads).

    Direct lighting of a distant environment only: no self-shadowing of the
    environment by the object, no interreflections; hence no position
    argument. Views with :math:`\mathbf{n} \cdot \omega_o \le 0` (and pairs
    outside :obj:`mask`) give 0. Computed in float64 with numba, parallel
    over points.

    Args:
        normal (torch.Tensor): Unit normals :math:`(N, 3)` (normalised
            here).
        base_color (torch.Tensor): Base colour :math:`(N, 3)` in
            :math:`[0, 1]`.
        metallic (torch.Tensor): Metallic :math:`(N)` in :math:`[0, 1]`.
        roughness (torch.Tensor): Roughness :math:`(N)` in :math:`[0, 1]`.
        view_dirs (torch.Tensor): Unit directions from each point towards
            each camera :math:`(N, V, 3)`.
        envmap (torch.Tensor): Equirectangular radiance :math:`(H, W, 3)`
            (:mod:`tg_intrinsic.geometry.appearance.envmap` convention).
        specular_samples (int, optional): Visible-normal samples per
            (point, view). (default: :obj:`96`)
        light_samples (int, optional): Environment samples per point,
            shared by its views (drawn once, weighed per view); 0 samples
            the BRDF only. (default: :obj:`128`)
        diffuse_resolution (int, optional): Minimum rows of the diffuse
            quadrature map. (default: :obj:`256`)
        mask (torch.Tensor, optional): Bool :math:`(N, V)`: the pairs to
            shade; the others are 0 (and cost nothing).
            (default: :obj:`None`, all)
        seed (int, optional): Seed of the lattice shifts. (default: :obj:`0`)
        separate (bool, optional): Return ``(diffuse, specular)`` instead
            of their sum. (default: :obj:`False`)
        irradiance_table (bool, optional): Interpolate the diffuse
            irradiance bilinearly from its exact values on a 128 x 256
            grid of normals instead of integrating per point (relative
            error ~1e-4; much faster for many points, as image pixels).
            (default: :obj:`False`)

    Returns:
        :math:`(N, V, 3)` radiance in the dtype of :obj:`normal`, or the
        pair of diffuse and specular parts.
    """
    normal_t = check_points(normal, 'normal')
    num = normal_t.size(0)
    normal_np = check_unit_rows(normal_t, 'normal', (num, 3))
    view_dirs = check_tensor(view_dirs, 'view_dirs')
    if view_dirs.dim() != 3 or view_dirs.size(0) != num \
            or view_dirs.size(2) != 3:
        raise ValueError(f"'view_dirs' must have shape [N, V, 3] with N = "
                         f"{num} points, got {list(view_dirs.shape)}")
    num_views = view_dirs.size(1)
    view_np = check_unit_rows(view_dirs, 'view_dirs',
                               (num, num_views, 3)) \
        if view_dirs.numel() else np.zeros((num, num_views, 3))
    base_color = check_unit_interval(base_color, 'base_color', (num, 3))
    metallic = check_unit_interval(metallic, 'metallic', (num, ))
    roughness = check_unit_interval(roughness, 'roughness', (num, ))
    env = _env_numpy(envmap)
    specular_samples = check_positive_int(specular_samples,
                                          'specular_samples')
    light_samples = check_positive_int(light_samples, 'light_samples', 0)
    diffuse_resolution = check_positive_int(diffuse_resolution,
                                            'diffuse_resolution')
    seed = check_seed(seed)
    if mask is None:
        mask_np = np.ones((num, num_views), dtype=np.bool_)
    else:
        mask = check_tensor(mask, 'mask')
        if mask.dtype != torch.bool or tuple(mask.shape) != (num, num_views):
            raise ValueError(f"'mask' must be a bool tensor of shape "
                             f"[{num}, {num_views}], got {mask.dtype} "
                             f"{list(mask.shape)}")
        mask_np = mask.cpu().numpy()

    kd, r0, alpha = principled_to_torrance_sparrow(base_color, metallic,
                                                   roughness)
    cos_o = np.einsum('nvc,nc->nv', view_np, normal_np)
    facing = (cos_o > 0) & mask_np

    dirs, weight, cells, hq, wq = _diffuse_tables(env, diffuse_resolution)
    moment, centre, sin_radius = _cell_summaries(dirs, weight, cells, hq, wq)
    shaded = facing.any(1)
    irradiance = np.zeros((num, 3))
    if shaded.any() and irradiance_table:
        # exact irradiance at the pixel centres of a 128 x 256 grid of
        # normals, bilinear in between: E is a cosine convolution, smooth
        # enough for a relative error of ~1e-4, and independent of N
        from .envmap import equirect_directions
        grid = equirect_directions(128, 256).numpy().reshape(-1, 3)
        table = _irradiance_kernel(grid, dirs, weight, cells, moment, centre,
                                   sin_radius).reshape(128, 256, 3)
        irradiance[shaded] = _lookup(table, normal_np[shaded])
    elif shaded.any():
        irradiance[shaded] = _irradiance_kernel(
            np.ascontiguousarray(normal_np[shaded]), dirs, weight, cells,
            moment, centre, sin_radius)
    diffuse = (kd.numpy() / math.pi * irradiance)[:, None, :] \
        * facing[..., None]

    tables = _light_tables(env)
    if tables is None or light_samples == 0:
        row_cdf, col_cdf = np.zeros(2), np.zeros((1, 2))
        density, light = np.zeros((1, 1)), 0
    else:
        (row_cdf, col_cdf, density), light = tables, light_samples
    specular = _specular_kernel(
        normal_np, np.ascontiguousarray(r0.numpy()),
        np.ascontiguousarray(alpha.numpy()), np.ascontiguousarray(view_np),
        np.ascontiguousarray(facing), env, specular_samples, light, row_cdf,
        col_cdf, density, seed)
    dtype, device = normal_t.dtype, normal_t.device
    diffuse = torch.from_numpy(diffuse).to(dtype=dtype, device=device)
    specular = torch.from_numpy(specular).to(dtype=dtype, device=device)
    if separate:
        return diffuse, specular
    return diffuse + specular
