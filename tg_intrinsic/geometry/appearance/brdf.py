r"""Reflection in the spherical-harmonic domain and the power-spectrum
uncertainty of Wiersma et al., "Uncertainty for SVBRDF Acquisition using
Frequency Analysis" (SIGGRAPH 2025), after Ramamoorthi and Hanrahan's
signal-processing view of inverse rendering (2001).

Directions are in a point's local frame (rows :math:`e_u, e_v, n` of
``frame``), so :math:`z = \cos\theta`. Outgoing radiance is parameterised by
the mirror direction :math:`r = 2 (n \cdot \omega_o) n - \omega_o`, in which
the specular lobe is a convolution of the incoming light with a kernel of
SH attenuation :math:`e^{-(\alpha l)^2}`.
"""
import functools
import math

import numba
import numpy as np
import torch
import torch.autograd.forward_ad as forward_ad
from torch import Tensor

from ..jit import jit
from .sh import (num_coefficients, power_spectrum, real_sh, schlick_fresnel,
                 smith_g1)

#: Smallest GGX width used by the model, as the original (roughness 0.03).
MIN_ALPHA = 1e-3


def model_alpha(roughness: Tensor) -> Tensor:
    r"""GGX width :math:`\alpha = r^2` of the model, at least
    :data:`MIN_ALPHA`. The floor keeps the gradient of :math:`r^2`: a hard
    clamp would zero it and strand a fit that touches the floor there for
    good."""
    alpha = roughness * roughness
    return alpha + (MIN_ALPHA - alpha).clamp_min(0).detach()


def reflect(directions: Tensor, normals: Tensor) -> Tensor:
    r"""Mirror directions :math:`2 (n \cdot \omega) n - \omega`."""
    return 2 * (directions * normals).sum(-1, keepdim=True) * normals \
        - directions


def to_local(vectors: Tensor, frame: Tensor) -> Tensor:
    r"""World vectors :math:`(N, \ldots, 3)` in the frames :math:`(N, 3, 3)`
    (rows :math:`e_u, e_v, n`) of their points."""
    shape = vectors.shape
    flat = vectors.reshape(shape[0], -1, 3)
    return (flat @ frame.transpose(1, 2)).reshape(shape)


def lobe_filter(l_max: int, alpha: Tensor, prefilter_alpha: float = 0.0,
                per_degree: bool = False) -> Tensor:
    r"""SH attenuation of the specular lobe for light that was already
    band-limited by a filter of width :math:`\alpha'`,
    :math:`e^{-(\alpha^2 - \alpha'^2) l^2}`: :math:`(\ldots)` to
    :math:`(\ldots, (l^*+1)^2)`, or to :math:`(\ldots, l^* + 1)` (one value
    per degree) with :obj:`per_degree`. With :math:`\alpha'=0` it is
    :func:`~tg_intrinsic.geometry.appearance.sh.brdf_filter`."""
    l = torch.arange(l_max + 1, dtype=alpha.dtype,  # noqa: E741
                     device=alpha.device)
    lobe = torch.exp(-(alpha.unsqueeze(-1) ** 2 - prefilter_alpha ** 2)
                     * l * l)
    if per_degree:
        return lobe
    return lobe.repeat_interleave(2 * l.long() + 1, dim=-1)


@functools.lru_cache(maxsize=4)
def _albedo_table_cpu(size: int, samples: int):
    # Importance sampling of h ~ D(h) (n.h) with a Hammersley set: the
    # estimate of f cos / pdf is G1(i) G1(o) (o.h) / ((n.o)(n.h)).
    k = torch.arange(samples, dtype=torch.float64)
    u1 = (k + 0.5) / samples
    bits = k.long()
    u2 = torch.zeros(samples, dtype=torch.float64)
    scale = 0.5
    for _ in range(32):  # radical inverse in base 2
        u2 += (bits & 1).double() * scale
        bits >>= 1
        scale /= 2
    mu = ((torch.arange(size, dtype=torch.float64) + 0.5) / size)[:, None,
                                                                 None]
    r = torch.linspace(0, 1, size, dtype=torch.float64)[None, :, None]
    alpha = (r * r).clamp_min(MIN_ALPHA)
    # GGX: tan^2(theta_h) = alpha^2 u / (1 - u)
    cos_h = torch.sqrt((1 - u1) / (1 + (alpha * alpha - 1) * u1))
    sin_h = torch.sqrt((1 - cos_h * cos_h).clamp_min(0))
    phi = 2 * math.pi * u2
    o = torch.cat([torch.sqrt(1 - mu * mu), torch.zeros_like(mu), mu], -1)
    shape = (size, size, samples)
    h = torch.stack([(sin_h * torch.cos(phi)).expand(shape),
                     (sin_h * torch.sin(phi)).expand(shape),
                     cos_h.expand(shape)], -1)
    o_h = (o.unsqueeze(-2) * h).sum(-1)
    cos_i = 2 * o_h * h[..., 2] - mu
    weight = torch.where(
        (cos_i > 0) & (o_h > 0),
        smith_g1(cos_i, alpha) * smith_g1(mu, alpha) * o_h / (mu * h[..., 2]),
        torch.zeros_like(cos_i))
    schlick = (1 - o_h.clamp(0, 1)) ** 5
    return ((weight * (1 - schlick)).mean(-1), (weight * schlick).mean(-1))


def ggx_albedo_table(size: int = 32, samples: int = 2048):
    r"""Directional albedo of the GGX lobe with Schlick's Fresnel,
    :math:`\int f_r \cos\theta_i\, d\omega_i = R_0 A + B`, tabulated
    over :math:`\mu = \cos\theta_o` (cell centres) and roughness
    :math:`r \in [0, 1]` (:math:`\alpha = r^2`), each :math:`(size,
    size)`: the "split-sum" factors of real-time rendering, here for the
    separable Smith :math:`G`. Computed once per process (about 0.5 s)."""
    return _albedo_table_cpu(size, samples)


def ggx_albedo(cos_out: Tensor, roughness: Tensor, r0: Tensor) -> Tensor:
    r""":math:`R_0 A(\mu, r) + B(\mu, r)` by bilinear interpolation in
    :func:`ggx_albedo_table` (differentiable in :math:`r` and
    :math:`R_0`): :obj:`cos_out` :math:`(N, V)`, :obj:`roughness`
    :math:`(N)`, :obj:`r0` :math:`(N, 3)` to :math:`(N, V, 3)`."""
    A, B = ggx_albedo_table()
    size = A.size(0)
    A, B = A.to(cos_out), B.to(cos_out)
    x = (cos_out.clamp(0, 1) * size - 0.5).clamp(0, size - 1)
    y = (roughness.clamp(0, 1) * (size - 1)).unsqueeze(-1).expand_as(x)
    x0 = x.detach().floor().clamp(max=size - 2)
    y0 = y.detach().floor().clamp(max=size - 2)
    fx, fy = x - x0, y - y0
    x0, y0 = x0.long(), y0.long()

    def lerp(table):
        top = table[x0, y0] * (1 - fy) + table[x0, y0 + 1] * fy
        bottom = table[x0 + 1, y0] * (1 - fy) + table[x0 + 1, y0 + 1] * fy
        return top * (1 - fx) + bottom * fx

    return r0.unsqueeze(1) * lerp(A).unsqueeze(-1) + lerp(B).unsqueeze(-1)


def dominant_direction(mirror_dir: Tensor, roughness: Tensor) -> Tensor:
    r"""Where a GGX lobe of the local mirror direction :math:`r`
    :math:`(N, V, 3)` collects most light: :math:`r` pulled towards the
    normal, :math:`\operatorname{normalize}(n + s (r - n))` with :math:`s =
    (1 - \alpha)(\sqrt{1 - \alpha} + \alpha)` (Lagarde and de Rousiers,
    "Moving Frostbite to PBR", 2014), :math:`\alpha = r^2` per point."""
    alpha = roughness * roughness
    lean = ((1 - alpha) * (torch.sqrt((1 - alpha).clamp_min(1e-6)) + alpha)
            ).view(-1, 1, 1)
    normal = torch.zeros_like(mirror_dir)
    normal[..., 2] = 1
    dominant = normal + lean * (mirror_dir - normal)
    return dominant / dominant.norm(dim=-1, keepdim=True).clamp_min(1e-12)


def sh_reflectance(sh_in: Tensor, irradiance: Tensor, mirror_dir: Tensor,
                   base_color: Tensor, metallic: Tensor, roughness: Tensor,
                   prefilter_alpha: float = 0.0, fresnel: bool = True,
                   masking: bool = True, specular_model: str = 'eq5.11',
                   basis_out: Tensor = None) -> Tensor:
    r"""Outgoing radiance of the principled BRDF under light given in
    spherical harmonics (thesis eq. 5.11),

    .. math::
        B(\omega_o) = \frac{K_d}{\pi} E + F(\theta_o)\, G_\alpha(\theta_o)
        \sum_{lm} e^{-(\alpha^2 - \alpha'^2) l^2} L_{lm}\, Y_{lm}(r),

    with :math:`K_d = b (1 - m)`, Schlick's :math:`F` of :math:`R_0 = 0.04 +
    (b - 0.04) m`, Smith's GGX masking :math:`G_\alpha`, :math:`\alpha =
    r^2` (at least :data:`MIN_ALPHA`), and :math:`L_{lm}` the incoming
    light (with shadowing :math:`G_\alpha(\theta_i)` applied by the caller
    if wanted) band-limited by :math:`\alpha'`.

    Args:
        sh_in (torch.Tensor): Incoming SH per point :math:`(N, K, 3)`.
        irradiance (torch.Tensor): :math:`E` per point :math:`(N, 3)`.
        mirror_dir (torch.Tensor): Mirror directions :math:`r` in the local
            frames :math:`(N, V, 3)`; their :math:`z` is
            :math:`\cos\theta_o`.
        base_color, metallic, roughness (torch.Tensor): :math:`(N, 3)`,
            :math:`(N)`, :math:`(N)`.
        prefilter_alpha (float, optional): :math:`\alpha'`.
            (default: :obj:`0.0`)
        fresnel (bool, optional): Apply :math:`F(\theta_o)`, else
            :math:`R_0`. (default: :obj:`True`)
        masking (bool, optional): Apply :math:`G_\alpha(\theta_o)`.
            (default: :obj:`True`)
        specular_model (str, optional): :obj:`'eq5.11'` as above, or
            :obj:`'split_sum'`, which replaces :math:`F G_\alpha(\theta_o)`
            (and the caller's shadowing) by the exact directional albedo
            :math:`R_0 A(\theta_o, \alpha) + B(\theta_o, \alpha)` of
            :func:`ggx_albedo`, so that uniform light is reflected exactly
            at every roughness (eq. 5.11 overestimates rough lobes, whose
            mass below the horizon it keeps), and reads the filtered light
            at the lobe's dominant direction, :math:`r` pulled towards
            :math:`n` by :math:`s = (1 - \alpha)(\sqrt{1 - \alpha} +
            \alpha)` (Lagarde and de Rousiers 2014), as rough GGX lobes
            lean towards the normal. (default: :obj:`'eq5.11'`)
        basis_out (torch.Tensor, optional): Harmonics at :obj:`mirror_dir`
            (eq. 5.11) or at the :func:`dominant_direction` (split sum), if
            already computed. (default: :obj:`None`)

    Returns:
        :math:`(N, V, 3)`.
    """
    l_max = int(round(math.sqrt(sh_in.size(1)))) - 1
    if basis_out is None:
        direction = mirror_dir
        if specular_model == 'split_sum':
            direction = dominant_direction(mirror_dir, roughness)
        basis_out = real_sh(direction, l_max)
    return principled_reflectance(
        lobe_degree_sums(sh_in, basis_out), irradiance, mirror_dir,
        base_color, metallic, roughness, prefilter_alpha, fresnel, masking,
        specular_model)


def lobe_degree_sums(sh_in: Tensor, basis_out: Tensor) -> Tensor:
    r"""The incoming light read along every outgoing lobe direction, one sum
    per degree,

    .. math::
        S_l(\omega) = \sum_{m=-l}^{l} L_{lm}\, Y_{lm}(\omega),

    so that a lobe filter :math:`f_l(\alpha)` gives the specular light
    :math:`\sum_l f_l(\alpha) S_l` without touching the coefficients
    again: fitting a material changes only :math:`f_l`.

    Args:
        sh_in (torch.Tensor): Incoming SH per point :math:`(N, K, 3)`.
        basis_out (torch.Tensor): Harmonics at the lobe directions
            :math:`(N, V, K)`.

    Returns:
        :math:`(N, V, 3, l^* + 1)`, the degree last.
    """
    l_max = int(round(math.sqrt(sh_in.size(1)))) - 1
    return torch.stack([basis_out[..., l * l:(l + 1) ** 2]
                        @ sh_in[:, l * l:(l + 1) ** 2]
                        for l in range(l_max + 1)], -1)  # noqa: E741


def principled_reflectance(degree_sums: Tensor, irradiance: Tensor,
                           mirror_dir: Tensor, base_color: Tensor,
                           metallic: Tensor, roughness: Tensor,
                           prefilter_alpha: float = 0.0, fresnel: bool = True,
                           masking: bool = True,
                           specular_model: str = 'eq5.11') -> Tensor:
    r""":func:`sh_reflectance` from the light's :func:`lobe_degree_sums`
    (at the mirror directions for eq. 5.11, at the lobes' dominant
    directions for the split sum): the part that depends on the material,
    cheap enough to evaluate at every step of a fit.

    Returns:
        :math:`(N, V, 3)`.
    """
    alpha = model_alpha(roughness)
    lobe = lobe_filter(degree_sums.size(-1) - 1, alpha, prefilter_alpha,
                       per_degree=True)
    specular = (degree_sums @ lobe[:, None, :, None]).squeeze(-1)
    cos_out = mirror_dir[..., 2]
    r0 = 0.04 + (base_color - 0.04) * metallic.unsqueeze(-1)
    if specular_model == 'split_sum':
        specular = specular * ggx_albedo(cos_out, roughness, r0)
    else:
        r0 = r0.unsqueeze(1)
        if fresnel:
            specular = specular * schlick_fresnel(cos_out.unsqueeze(-1), r0)
        else:
            specular = specular * r0
        if masking:
            specular = specular * smith_g1(cos_out, alpha.unsqueeze(-1)
                                           ).unsqueeze(-1)
    diffuse = base_color * (1 - metallic.unsqueeze(-1)) * irradiance / math.pi
    return diffuse.unsqueeze(1) + specular


def principled_reflectance_jacobian(
        degree_sums: Tensor, irradiance: Tensor, mirror_dir: Tensor,
        base_color: Tensor, metallic: Tensor, roughness: Tensor,
        prefilter_alpha: float = 0.0, fresnel: bool = True,
        masking: bool = True, specular_model: str = 'eq5.11') -> tuple:
    r""":func:`principled_reflectance` and its derivatives with respect to
    the base colour (3), metallic and roughness of each point, for
    per-point second-order fits. The model is bilinear in base colour and
    metallic, so those columns follow from its factors; the roughness
    column takes the derivatives of the lobe filter, the masking and the
    albedo table by forward-mode differentiation, and reads the light once
    for value and derivative.

    Returns:
        ``(value, jacobian)``: :math:`(N, V, 3)` and :math:`(N, V, 3, 5)`,
        columns :math:`(b_r, b_g, b_b, m, r)`.
    """
    n, v = mirror_dir.shape[:2]
    with forward_ad.dual_level():
        rough = forward_ad.make_dual(roughness, torch.ones_like(roughness))
        alpha = model_alpha(rough)
        lobe = forward_ad.unpack_dual(lobe_filter(
            degree_sums.size(-1) - 1, alpha, prefilter_alpha,
            per_degree=True))
        cos_out = mirror_dir[..., 2]
        if specular_model == 'split_sum':
            ones = torch.ones(n, 1, dtype=roughness.dtype,
                              device=roughness.device)
            bias = ggx_albedo(cos_out, rough, 0 * ones)
            slope = forward_ad.unpack_dual(ggx_albedo(cos_out, rough, ones)
                                           - bias)
            bias = forward_ad.unpack_dual(bias)
        elif masking:
            mask = forward_ad.unpack_dual(smith_g1(cos_out,
                                                   alpha.unsqueeze(-1)))
    light = torch.bmm(degree_sums.reshape(n, v * 3, -1),
                      torch.stack([lobe.primal, lobe.tangent], -1))
    light, light_d = light.view(n, v, 3, 2).unbind(-1)
    m = metallic.view(n, 1, 1)
    color = base_color.unsqueeze(1)
    r0 = 0.04 + (color - 0.04) * m
    diffuse = (irradiance / math.pi).unsqueeze(1).expand(n, v, 3)
    if specular_model == 'split_sum':
        weight = r0 * slope.primal + bias.primal
        weight_d = r0 * slope.tangent + bias.tangent
        d_r0 = light * slope.primal
    else:
        c = cos_out.clamp(0.0, 1.0).unsqueeze(-1)
        q = 1 - (1 - c) ** 5 if fresnel else torch.ones_like(c)
        g = mask.primal.unsqueeze(-1) if masking else torch.ones_like(c)
        g_d = mask.tangent.unsqueeze(-1) if masking else torch.zeros_like(c)
        fres = r0 * q + (1 - q)
        weight, weight_d = fres * g, fres * g_d
        d_r0 = light * q * g
    specular = light * weight
    value = color * (1 - m) * diffuse + specular
    jacobian = value.new_zeros(n, v, 3, 5)
    d_color = (1 - m) * diffuse + d_r0 * m
    jacobian[..., [0, 1, 2], [0, 1, 2]] = d_color
    jacobian[..., 3] = -color * diffuse + d_r0 * (color - 0.04)
    jacobian[..., 4] = light_d * weight + light * weight_d
    return value, jacobian


def spectral_grid(num_specular: int, num_roughness: int, dtype=torch.float64,
                  device=None):
    r"""The search grid: :math:`K_s` and roughness :math:`r` evenly in
    :math:`[0, 1]` (so :math:`\alpha = r^2` is denser at low roughness)."""
    return (torch.linspace(0, 1, num_specular, dtype=dtype, device=device),
            torch.linspace(0, 1, num_roughness, dtype=dtype, device=device))


def spectral_uncertainty(spectrum_in: Tensor, spectrum_out: Tensor,
                         grid=(32, 32), sigma: float = 1e-2,
                         prefilter_alpha: float = 0.0,
                         chunk_size: int = 16384):
    r"""Likelihood of the specular parameters given the power spectra of
    incoming and outgoing light, and its normalised entropy (eqs. 5.19 and
    5.25).

    Per channel, with both spectra divided by the light's band-limited
    power :math:`\sum_{l \leq l^*} S_L(l)`, so that the distance depends
    neither on the radiance scale nor on the light's mean (a Dirac light
    with a clear lobe then has entropy about 0.25, as in the paper's
    Figure 5.4),

    .. math::
        D(K_s, \alpha) = \sum_{l \geq 1} \left(S_B(l) - K_s^2
        e^{-2(\alpha^2 - \alpha'^2) l^2} S_L(l)\right)^2, \qquad
        d \propto e^{-D / (2\sigma^2)}, \qquad
        H = -\frac{\sum d \log d}{\log n}.

    The channel with the lowest entropy is reported (the most decisive
    one); its grid argmax gives :math:`\alpha`, and every channel's
    :math:`K_s` is its argmin of :math:`D` at that :math:`\alpha`. A point
    whose light is black in every channel, or that was never observed
    (zero spectra), has a flat likelihood: entropy 1; so does a channel
    without light. The grid is evaluated in float64 whatever the input.

    Args:
        spectrum_in (torch.Tensor): :math:`S_L(l)` :math:`(N, l^*+1, C)`.
        spectrum_out (torch.Tensor): :math:`S_B(l)` :math:`(N, l^*+1, C)`.
        grid (tuple, optional): Grid cells ``(specular, roughness)``.
            (default: :obj:`(32, 32)`)
        sigma (float, optional): :math:`\sigma`. (default: :obj:`1e-2`)
        prefilter_alpha (float, optional): :math:`\alpha'` of the light.
            (default: :obj:`0.0`)
        chunk_size (int, optional): Points per chunk (bounds the memory
            to about ``chunk_size * C * cells`` numbers).
            (default: :obj:`16384`)

    Returns:
        ``(entropy (N), likelihood (N, grid[0], grid[1]), roughness (N),
        specular (N, C))``.
    """
    num_ks, num_r = grid
    ks, roughness = spectral_grid(num_ks, num_r, spectrum_in.dtype,
                                  spectrum_in.device)
    l = torch.arange(1, spectrum_in.size(1), dtype=spectrum_in.dtype,
                     device=spectrum_in.device)  # noqa: E741
    alpha = roughness ** 2
    # (num_r, L): the squared lobe, e^{-2 (alpha^2 - alpha'^2) l^2}
    lobe = torch.exp(-2 * (alpha[:, None] ** 2 - prefilter_alpha ** 2)
                     * l * l)
    ks2 = ks * ks
    scale = 1 / (2 * sigma * sigma)
    out = ([], [], [], [])
    for start in range(0, spectrum_in.size(0), chunk_size):
        # float64 here: dividing by a tiny light power overflows float32
        s_in = spectrum_in[start:start + chunk_size].double()
        s_out = spectrum_out[start:start + chunk_size].double()
        power = s_in.sum(1, keepdim=True)
        # a channel without light carries no information: flat likelihood
        lit = power > 1e-30
        power = torch.where(lit, power, torch.ones_like(power))
        s_in = (lit * s_in[:, 1:] / power).transpose(1, 2)  # (n, C, L)
        s_out = (lit * s_out[:, 1:] / power).transpose(1, 2)
        # D = sum B^2 - 2 ks^2 sum B f L + ks^4 sum f^2 L^2, expanded so
        # the grid costs two small matrix products.
        cross = (s_out * s_in) @ lobe.double().t()  # (n, C, num_r)
        square = (s_in * s_in) @ (lobe * lobe).double().t()
        const = (s_out * s_out).sum(-1)  # (n, C)
        if cross.device.type == 'cpu':
            result = _grid_cpu(cross, square, const, ks2.double(), scale)
        else:
            result = _grid_torch(cross, square, const, ks2.double(), scale)
        entropy, p_best, r_index, ks_index = result
        dtype = spectrum_in.dtype
        out[0].append(entropy.to(dtype))
        out[1].append(p_best.to(dtype))
        out[2].append(roughness[r_index])
        out[3].append(ks[ks_index])
    return tuple(torch.cat(o) for o in out)


def _grid_torch(cross, square, const, ks2, scale):
    """The grid on any device, with broadcasting."""
    num_ks, num_r = ks2.numel(), cross.size(-1)
    u = ks2[:, None]
    distance = (const[..., None, None] - 2 * u * cross.unsqueeze(-2)
                + u * u * square.unsqueeze(-2)).clamp_min(0)
    log_like = -distance * scale
    log_p = log_like - torch.logsumexp(log_like, (-2, -1), keepdim=True)
    p = log_p.exp()
    entropy = -(p * log_p).sum((-2, -1)) / math.log(num_ks * num_r)
    best = entropy.argmin(-1)  # (n,)
    rows = torch.arange(best.numel(), device=best.device)
    p_best = p[rows, best]  # (n, num_ks, num_r)
    r_index = p_best.amax(-2).argmax(-1)
    ks_index = distance[rows, :, :, r_index].argmin(-1)  # (n, C)
    return entropy[rows, best].clamp(0, 1), p_best, r_index, ks_index


def _grid_cpu(cross, square, const, ks2, scale):
    """The grid on the CPU (float64): one compiled pass per point and
    channel, the exponentials computed once, nothing of size points x
    channels x grid allocated but the answer."""
    n, channels, num_r = cross.shape
    num_ks = ks2.numel()
    entropy = np.empty(n)
    p_best = np.empty((n, num_ks, num_r))
    r_index = np.empty(n, dtype=np.int64)
    ks_index = np.zeros((n, channels), dtype=np.int64)
    _grid_kernel(*(t.contiguous().numpy() for t in (
        cross, square, const, ks2)), float(scale), entropy, p_best, r_index,
        ks_index)
    return (torch.from_numpy(entropy), torch.from_numpy(p_best),
            torch.from_numpy(r_index), torch.from_numpy(ks_index))


_NEGLIGIBLE = 50.0


@jit(inline='always', fastmath=True)
def _distance(const, cross, square, u):  # pragma: no cover (numba)
    """D of eq. 5.19 at K_s^2 = u, clamped at 0 against rounding."""
    return max(const - 2 * u * cross + u * u * square, 0.0)


@jit(parallel=True, fastmath=True)
def _grid_kernel(cross, square, const, ks2, scale, entropy, p_best, r_index,
                 ks_index):  # pragma: no cover (numba)
    n, channels, num_r = cross.shape
    num_ks = ks2.size
    log_cells = np.log(num_ks * num_r)
    for i in numba.prange(n):
        best_h = np.inf
        best_c = 0
        best_min = 0.0
        best_z = 1.0
        for c in range(channels):
            d_min = np.inf
            for k in range(num_ks):
                u = ks2[k]
                for a in range(num_r):
                    d = _distance(const[i, c], cross[i, c, a],
                                  square[i, c, a], u)
                    d_min = min(d_min, d)
            z = 0.0
            s = 0.0
            for k in range(num_ks):
                u = ks2[k]
                for a in range(num_r):
                    d = _distance(const[i, c], cross[i, c, a],
                                  square[i, c, a], u)
                    x = (d - d_min) * scale
                    if x < _NEGLIGIBLE:  # e^{-x} below 1e-22 adds nothing
                        e = np.exp(-x)
                        z += e
                        s += e * x
            # -sum p log p with p = e^{-x} / z is log z + sum e x / z
            h = (np.log(z) + s / z) / log_cells
            if h < best_h:
                best_h, best_c, best_min, best_z = h, c, d_min, z
        entropy[i] = min(max(best_h, 0.0), 1.0)
        c = best_c
        best_p = -1.0
        best_a = 0
        for k in range(num_ks):
            u = ks2[k]
            for a in range(num_r):
                d = _distance(const[i, c], cross[i, c, a], square[i, c, a],
                              u)
                x = (d - best_min) * scale
                p = np.exp(-x) / best_z if x < _NEGLIGIBLE else 0.0
                p_best[i, k, a] = p
                if p > best_p:
                    best_p, best_a = p, a
        r_index[i] = best_a
        for c in range(channels):
            d_best = np.inf
            for k in range(num_ks):
                u = ks2[k]
                d = max(const[i, c] - 2 * u * cross[i, c, best_a]
                        + u * u * square[i, c, best_a], 0.0)
                if d < d_best:
                    d_best = d
                    ks_index[i, c] = k


def observed_spectra(sh_in: Tensor, sh_out: Tensor):
    """Power spectra of incoming and outgoing SH :math:`(N, K, C)` as
    :math:`(N, l^*+1, C)`."""
    l_max = int(round(math.sqrt(sh_in.size(1)))) - 1
    assert num_coefficients(l_max) == sh_in.size(1)
    return (power_spectrum(sh_in.transpose(1, 2), l_max).transpose(1, 2),
            power_spectrum(sh_out.transpose(1, 2), l_max).transpose(1, 2))

