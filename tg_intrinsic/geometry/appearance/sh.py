r"""Real spherical harmonics and their fitting to sparse samples, in torch
(autograd, any device).

Convention: real orthonormal harmonics built from the complex ones with the
Condon-Shortley phase (as scipy's ``sph_harm_y``),

.. math::
    Y_{lm} = \begin{cases}
      \sqrt{2}\,\operatorname{Re} Y_l^{m} & m > 0 \\
      Y_l^0 & m = 0 \\
      \sqrt{2}\,\operatorname{Im} Y_l^{|m|} & m < 0,
    \end{cases}

so that :math:`Y_{1,1} = -\sqrt{3/4\pi}\,x`, :math:`Y_{1,-1} =
-\sqrt{3/4\pi}\,y` and :math:`Y_{1,0} = \sqrt{3/4\pi}\,z` for a unit
direction :math:`(x, y, z)` (polar angle from :math:`+z`). Coefficient
:math:`(l, m)` sits at index :math:`l (l + 1) + m`; degree :math:`l^*` has
:math:`(l^* + 1)^2` of them.
"""
import math

import torch
from torch import Tensor

from ..checks import check_positive_int, check_tensor


def num_coefficients(l_max: int) -> int:
    """:math:`(l^* + 1)^2`, the harmonics up to degree ``l_max``."""
    return (l_max + 1) ** 2


def sh_index(l: int, m: int) -> int:  # noqa: E741
    """Position of :math:`Y_{lm}` in the coefficient vector."""
    return l * (l + 1) + m


def real_sh(directions: Tensor, l_max: int) -> Tensor:
    r"""The real orthonormal spherical harmonics :math:`Y_{lm}` up to degree
    :obj:`l_max` at unit :obj:`directions` :math:`(\ldots, 3)`, as
    :math:`(\ldots, (l^*+1)^2)`.

    Computed as polynomials in :math:`x, y, z` (the Legendre recurrence
    divided by :math:`\sin^m\theta`, times :math:`\operatorname{Re}/
    \operatorname{Im} (x + i y)^m`), so there is no :math:`\arctan` and no
    singularity at the poles, and gradients flow through the directions.
    Directions are used as given; normalise them first."""
    l_max = check_positive_int(l_max, 'l_max', minimum=0)
    directions = check_tensor(directions, 'directions')
    if directions.size(-1) != 3:
        raise ValueError(f"'directions' must end in 3 coordinates, got "
                         f"shape {list(directions.shape)}")
    if not directions.is_floating_point():
        raise ValueError("'directions' must be a float tensor")
    x, y, z = directions.unbind(-1)
    out = directions.new_empty(directions.shape[:-1]
                               + (num_coefficients(l_max), ))
    # cos(m phi) sin^m(theta) and sin(m phi) sin^m(theta) by recurrence
    cos_m, sin_m = [torch.ones_like(x)], [torch.zeros_like(x)]
    for m in range(1, l_max + 1):
        c, s = cos_m[-1], sin_m[-1]
        cos_m.append(x * c - y * s)
        sin_m.append(x * s + y * c)
    # q_lm = N_lm P_l^m(z) / sin^m(theta), normalised as it goes (no
    # factorials, so any degree fits in float32): q_mm from q_{m-1,m-1},
    # q_{m+1,m} = sqrt(2m + 3) z q_mm, then the three-term recurrence with
    # a_lm = sqrt((4 l^2 - 1) / (l^2 - m^2)). Condon-Shortley phase in q_mm.
    diagonal = math.sqrt(1 / (4 * math.pi))
    for m in range(l_max + 1):
        if m > 0:
            diagonal *= -math.sqrt((2 * m + 1) / (2 * m))
        q_prev, q = None, torch.full_like(z, diagonal)
        a_prev = 0.0
        for l in range(m, l_max + 1):  # noqa: E741
            if l == m + 1:
                a = math.sqrt(2 * m + 3)
                q_prev, q = q, a * z * q
                a_prev = a
            elif l > m + 1:
                a = math.sqrt((4 * l * l - 1) / (l * l - m * m))
                q_prev, q = q, a * (z * q - q_prev / a_prev)
                a_prev = a
            if m == 0:
                out[..., sh_index(l, 0)] = q
            else:
                scaled = math.sqrt(2) * q
                out[..., sh_index(l, m)] = scaled * cos_m[m]
                out[..., sh_index(l, -m)] = scaled * sin_m[m]
    return out


def fibonacci_sphere(n: int, dtype=torch.float64, device=None) -> Tensor:
    r"""``n`` nearly uniform unit directions :math:`(n, 3)` on the
    Fibonacci spiral: :math:`z_k = 1 - (2k + 1)/n`, azimuth :math:`k`
    times the golden angle."""
    if not isinstance(n, int) or n < 1:
        raise ValueError(f"'n' must be a positive integer, got {n!r}")
    k = torch.arange(n, dtype=dtype, device=device)
    z = 1 - (2 * k + 1) / n
    radius = torch.sqrt((1 - z * z).clamp_min(0))
    phi = k * math.pi * (3 - math.sqrt(5))
    return torch.stack([radius * torch.cos(phi), radius * torch.sin(phi), z],
                       -1)


def fit_sh(directions: Tensor, values: Tensor, l_max: int,
           weights: Tensor = None, regularizer: float = 1e-4) -> Tensor:
    r"""Regularised least-squares spherical-harmonic coefficients of sparse
    samples, batched over leading dimensions. They solve

    .. math::
        (Y^\top W Y + \lambda\,\operatorname{diag}(e^{l}))\,c = Y^\top W f,

    with :math:`Y` the harmonics at the sample directions, :math:`W` the
    sample :obj:`weights` (default 1; e.g. :math:`\max(0, \cos\theta)`) and
    :math:`\lambda` the :obj:`regularizer`, which damps high degrees and
    keeps the system solvable with fewer samples than coefficients.

    Args:
        directions (torch.Tensor): Unit directions :math:`(\ldots, S, 3)`.
        values (torch.Tensor): Samples :math:`(\ldots, S)` or
            :math:`(\ldots, S, C)` (channels).
        l_max (int): Highest degree.
        weights (torch.Tensor, optional): Non-negative sample weights
            :math:`(\ldots, S)`. (default: :obj:`None`)
        regularizer (float, optional): :math:`\lambda`.
            (default: :obj:`1e-4`)

    Returns:
        Coefficients :math:`(\ldots, (l^*+1)^2)` or :math:`(\ldots,
        (l^*+1)^2, C)`.
    """
    l_max = check_positive_int(l_max, 'l_max', minimum=0)
    if not (regularizer >= 0 and math.isfinite(regularizer)):
        raise ValueError(f"'regularizer' must be finite and >= 0, got "
                         f"{regularizer!r}")
    Y = real_sh(directions, l_max)  # (..., S, K)
    squeeze = values.dim() == Y.dim() - 1
    f = values.unsqueeze(-1) if squeeze else values
    if f.shape[:-1] != Y.shape[:-1]:
        raise ValueError(f"'values' must have one sample per direction: "
                         f"directions {list(directions.shape)}, values "
                         f"{list(values.shape)}")
    if not bool(torch.isfinite(f).all()):
        raise ValueError("'values' hold NaN or infinite samples; mask them "
                         "with zero weights instead")
    if weights is not None:
        if weights.shape != Y.shape[:-1] or bool((weights < 0).any()):
            raise ValueError("'weights' must be non-negative, one per "
                             "sample")
        Yw = Y * weights.unsqueeze(-1)
    else:
        Yw = Y
    degree = torch.arange(l_max + 1, dtype=Y.dtype, device=Y.device)
    degree = degree.repeat_interleave(2 * degree.long() + 1)
    gram = Yw.transpose(-1, -2) @ Y
    gram = gram + regularizer * torch.diag_embed(torch.exp(degree))
    if regularizer == 0:
        coefficients = torch.linalg.lstsq(gram, Yw.transpose(-1, -2) @ f
                                          ).solution
    else:
        # positive definite: Cholesky, about twice as fast as LU
        factor = torch.linalg.cholesky(gram)
        coefficients = torch.cholesky_solve(Yw.transpose(-1, -2) @ f,
                                            factor)
    return coefficients.squeeze(-1) if squeeze else coefficients


def power_spectrum(coefficients: Tensor, l_max: int) -> Tensor:
    r""":math:`S(l) = \sum_m c_{lm}^2` per degree: :math:`(\ldots,
    (l^*+1)^2)` to :math:`(\ldots, l^* + 1)`; invariant under rotations."""
    l_max = check_positive_int(l_max, 'l_max', minimum=0)
    if coefficients.size(-1) != num_coefficients(l_max):
        raise ValueError(f"expected {num_coefficients(l_max)} coefficients "
                         f"for l_max={l_max}, got {coefficients.size(-1)}")
    degree = torch.arange(l_max + 1, device=coefficients.device)
    index = degree.repeat_interleave(2 * degree + 1)
    out = coefficients.new_zeros(coefficients.shape[:-1] + (l_max + 1, ))
    return out.index_add(-1, index, coefficients * coefficients)


# ---------------------------------------------------------------- BRDF terms
def brdf_filter(l_max: int, alpha: Tensor) -> Tensor:
    r"""Spherical-harmonic attenuation of the Torrance-Sparrow lobe of
    roughness :math:`\alpha`, :math:`e^{-(\alpha l)^2}` per coefficient:
    :math:`(\ldots)` to :math:`(\ldots, (l^*+1)^2)` (Ramamoorthi and
    Hanrahan's frequency-space approximation)."""
    l_max = check_positive_int(l_max, 'l_max', minimum=0)
    alpha = torch.as_tensor(alpha)
    if not alpha.is_floating_point():
        alpha = alpha.double()
    degree = torch.arange(l_max + 1, dtype=alpha.dtype, device=alpha.device)
    degree = degree.repeat_interleave(2 * degree.long() + 1)
    return torch.exp(-(alpha.unsqueeze(-1) * degree) ** 2)


def schlick_fresnel(cos_theta: Tensor, r0: Tensor) -> Tensor:
    r"""Schlick's Fresnel :math:`F = R_0 + (1 - R_0)(1 - \cos\theta)^5`,
    with :math:`\cos\theta` clamped to :math:`[0, 1]`."""
    c = cos_theta.clamp(0.0, 1.0)
    return r0 + (1 - r0) * (1 - c) ** 5


def smith_g1(cos_theta: Tensor, alpha: Tensor) -> Tensor:
    r"""Smith's GGX shadowing-masking term for one direction. It is

    .. math::
        G_1 = \frac{2 \cos\theta}{\cos\theta + \sqrt{\alpha^2 + (1 -
        \alpha^2)\cos^2\theta}},

    0 at grazing and below the horizon, 1 at normal incidence."""
    c = cos_theta.clamp(0.0, 1.0)
    root = torch.sqrt(alpha ** 2 + (1 - alpha ** 2) * c * c)
    return torch.where(c > 0, 2 * c / (c + root).clamp_min(1e-30),
                       torch.zeros_like(c + root))


def principled_to_torrance_sparrow(base_color: Tensor, metallic: Tensor,
                                   roughness: Tensor):
    r"""Principled parameters to the Lambert + Torrance-Sparrow ones:
    diffuse albedo :math:`K_d = b (1 - m)`, specular reflectance at normal
    incidence :math:`R_0 = 0.04 + (b - 0.04) m` and lobe width
    :math:`\alpha = r^2`, for base colour :math:`b` :math:`(\ldots, 3)`,
    metallic :math:`m` and roughness :math:`r` :math:`(\ldots)`.
    Returns ``(kd, r0, alpha)``."""
    m = metallic.unsqueeze(-1)
    return base_color * (1 - m), 0.04 + (base_color - 0.04) * m, \
        roughness ** 2


def torrance_sparrow_to_principled(kd: Tensor, r0: Tensor, alpha: Tensor):
    r"""The inverse of :func:`principled_to_torrance_sparrow` with one
    metallic value shared by the colour channels.

    Per channel, :math:`K_d = b (1 - m)` and :math:`R_0 = 0.04 + (b - 0.04)
    m` give :math:`b = K_d + R_0 - 0.04 (1 - m)` and, with :math:`s = 1 - m`,

    .. math::
        0.04 s^2 - (K_d + R_0) s + K_d = 0.

    One channel alone is ambiguous (both roots are valid when :math:`b <
    0.04 s`); the shared metallic decides: of the six roots of the three
    channels, the :math:`s \in [0, 1]` with the smallest summed residual
    over the channels is taken (a grey colour stays ambiguous; it resolves to
    the less metallic reading). The base colour follows from it and the
    roughness is :math:`\sqrt{\alpha}`; everything is clamped to
    :math:`[0, 1]`. Exact for inputs made by
    :func:`principled_to_torrance_sparrow`. Returns ``(base_color,
    metallic, roughness)``."""
    total = kd + r0
    root = torch.sqrt((total * total - 0.16 * kd).clamp_min(0))
    # The smaller root without cancellation.
    small = 2 * kd / (total + root).clamp_min(1e-30)
    candidates = torch.cat([(total + root) / 0.08, small], -1).clamp(0, 1)
    s = candidates.unsqueeze(-1)  # (..., 6, 1) against channels (..., 1, 3)
    # The tiny tilt makes rounding-level ties (grey, b < 0.04 s) resolve to
    # the larger s, the less metallic reading.
    residual = (0.04 * s * s - total.unsqueeze(-2) * s
                + kd.unsqueeze(-2)).abs().sum(-1) - 1e-9 * candidates
    s = candidates.gather(-1, residual.argmin(-1, keepdim=True))
    metallic = (1 - s.squeeze(-1)).clamp(0, 1)
    base_color = (total - 0.04 * s).clamp(0, 1)
    return base_color, metallic, alpha.clamp(0, 1).sqrt()


def light_directions(num_samples: int, dtype=torch.float64, device=None):
    """The local sample directions of the incoming light (a Fibonacci
    sphere), shared by every point."""
    return fibonacci_sphere(num_samples, dtype=dtype, device=device)


def light_fit_matrix(directions, l_max: int, regularizer: float):
    r"""The regularised, cosine-weighted least-squares operator
    :math:`(Y^\top W Y + \lambda \operatorname{diag}(e^l))^{-1} Y^\top W`
    with :math:`W = \max(0, \cos\theta)`, :math:`(K, S)`, the same for
    every point. Only the upper hemisphere is fitted; the lower one is left
    to the regulariser, which continues the light smoothly (cutting it to
    zero at the horizon would ring through every degree instead)."""
    Y = real_sh(directions, l_max)
    weights = directions[:, 2].clamp_min(0).unsqueeze(-1)
    l = torch.arange(l_max + 1, dtype=Y.dtype, device=Y.device)  # noqa: E741
    l = l.repeat_interleave(2 * l.long() + 1)
    gram = (Y * weights).t() @ Y + regularizer * torch.diag(l.exp())
    return torch.linalg.solve(gram, (Y * weights).t())


def fit_light(directions: Tensor, samples: Tensor, l_max: int,
              regularizer: float) -> Tensor:
    r""":func:`light_fit_matrix` applied to the light samples of many
    points, :math:`(N, S, C)` at the shared :obj:`directions` :math:`(S,
    3)`, as one matrix product over the samples the fit reads (those above
    the horizon; the others have weight 0): :math:`(N, K, C)`."""
    upper = directions[:, 2] > 0
    matrix = light_fit_matrix(directions, l_max, regularizer)[:, upper]
    num, _, channels = samples.shape
    above = samples[:, upper].to(matrix.dtype)           # (N, S', C)
    out = matrix @ above.transpose(0, 1).reshape(matrix.size(1), -1)
    return out.view(-1, num, channels).transpose(0, 1)
