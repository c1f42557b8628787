r"""Equirectangular environment maps: directions, solid angles and lookup.

Convention (world :math:`z` is up, as the polar angle of
:mod:`tg_intrinsic.geometry.appearance.sh`): an environment map is an array
:math:`(H, W, 3)` of linear radiance. Pixel ``(row, col)`` covers polar
angles :math:`\theta \in [\pi\,\mathrm{row}/H, \pi(\mathrm{row}+1)/H]`
(row 0 looks up, at :math:`+z`) and azimuths :math:`\phi \in [2\pi\,
\mathrm{col}/W - \pi, 2\pi(\mathrm{col}+1)/W - \pi]`, with
:math:`\phi = \operatorname{atan2}(y, x)`: column 0 starts at :math:`-x`,
the middle column looks along :math:`+x`. The direction of
:math:`(\theta, \phi)` is :math:`(\sin\theta\cos\phi, \sin\theta\sin\phi,
\cos\theta)`; the lookup is bilinear between pixel centres, wrapping in
azimuth.
"""
import math
from typing import Optional, Tuple

import numpy as np
import torch
from numba import prange
from torch import Tensor

from ..checks import check_positive_int, check_tensor
from ..jit import jit


def check_envmap(envmap, name: str = 'envmap') -> Tensor:
    """Checks an environment map: a floating, finite, non-negative
    :math:`(H, W, 3)` tensor."""
    envmap = check_tensor(envmap, name)
    if envmap.dim() != 3 or envmap.size(-1) != 3 or min(envmap.shape[:2]) < 2:
        raise ValueError(f"'{name}' must be an equirectangular image of shape "
                         f"[H, W, 3] (usually W = 2 H), got "
                         f"{list(envmap.shape)}")
    if not envmap.is_floating_point():
        raise ValueError(f"'{name}' must hold floating-point linear radiance, "
                         f"got {envmap.dtype}; an 8-bit image is not HDR: "
                         f"read a .hdr/.exr file instead")
    bad = ~torch.isfinite(envmap)
    if bool(bad.any()):
        raise ValueError(f"'{name}' has {int(bad.any(-1).sum())} pixel(s) "
                         f"with NaN or infinite radiance; repair or replace "
                         f"them first")
    if bool((envmap < 0).any()):
        raise ValueError(f"'{name}' has negative radiance; an environment map "
                         f"must be non-negative")
    return envmap


def view_lightings(data) -> Optional[Tuple[Tensor, Tensor]]:
    r"""The lighting of every photograph of a capture lit differently from
    view to view: ``data.envmaps`` :math:`(L, H, W, 3)` (each one as
    :func:`check_envmap` wants it) and ``data.view_lighting``
    :math:`(V)`, the map of each view (integers in :math:`[0, L)`). Returns
    them, or :obj:`None` for a capture with one lighting
    (``data.envmap``) alone."""
    envmaps = getattr(data, 'envmaps', None)
    which = getattr(data, 'view_lighting', None)
    if envmaps is None and which is None:
        return None
    if envmaps is None or which is None:
        raise ValueError("a capture lit differently per view needs both "
                         "'data.envmaps' [L, H, W, 3] and "
                         "'data.view_lighting' [V] (the map of each view)")
    envmaps = check_tensor(envmaps, 'envmaps')
    if envmaps.dim() != 4:
        raise ValueError(f"'envmaps' must be [L, H, W, 3], got "
                         f"{list(envmaps.shape)}")
    for lighting in envmaps:
        check_envmap(lighting, 'envmaps')
    which = check_tensor(which, 'view_lighting')
    views = getattr(data, 'intrinsics', None)
    if which.dim() != 1 or which.is_floating_point() or (
            views is not None and which.numel() != views.size(0)):
        raise ValueError(f"'view_lighting' must hold one integer per view"
                         f"{'' if views is None else f' ({views.size(0)})'},"
                         f" got {which.dtype} {list(which.shape)}")
    if which.numel() and (int(which.min()) < 0
                          or int(which.max()) >= envmaps.size(0)):
        raise ValueError(f"'view_lighting' must index the {envmaps.size(0)} "
                         f"maps of 'envmaps', got values from "
                         f"{int(which.min())} to {int(which.max())}")
    return envmaps, which.long()


def equirect_angles(height: int, width: int, dtype=torch.float64,
                    device=None):
    r"""Polar and azimuthal angles :math:`(\theta, \phi)` of the pixel
    centres, each :math:`(H, W)`."""
    theta = (torch.arange(height, dtype=dtype, device=device) + 0.5) \
        * (math.pi / height)
    phi = (torch.arange(width, dtype=dtype, device=device) + 0.5) \
        * (2 * math.pi / width) - math.pi
    return torch.broadcast_tensors(theta[:, None], phi[None, :])


def equirect_directions(height: int, width: int, dtype=torch.float64,
                        device=None) -> Tensor:
    """Unit directions of the pixel centres, :math:`(H, W, 3)`."""
    theta, phi = equirect_angles(height, width, dtype, device)
    sin_theta = torch.sin(theta)
    return torch.stack([sin_theta * torch.cos(phi), sin_theta * torch.sin(phi),
                        torch.cos(theta)], -1)


def equirect_solid_angles(height: int, width: int, dtype=torch.float64,
                          device=None) -> Tensor:
    r"""Exact solid angle of every pixel, :math:`(H, W)`; they sum to
    :math:`4\pi`."""
    edges = torch.arange(height + 1, dtype=dtype, device=device) \
        * (math.pi / height)
    band = torch.cos(edges[:-1]) - torch.cos(edges[1:])
    return (band * (2 * math.pi / width))[:, None].expand(height, width)


def direction_to_equirect(directions: Tensor, height: int, width: int):
    r"""Continuous pixel coordinates ``(row, col)`` of unit directions
    :math:`(\ldots, 3)`: pixel centres sit at integers + 0.5."""
    z = directions[..., 2].clamp(-1.0, 1.0)
    theta = torch.acos(z)
    phi = torch.atan2(directions[..., 1], directions[..., 0])
    return theta * (height / math.pi), (phi + math.pi) * (width / (2 *
                                                                   math.pi))


@jit(inline='always')
def env_coords(dx, dy, dz, height, width):  # pragma: no cover (numba)
    """Continuous pixel coordinates (row, col) of a unit direction, as
    :func:`~tg_intrinsic.geometry.appearance.envmap.direction_to_equirect`."""
    z = min(1.0, max(-1.0, dz))
    theta = math.acos(z)
    phi = math.atan2(dy, dx)
    return theta * (height / math.pi), (phi + math.pi) * (width /
                                                         (2 * math.pi))


@jit(inline='always')
def bilinear_rgb(env, row, col):  # pragma: no cover (numba)
    """Bilinear radiance at continuous pixel coordinates, exactly as
    :func:`~tg_intrinsic.geometry.appearance.envmap.equirect_lookup` (wrapping in
    azimuth, clamped at the poles)."""
    height, width = env.shape[0], env.shape[1]
    row = min(max(row - 0.5, 0.0), height - 1.0)
    col = col - 0.5
    r0 = min(math.floor(row), height - 2.0)
    c0 = math.floor(col)
    fr = row - r0
    fc = col - c0
    i0 = np.int64(r0)
    j0 = np.int64(c0) % width
    j1 = (j0 + 1) % width
    w00 = (1 - fr) * (1 - fc)
    w01 = (1 - fr) * fc
    w10 = fr * (1 - fc)
    w11 = fr * fc
    r = (w00 * env[i0, j0, 0] + w01 * env[i0, j1, 0]
         + w10 * env[i0 + 1, j0, 0] + w11 * env[i0 + 1, j1, 0])
    g = (w00 * env[i0, j0, 1] + w01 * env[i0, j1, 1]
         + w10 * env[i0 + 1, j0, 1] + w11 * env[i0 + 1, j1, 1])
    b = (w00 * env[i0, j0, 2] + w01 * env[i0, j1, 2]
         + w10 * env[i0 + 1, j0, 2] + w11 * env[i0 + 1, j1, 2])
    return r, g, b


def equirect_lookup(envmap: Tensor, directions: Tensor) -> Tensor:
    r"""Radiance of :obj:`envmap` :math:`(H, W, C)` in unit
    :obj:`directions` :math:`(\ldots, 3)`, bilinear between pixel centres
    (wrapping in azimuth, clamped at the poles): :math:`(\ldots, C)`.
    Compiled on the CPU for RGB maps when no gradient is needed."""
    if envmap.device.type == 'cpu' and directions.device.type == 'cpu' \
            and envmap.dim() == 3 and envmap.size(-1) == 3 \
            and not (torch.is_grad_enabled() and (
                envmap.requires_grad or directions.requires_grad)):
        flat = directions.detach().reshape(-1, 3).to(torch.float64)
        out = _lookup_rgb(envmap.detach().to(torch.float64).contiguous()
                          .numpy(), flat.contiguous().numpy())
        return torch.from_numpy(out).to(envmap.dtype).view(
            *directions.shape[:-1], 3)
    height, width = envmap.shape[:2]
    row, col = direction_to_equirect(directions.to(envmap.dtype), height,
                                     width)
    row = (row - 0.5).clamp(0, height - 1)
    col = col - 0.5
    r0 = row.floor().clamp(max=height - 2)
    c0 = col.floor()
    fr = (row - r0).unsqueeze(-1)
    fc = (col - c0).unsqueeze(-1)
    r0 = r0.long()
    c0 = c0.long() % width
    c1 = (c0 + 1) % width
    flat = envmap.reshape(height * width, -1)

    def at(r, c):
        return flat[r * width + c]

    top = at(r0, c0) * (1 - fc) + at(r0, c1) * fc
    bottom = at(r0 + 1, c0) * (1 - fc) + at(r0 + 1, c1) * fc
    return top * (1 - fr) + bottom * fr


@jit(parallel=True)
def _lookup_rgb(env, dirs):  # pragma: no cover (numba)
    out = np.empty((dirs.shape[0], 3))
    height, width = env.shape[0], env.shape[1]
    for k in prange(dirs.shape[0]):
        row, col = env_coords(dirs[k, 0], dirs[k, 1], dirs[k, 2], height,
                              width)
        out[k, 0], out[k, 1], out[k, 2] = bilinear_rgb(env, row, col)
    return out


# ------------------------------------------------- spherical harmonics, filters
def _check_map(envmap, name: str = 'envmap', signed: bool = False) -> Tensor:
    """:func:`check_envmap`, or only shape, dtype and finiteness when the
    map may be signed (a band-limited function, a difference of maps)."""
    if not signed:
        return check_envmap(envmap, name)
    envmap = check_tensor(envmap, name)
    if envmap.dim() != 3 or envmap.size(-1) != 3 or min(envmap.shape[:2]) < 2:
        raise ValueError(f"'{name}' must be an equirectangular image of shape "
                         f"[H, W, 3], got {list(envmap.shape)}")
    if not envmap.is_floating_point():
        raise ValueError(f"'{name}' must be float32 or float64, got "
                         f"{envmap.dtype}")
    if not bool(torch.isfinite(envmap).all()):
        raise ValueError(f"'{name}' has NaN or infinite values; repair "
                         f"them first")
    return envmap


def _row_harmonics(height: int, l_max: int, dtype, device):
    r"""The separable form of the harmonics on the pixel grid:
    :math:`Y_{lm}(\theta, \phi) = \Lambda_{l|m|}(\theta)\,T_m(\phi)` with
    :math:`T_m = \cos(m\phi)` for :math:`m \ge 0` and :math:`\sin(|m|\phi)`
    otherwise. Returns :math:`\Lambda` at the row centres :math:`(H, K)`
    (coefficient order of :func:`~tg_intrinsic.geometry.appearance.sh.real_sh`) and,
    per coefficient, the column :math:`m + l^*` of :func:`_azimuth_table`."""
    from .sh import num_coefficients, real_sh
    theta = (torch.arange(height, dtype=dtype, device=device) + 0.5) \
        * (math.pi / height)
    at_phi0 = torch.stack([torch.sin(theta), torch.zeros_like(theta),
                           torch.cos(theta)], -1)
    degree = torch.arange(l_max + 1, device=device)
    degree = degree.repeat_interleave(2 * degree + 1)
    order = torch.arange(num_coefficients(l_max), device=device) \
        - degree * (degree + 1)
    # at phi = 0, Y_{l,|m|} is Lambda_{l|m|} (cos 0 = 1)
    lam = real_sh(at_phi0, l_max)[:, degree * (degree + 1) + order.abs()]
    return lam, order + l_max


def _azimuth_table(width: int, l_max: int, dtype, device) -> Tensor:
    r""":math:`T_m(\phi_c)` at the column centres, :math:`(W, 2 l^* + 1)`,
    column :math:`m + l^*`."""
    phi = (torch.arange(width, dtype=dtype, device=device) + 0.5) \
        * (2 * math.pi / width) - math.pi
    m = torch.arange(-l_max, l_max + 1, dtype=dtype, device=device)
    angle = phi[:, None] * m.abs()
    return torch.where(m >= 0, torch.cos(angle), torch.sin(angle))


def _row_chunk(num_coefficients: int, channels: int) -> int:
    # rows per block so that a (rows, K, C) temporary stays near 32 MB
    return max(1, (1 << 22) // (num_coefficients * channels))


def envmap_to_sh(envmap: Tensor, l_max: int) -> Tensor:
    r"""Spherical-harmonic coefficients of an environment map by pixel
    quadrature. They are

    .. math::
        c_{lm} = \sum_{\text{pixels } p} L_p\, Y_{lm}(\omega_p)\,
        \Omega_p,

    with :math:`\omega_p` the pixel centres and :math:`\Omega_p` their exact
    solid angles (:func:`equirect_solid_angles`). The harmonics separate
    into a function of the row times :math:`\cos(m\phi)` or
    :math:`\sin(|m|\phi)`, so the sum is a Fourier sum per row followed by a
    sum over rows, :math:`O(H W l^* + H (l^*)^2)`, in blocks of rows (the
    memory stays bounded at any resolution and degree). The map may be
    signed.

    Args:
        envmap (torch.Tensor): :math:`(H, W, 3)` map (see the module's
            convention).
        l_max (int): Highest degree :math:`l^*`.

    Returns:
        Coefficients :math:`((l^*+1)^2, 3)` in the order of
        :func:`~tg_intrinsic.geometry.appearance.sh.real_sh`, dtype and device of the
        map.
    """
    return _to_sh(_check_map(envmap, signed=True),
                  check_positive_int(l_max, 'l_max', minimum=0))


def _fejer_weights(height: int, dtype, device) -> Tensor:
    r"""Fejer's first quadrature rule on the row centres: weights
    :math:`w_r` with :math:`\sum_r w_r\, p(\cos\theta_r) = \int_{-1}^1 p`
    for every polynomial of degree below :math:`H` (the centres are the
    Chebyshev points),

    .. math::
        w_r = \frac{2}{H}\Big(1 - 2 \sum_{j=1}^{\lfloor H/2 \rfloor}
        \frac{\cos 2 j \theta_r}{4 j^2 - 1}\Big) > 0."""
    theta = (torch.arange(height, dtype=torch.float64, device=device) + 0.5) \
        * (math.pi / height)
    j = torch.arange(1, height // 2 + 1, dtype=torch.float64, device=device)
    series = (torch.cos(2 * theta[:, None] * j) / (4 * j * j - 1)).sum(1)
    return ((2 / height) * (1 - 2 * series)).to(dtype)


def _to_sh(envmap: Tensor, l_max: int, fejer: bool = False) -> Tensor:
    """:func:`envmap_to_sh` without checks; ``fejer`` replaces the rows'
    solid angles by Fejer's weights (exact for band-limited maps)."""
    height, width, channels = envmap.shape
    dtype, device = envmap.dtype, envmap.device
    lam, column = _row_harmonics(height, l_max, dtype, device)
    if fejer:
        band = _fejer_weights(height, dtype, device) * (2 * math.pi / width)
    else:
        band = equirect_solid_angles(height, width, dtype, device)[:, 0]
    # F[r, m + l*, c] = sum over the row of L T_m
    fourier = torch.einsum('rwc,wj->rjc', envmap,
                           _azimuth_table(width, l_max, dtype, device))
    out = envmap.new_zeros(lam.size(1), channels)
    step = _row_chunk(lam.size(1), channels)
    for start in range(0, height, step):
        rows = slice(start, start + step)
        out += torch.einsum('rk,rkc->kc', lam[rows] * band[rows, None],
                            fourier[rows][:, column])
    return out


def sh_to_envmap(coefficients: Tensor, height: int, width: int) -> Tensor:
    r"""Evaluates a spherical-harmonic expansion at the pixel centres of an
    :math:`H \times W` equirectangular grid. It computes

    .. math::
        L(\omega_p) = \sum_{l \le l^*} \sum_{m=-l}^{l} c_{lm}\,
        Y_{lm}(\omega_p),

    separably (per row, then a Fourier synthesis along it). The result may
    be negative; it is not clamped.

    Args:
        coefficients (torch.Tensor): :math:`((l^*+1)^2, C)` or
            :math:`((l^*+1)^2,)`.
        height (int): Rows :math:`H`.
        width (int): Columns :math:`W`.

    Returns:
        :math:`(H, W, C)` (or :math:`(H, W)`), dtype and device of the
        coefficients.
    """
    coefficients = check_tensor(coefficients, 'coefficients')
    height = check_positive_int(height, 'height')
    width = check_positive_int(width, 'width')
    if coefficients.dim() not in (1, 2) or coefficients.size(0) == 0:
        raise ValueError(f"'coefficients' must have shape [K, C] or [K], got "
                         f"{list(coefficients.shape)}")
    if not coefficients.is_floating_point():
        raise ValueError(f"'coefficients' must be float32 or float64, got "
                         f"{coefficients.dtype}")
    if not bool(torch.isfinite(coefficients).all()):
        raise ValueError("'coefficients' have NaN or infinite values")
    num = coefficients.size(0)
    l_max = math.isqrt(num) - 1
    if (l_max + 1) ** 2 != num:
        raise ValueError(f"'coefficients' must hold (l_max + 1)^2 rows, got "
                         f"{num}")
    squeeze = coefficients.dim() == 1
    coefficients = coefficients.reshape(num, -1)
    channels = coefficients.size(1)
    dtype, device = coefficients.dtype, coefficients.device
    lam, column = _row_harmonics(height, l_max, dtype, device)
    table = _azimuth_table(width, l_max, dtype, device)
    out = coefficients.new_empty(height, width, channels)
    step = _row_chunk(num, channels)
    for start in range(0, height, step):
        block = lam[start:start + step]
        # a[r, m + l*, c] = sum over l of c_lm Lambda_l|m|(theta_r)
        per_order = block.new_zeros(block.size(0), 2 * l_max + 1, channels)
        per_order.index_add_(1, column,
                             block[:, :, None] * coefficients[None])
        out[start:start + step] = torch.einsum('rjc,wj->rwc', per_order,
                                               table)
    return out[..., 0] if squeeze else out


def downsample_envmap(envmap: Tensor, factor: int) -> Tensor:
    r"""Area average over :math:`f \times f` pixel blocks, weighted by the
    solid angle of each row band,

    .. math::
        L'_{P} = \frac{\sum_{p \in P} L_p\,\Omega_p}{\sum_{p \in P}
        \Omega_p},

    so the integral :math:`\sum_p L_p \Omega_p` over the sphere is kept
    exactly (the coarse pixel :math:`P` covers exactly the solid angle of
    its block).

    Args:
        envmap (torch.Tensor): :math:`(H, W, 3)` radiance, :math:`H` and
            :math:`W` divisible by :obj:`factor`.
        factor (int): :math:`f \ge 1`.

    Returns:
        :math:`(H / f, W / f, 3)`.
    """
    envmap = check_envmap(envmap)
    factor = check_positive_int(factor, 'factor')
    height, width, channels = envmap.shape
    if height % factor or width % factor:
        raise ValueError(f"the map's size {height} x {width} must be "
                         f"divisible by 'factor' = {factor}; crop the map or "
                         f"pick a common divisor")
    if height // factor < 2:
        raise ValueError(f"'factor' = {factor} leaves fewer than 2 rows of "
                         f"{height}; use a smaller factor")
    if factor == 1:
        return envmap.clone()
    return _downsample(envmap, factor)


def _downsample(envmap: Tensor, factor: int) -> Tensor:
    height, width, channels = envmap.shape
    band = equirect_solid_angles(height, 1, envmap.dtype, envmap.device)[:, 0]
    weighted = (envmap * band[:, None, None]).reshape(
        height // factor, factor, width // factor, factor, channels)
    total = band.reshape(height // factor, factor).sum(1) * factor
    return weighted.sum((1, 3)) / total[:, None, None]


def _largest_factor(height: int, width: int, rows: int) -> int:
    """The largest common divisor ``f`` of the size with ``height / f >=
    rows`` (1 when none)."""
    best = 1
    for f in range(2, height // max(rows, 1) + 1):
        if height % f == 0 and width % f == 0:
            best = f
    return best


def filter_envmap(envmap: Tensor, alpha: float,
                  out_height: int = None) -> Tensor:
    r"""Band-limits an environment map with the spherical Gaussian whose
    harmonic attenuation is the lobe filter of
    :func:`~tg_intrinsic.geometry.appearance.sh.brdf_filter`,

    .. math::
        c'_{lm} = e^{-(\alpha l)^2}\, c_{lm}, \qquad l \le L =
        \min(\lceil 3.5 / \alpha \rceil, \lfloor H / 2 \rfloor),

    where the truncation costs at most :math:`e^{-3.5^2} \approx 5 \cdot
    10^{-6}` of a degree's amplitude, and :math:`H/2` is the finest degree
    the input resolves well (a smaller :math:`\alpha` filters no further).
    To be fast the map is first area-averaged
    (:func:`downsample_envmap`) to the coarsest grid of at least
    :math:`\max(4L, 16)` rows its size divides into, then projected as in
    :func:`envmap_to_sh` but with Fejer's weights for the rows (exact for a
    band-limited map of degree below :math:`H'/2` on :math:`H'` rows, so a
    constant map stays constant; the solid angles would leak
    :math:`O((l\pi/H')^2)` of each degree into its neighbours), filtered
    and evaluated (:func:`sh_to_envmap`). The total power moves by the
    rows' difference between the two weights, well below 1%.
    The small negative ringing of the truncated expansion around bright
    lights is clamped to 0, so the result is a valid radiance map.

    Args:
        envmap (torch.Tensor): :math:`(H, W, 3)` radiance.
        alpha (float): Filter width :math:`\alpha > 0` (GGX roughness
            squared for a glossy lobe).
        out_height (int, optional): Rows of the result, with twice as many
            columns. (default: :math:`\max(2L, 16)`, enough for degree
            :math:`L`)

    Returns:
        :math:`(H', 2H', 3)`, dtype and device of the map.
    """
    from ..checks import check_positive_float, check_positive_int
    from .sh import brdf_filter
    envmap = check_envmap(envmap)
    alpha = check_positive_float(alpha, 'alpha')
    height, width = envmap.shape[:2]
    l_max = max(1, min(math.ceil(3.5 / alpha), height // 2))
    if out_height is None:
        out_height = max(2 * l_max, 16)
    out_height = check_positive_int(out_height, 'out_height', 2)
    factor = _largest_factor(height, width, max(4 * l_max, 16))
    if factor > 1:
        envmap = _downsample(envmap, factor)
    coefficients = _to_sh(envmap, l_max, fejer=True)
    coefficients = coefficients * brdf_filter(
        l_max, torch.tensor(alpha, dtype=envmap.dtype,
                            device=envmap.device))[:, None]
    return sh_to_envmap(coefficients, out_height, 2 * out_height).clamp_min(0)


def _pixel_moments(height: int, width: int, dtype, device) -> Tensor:
    r"""First moments :math:`\int_{\text{pixel}} \omega\, d\omega` of the
    pixels, :math:`(H, W, 3)`, in closed form."""
    t = torch.arange(height + 1, dtype=dtype, device=device) \
        * (math.pi / height)
    p = torch.arange(width + 1, dtype=dtype, device=device) \
        * (2 * math.pi / width) - math.pi
    # int sin^2 and int sin cos over the row, int cos, sin over the column
    sin2 = (t[1:] - t[:-1]) / 2 - (torch.sin(2 * t[1:])
                                   - torch.sin(2 * t[:-1])) / 4
    sincos = (torch.sin(t[1:]) ** 2 - torch.sin(t[:-1]) ** 2) / 2
    dx = torch.sin(p[1:]) - torch.sin(p[:-1])
    dy = torch.cos(p[:-1]) - torch.cos(p[1:])
    return torch.stack(torch.broadcast_tensors(
        sin2[:, None] * dx, sin2[:, None] * dy,
        sincos[:, None] * (2 * math.pi / width)), -1)


def irradiance(envmap: Tensor, normals: Tensor,
               resolution: int = 32) -> Tensor:
    r"""Irradiance of an environment map on surfaces with the given normals.
    It is computed as

    .. math::
        E(n) = \int_{S^2} L(\omega) \max(0, n \cdot \omega)\, d\omega
        \approx \sum_p L_p \max\Big(0,\; n \cdot \int_{p} \omega\,
        d\omega\Big),

    on the map area-averaged (:func:`downsample_envmap`) to the coarsest
    grid of at least :obj:`resolution` rows its size divides into. With the
    pixels' exact first moments the sum is the exact integral of the
    piecewise-constant map for every pixel wholly above or below the
    horizon of :math:`n`; only the pixels the horizon crosses are
    approximated (an underestimate of order the squared pixel size, about
    0.2% of a constant map's :math:`\pi L` at 32 rows). Vectorised, in
    blocks of normals.

    Args:
        envmap (torch.Tensor): :math:`(H, W, 3)` radiance.
        normals (torch.Tensor): :math:`(N, 3)` normals (normalised here).
        resolution (int, optional): Rows of the quadrature grid.
            (default: :obj:`32`)

    Returns:
        :math:`(N, 3)`, in the promoted dtype of the map and the normals.
    """
    from ..checks import check_points, check_positive_int, same_device
    envmap = check_envmap(envmap)
    normals = check_points(normals, 'normals')
    same_device(normals, 'normals', envmap, 'envmap')
    resolution = check_positive_int(resolution, 'resolution', 2)
    length = normals.norm(dim=1, keepdim=True)
    if bool((length == 0).any()):
        raise ValueError(f"'normals' has {int((length == 0).sum())} zero "
                         f"vector(s); every normal needs a direction")
    dtype = torch.promote_types(envmap.dtype, normals.dtype)
    normals = (normals / length).to(dtype)
    height, width = envmap.shape[:2]
    factor = _largest_factor(height, width, resolution)
    if factor > 1:
        envmap = _downsample(envmap, factor)
    height, width = envmap.shape[:2]
    moments = _pixel_moments(height, width, dtype, envmap.device).reshape(
        -1, 3)
    radiance = envmap.reshape(-1, 3).to(dtype)
    out = normals.new_empty(normals.size(0), 3)
    step = max(1, (1 << 22) // moments.size(0))
    for start in range(0, normals.size(0), step):
        cosine = (normals[start:start + step] @ moments.t()).clamp_min(0)
        out[start:start + step] = cosine @ radiance
    return out


def sun_sky_envmap(height: int = 256, width: int = 512,
                   sun_direction=(0.5 ** 0.5, 0.0, 0.5 ** 0.5),
                   sun_angular_radius: float = 0.02,
                   sun_power=(25.0, 23.5, 21.0),
                   sky_zenith=(0.25, 0.45, 1.0),
                   sky_horizon=(0.9, 0.9, 1.0),
                   ground=(0.15, 0.13, 0.1),
                   dtype=torch.float32, device=None) -> Tensor:
    r"""A procedural HDR sky: a small bright sun, a smooth sky gradient and
    a dim ground. Deterministic.

    The sky is a function of the height :math:`z` of a direction,

    .. math::
        f(z) = \begin{cases} s_h + (s_z - s_h)\sqrt{z} & z \ge 0 \\
        g & z < 0, \end{cases}

    stored as its exact average over each pixel row (so a row the horizon
    crosses blends sky and ground), and the sun is a disc of angular radius
    :math:`r` about :math:`s`, soft over one pixel height :math:`\delta =
    \pi / H`: weight :math:`w_p = \operatorname{clamp}((r' - \gamma_p) /
    \delta + 1/2, 0, 1)` at angle :math:`\gamma_p` from the sun, with
    :math:`r' = \max(r, \delta)` so that a small sun still lights a
    pixel and the bilinear lookup resolves it. Its radiance is
    :math:`P\, w_p / \sum_q w_q \Omega_q`, which makes the sun's integral
    exactly the requested power, and the whole map's

    .. math::
        \sum_p L_p\,\Omega_p = P + 2\pi\Big(g + s_h + \tfrac{2}{3}(s_z -
        s_h)\Big)

    per channel (to rounding). With the defaults the sun (peak radiance
    about :math:`P / \pi r^2 \approx 2 \cdot 10^4`) gives about 10 times
    the sky's irradiance at normal incidence.

    Args:
        height (int, optional): Rows :math:`H`. (default: :obj:`256`)
        width (int, optional): Columns. (default: :obj:`512`)
        sun_direction (sequence or torch.Tensor, optional): Direction
            :math:`s` to the sun (normalised here; z is up).
            (default: 45 degrees above :math:`+x`)
        sun_angular_radius (float, optional): :math:`r` in radians, about
            four times the real sun's 0.0047 so that :math:`256 \times 512`
            resolves it. (default: :obj:`0.02`)
        sun_power (sequence, optional): RGB :math:`P = \int L_{sun}\,
            d\omega`. (default: :obj:`(25.0, 23.5, 21.0)`)
        sky_zenith (sequence, optional): RGB :math:`s_z`.
            (default: :obj:`(0.25, 0.45, 1.0)`)
        sky_horizon (sequence, optional): RGB :math:`s_h`.
            (default: :obj:`(0.9, 0.9, 1.0)`)
        ground (sequence, optional): RGB :math:`g`.
            (default: :obj:`(0.15, 0.13, 0.1)`)
        dtype (torch.dtype, optional): (default: :obj:`torch.float32`)
        device (torch.device, optional): (default: :obj:`None`)

    Returns:
        :math:`(H, W, 3)` radiance.
    """
    from ..checks import check_positive_float, check_positive_int
    height = check_positive_int(height, 'height', 2)
    width = check_positive_int(width, 'width', 2)
    radius = check_positive_float(sun_angular_radius, 'sun_angular_radius',
                                  allow_zero=True)

    def rgb(value, name):
        value = torch.as_tensor(value, dtype=torch.float64).detach().cpu()
        if value.shape != (3, ) or not bool(torch.isfinite(value).all()) \
                or bool((value < 0).any()):
            raise ValueError(f"'{name}' must be 3 finite, non-negative RGB "
                             f"values, got {value.tolist()}")
        return value.to(device)

    power, zenith = rgb(sun_power, 'sun_power'), rgb(sky_zenith, 'sky_zenith')
    horizon, below = rgb(sky_horizon, 'sky_horizon'), rgb(ground, 'ground')
    sun = torch.as_tensor(sun_direction, dtype=torch.float64).detach()
    sun = sun.cpu().flatten()
    if sun.numel() != 3 or not bool(torch.isfinite(sun).all()) \
            or float(sun.norm()) == 0:
        raise ValueError(f"'sun_direction' must be a finite, non-zero "
                         f"3-vector, got {sun.tolist()}")
    sun = (sun / sun.norm()).to(device)

    # exact row averages of f(z) from its primitive F(z) = int_-1^z f
    z = torch.cos(torch.arange(height + 1, dtype=torch.float64,
                               device=device) * (math.pi / height))[:, None]
    up = z.clamp_min(0)
    primitive = below * (z.clamp_max(0) + 1) + horizon * up \
        + (zenith - horizon) * (2 / 3) * up ** 1.5
    sky = (primitive[:-1] - primitive[1:]) / (z[:-1] - z[1:])

    directions = equirect_directions(height, width, torch.float64, device)
    # the angle to the sun, accurate near 0 (acos is not)
    gamma = torch.atan2(torch.linalg.cross(directions, sun.expand_as(
        directions)).norm(dim=-1), directions @ sun)
    pixel = math.pi / height
    weight = ((max(radius, pixel) - gamma) / pixel + 0.5).clamp(0, 1)
    omega = equirect_solid_angles(height, width, torch.float64, device)
    sun_map = weight[..., None] * (power / (weight * omega).sum())
    return (sky[:, None, :] + sun_map).to(dtype)


def rotate_envmap(envmap: Tensor, degrees: float) -> Tensor:
    r"""The environment map turned by :obj:`degrees` about world :math:`z`
    (counter-clockwise seen from above): the radiance that came from
    azimuth :math:`\phi` comes from :math:`\phi + \alpha`. Columns are
    shifted with linear interpolation, wrapping in azimuth; a multiple of
    a column's width moves pixels exactly."""
    width = envmap.size(1)
    shift = (float(degrees) / 360.0 * width) % width
    whole = int(math.floor(shift))
    fraction = shift - whole
    rolled = torch.roll(envmap, whole, dims=1)
    if fraction == 0:
        return rolled
    return (1 - fraction) * rolled + fraction * torch.roll(rolled, 1, dims=1)


def blender_envmap(envmap: Tensor) -> Tensor:
    r"""Converts between Blender's equirectangular convention and this
    module's (the conversion is its own inverse). Blender's Environment
    Texture looks up :math:`u = \frac12 - \operatorname{atan2}(y, x) /
    2\pi` (Cycles' ``direction_to_equirectangular``), so its azimuth runs
    the other way along the columns: the columns are mirrored. Polar rows
    agree (row 0 looks up, +z)."""
    return torch.flip(envmap, dims=(1, ))
