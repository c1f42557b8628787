r"""Which views to take or keep: greedy selection of cameras by the expected
reduction of the spectral uncertainty (Wiersma et al., "Uncertainty for
SVBRDF Acquisition using Frequency Analysis", SIGGRAPH 2025, Fig. 5.8,
"guiding capture").

Directions are in each point's local frame (rows :math:`e_u, e_v, n`), as
in :mod:`~tg_intrinsic.geometry.appearance.brdf`.
"""
import math
from typing import Sequence, Tuple

import torch
from torch import Tensor

from ..checks import (check_float_tensor, check_positive_float,
                      check_positive_int, check_tensor, check_view_indices)
from .brdf import (lobe_degree_sums, lobe_filter, model_alpha,
                   observed_spectra, spectral_uncertainty)
from .sh import num_coefficients, real_sh


class _Estimate:
    """The spectral state of a set of views: per point the Gram matrix and
    right-hand sides of the regularised SH fit (outgoing radiance and
    light, one factorisation as in ``FitSphericalHarmonics``), and what
    :func:`spectral_uncertainty` makes of them."""

    def __init__(self, basis, weight, light, sh_in, irradiance, regularizer,
                 prefilter_alpha, grid, sigma, chunk_size):
        self.basis, self.weight, self.light = basis, weight, light
        self.sh_in, self.irradiance = sh_in, irradiance
        self.prefilter, self.grid, self.sigma = prefilter_alpha, grid, sigma
        self.chunk_size = chunk_size
        num, _, k = basis.shape
        self.l_max = int(round(math.sqrt(k))) - 1
        degree = torch.arange(self.l_max + 1, dtype=basis.dtype,
                              device=basis.device)
        degree = degree.repeat_interleave(2 * degree.long() + 1)
        self.gram = (regularizer * torch.diag(torch.exp(degree))).expand(
            num, k, k).clone()
        self.rhs = basis.new_zeros(num, k, 6)
        self.seen = torch.zeros(num, dtype=torch.bool, device=basis.device)

    def add(self, view: int, radiance: Tensor):
        """Adds the observations :obj:`radiance` :math:`(N, 3)` of a view."""
        y, w = self.basis[:, view], self.weight[:, view]
        yw = y * w[:, None]
        self.gram += yw[:, :, None] * y[:, None, :]
        values = torch.cat([torch.where(w[:, None] > 0, radiance,
                                        torch.zeros_like(radiance)),
                            self.light[:, view]], -1)
        self.rhs += yw[:, :, None] * values[:, None, :]
        self.seen |= w > 0

    def entropy(self, gram, rhs):
        """Entropy, roughness and specular of the SH fits ``gram c = rhs``
        (first three columns outgoing, last three light)."""
        both = torch.cholesky_solve(rhs, torch.linalg.cholesky(gram))
        sh_out, sh_in_obs = both[..., :3], both[..., 3:]
        spectrum_in, spectrum_out = observed_spectra(sh_in_obs, sh_out)
        entropy, _, roughness, specular = spectral_uncertainty(
            spectrum_in, spectrum_out, self.grid, self.sigma, self.prefilter,
            self.chunk_size)
        return entropy, roughness, specular, sh_out, sh_in_obs

    def fit(self):
        """The current entropy :math:`(N)` and the spectrum argmax of every
        point, the estimate that predicts unseen views (as
        ``SpectralUncertainty``: :math:`K_s`, :math:`r` and :math:`K_d`
        from degree 0). Points no view sees yet take the mean estimate of
        the seen ones, a population prior, so that views of them are
        predicted to show something."""
        entropy, roughness, specular, sh_out, sh_in_obs = self.entropy(
            self.gram, self.rhs)
        diffuse_mean = sh_out[:, 0] - specular * sh_in_obs[:, 0]
        diffuse = (math.pi * diffuse_mean / (math.sqrt(4 * math.pi)
                                             * self.irradiance.clamp_min(
                                                 1e-12))).clamp(0, 1)
        if bool(self.seen.any()) and not bool(self.seen.all()):
            unseen = ~self.seen
            roughness = torch.where(unseen, roughness[self.seen].mean(),
                                    roughness)
            specular = torch.where(unseen[:, None],
                                   specular[self.seen].mean(0), specular)
            diffuse = torch.where(unseen[:, None],
                                  diffuse[self.seen].mean(0), diffuse)
        self.current = entropy
        self.roughness, self.specular, self.diffuse = (roughness, specular,
                                                       diffuse)
        return entropy

    def predict(self, point: Tensor, view: Tensor) -> Tensor:
        r"""The radiance the model of the current estimate predicts for
        pairs (point, view), :math:`(P, 3)`:

        .. math::
            \hat B = \frac{K_d E}{\pi} + K_s \sum_{lm}
            e^{-(\alpha^2 - \alpha'^2) l^2} L_{lm} Y_{lm}(r),

        the model whose spectrum the uncertainty scores (eq. 5.19, with
        the diffuse mean of ``SpectralUncertainty``), clamped at 0."""
        sums = lobe_degree_sums(self.sh_in[point],
                                self.basis[point, view][:, None])[:, 0]
        lobe = lobe_filter(self.l_max, model_alpha(self.roughness[point]),
                           self.prefilter, per_degree=True)
        specular = (sums @ lobe[:, :, None]).squeeze(-1)
        return (self.diffuse[point] * self.irradiance[point] / math.pi
                + self.specular[point] * specular).clamp_min(0)

    def gains(self, candidates: Sequence[int]) -> Tensor:
        """Expected reduction of the summed entropy per candidate: every
        point the candidate sees is refitted with one more sample (the
        predicted radiance, the known light); the others do not change."""
        candidates = torch.as_tensor(candidates, device=self.basis.device)
        visible = self.weight[:, candidates] > 0  # (N, C)
        point, which = visible.nonzero(as_tuple=True)
        total = self.basis.new_zeros(candidates.numel())
        for start in range(0, point.numel(), self.chunk_size):
            p = point[start:start + self.chunk_size]
            c = which[start:start + self.chunk_size]
            view = candidates[c]
            y, w = self.basis[p, view], self.weight[p, view]
            yw = y * w[:, None]
            gram = self.gram[p] + yw[:, :, None] * y[:, None, :]
            values = torch.cat([self.predict(p, view), self.light[p, view]],
                               -1)
            rhs = self.rhs[p] + yw[:, :, None] * values[:, None, :]
            entropy = self.entropy(gram, rhs)[0]
            total.index_add_(0, c, self.current[p] - entropy)
        return total


def select_views(mirror_dir: Tensor, weight: Tensor, light: Tensor,
                 radiance: Tensor, sh_in: Tensor, irradiance: Tensor,
                 num_views: int, seed_views: Sequence[int] = (0, ),
                 candidates: Sequence[int] = None,
                 regularizer: float = 1e-4, prefilter_alpha: float = 0.0,
                 grid=(32, 32), sigma: float = 1e-2,
                 chunk_size: int = 2048) -> Tuple[Tensor, Tensor]:
    r"""Greedy next-view selection by expected entropy reduction. From the
    :obj:`seed_views`, it adds one candidate at a time, the one whose
    *predicted* observations lower the mean normalised entropy of
    :func:`~tg_intrinsic.geometry.appearance.brdf.spectral_uncertainty`
    the most,

    .. math::
        v^* = \operatorname*{arg\,max}_{v \in C \setminus S}
        \sum_{i\,:\,w_{iv} > 0} H_i(S) - H_i(S \cup \{v\};
        \hat B_{iv}),

    where :math:`H_i(S)` is point :math:`i`'s entropy from the SH fits
    (eq. 5.12, as ``FitSphericalHarmonics``) of the real observations of
    the chosen views :math:`S`, and :math:`\hat B_{iv}` is the radiance
    that the current estimate predicts for candidate :math:`v`: the
    spectrum argmax :math:`(K_d, K_s, \alpha)` of :math:`S` through the
    model the entropy scores,

    .. math::
        \hat B_{iv} = \frac{K_d E}{\pi} + K_s \sum_{lm}
        e^{-(\alpha^2 - \alpha'^2) l^2} L_{lm} Y_{lm}(r_{iv}).

    A candidate's real observations are never read (in guided capture the
    photo is not taken yet): only its geometry (:obj:`mirror_dir`,
    :obj:`weight`) and the known light there. Only the points the candidate
    sees are refitted, all candidates at once in chunks of
    :obj:`chunk_size` (point, view) pairs. Once chosen, a view's real
    observations enter the estimate for the next choice. Points seen by no
    chosen view yet are predicted with the mean estimate of the seen ones.
    Ties go to the earlier candidate; the result is deterministic.

    Args:
        mirror_dir (torch.Tensor): Mirror directions :math:`r` of every
            view in the local frames :math:`(N, V, 3)`.
        weight (torch.Tensor): Fit weights :math:`(N, V)`,
            :math:`\max(0, \cos\theta_o)` where the view sees the point,
            else 0.
        light (torch.Tensor): The (band-limited) light at the mirror
            directions :math:`(N, V, 3)`, known for every view.
        radiance (torch.Tensor): Observations :math:`(N, V, 3)`; only the
            columns of the seed and the chosen views but the last are read
            (the others may be anything, NaN included).
        sh_in (torch.Tensor): The light's SH in the local frames
            :math:`(N, K, 3)`, :math:`K = (l^* + 1)^2`.
        irradiance (torch.Tensor): :math:`E` :math:`(N, 3)`.
        num_views (int): Views to return, seed included.
        seed_views (sequence of int, optional): Views taken first, at least
            one. (default: :obj:`(0,)`)
        candidates (sequence of int, optional): Views to choose from
            (default: all others). (default: :obj:`None`)
        regularizer (float, optional): :math:`\lambda` of the SH fit.
            (default: :obj:`1e-4`)
        prefilter_alpha (float, optional): :math:`\alpha'` of the light.
            (default: :obj:`0.0`)
        grid (tuple, optional): Cells of the uncertainty grid.
            (default: :obj:`(32, 32)`)
        sigma (float, optional): :math:`\sigma` of the likelihood.
            (default: :obj:`1e-2`)
        chunk_size (int, optional): (point, view) pairs refitted at once.
            (default: :obj:`2048`)

    Returns:
        ``(views, mean_entropy)``: the chosen view indices
        :math:`(\text{num\_views})` (long; the seed first, then in the
        order chosen) and the mean entropy over all points
        :math:`(\text{num\_views} - |S_0| + 1)`: of the seed's
        observations, then the expected value after each added view, as
        predicted before its photo (the real observations of the views
        chosen before it, its predicted ones). The last chosen view's
        observations are never read, so a capture asks for the next view
        with :obj:`num_views` one more than the views taken.
    """
    mirror_dir = check_tensor(mirror_dir, 'mirror_dir')
    if mirror_dir.dim() != 3 or mirror_dir.size(-1) != 3:
        raise ValueError(f"'mirror_dir' must have shape [N, V, 3], got "
                         f"{list(mirror_dir.shape)}")
    num, total = mirror_dir.shape[:2]
    mirror_dir = check_float_tensor(mirror_dir, 'mirror_dir',
                                    (num, total, 3))
    weight = check_float_tensor(weight, 'weight', (num, total))
    if bool((weight < 0).any()):
        raise ValueError("'weight' must be non-negative (max(0, cos) where "
                         "the view sees the point, else 0)")
    light = check_float_tensor(light, 'light', (num, total, 3))
    if not (isinstance(radiance, Tensor) and radiance.shape == (num, total,
                                                                3)):
        raise ValueError(f"'radiance' must be a tensor [{num}, {total}, 3], "
                         f"got {getattr(radiance, 'shape', type(radiance))}")
    sh_in = check_tensor(sh_in, 'sh_in')
    if sh_in.dim() != 3:
        raise ValueError(f"'sh_in' must have shape [{num}, K, 3], got "
                         f"{list(sh_in.shape)}")
    sh_in = check_float_tensor(sh_in, 'sh_in', (num, sh_in.size(1), 3))
    l_max = int(round(math.sqrt(sh_in.size(1)))) - 1
    if l_max < 1 or num_coefficients(l_max) != sh_in.size(1):
        raise ValueError(f"'sh_in' must hold (l* + 1)^2 >= 4 coefficients, "
                         f"got {sh_in.size(1)}")
    irradiance = check_float_tensor(irradiance, 'irradiance', (num, 3))
    num_views = check_positive_int(num_views, 'num_views')
    seed = check_view_indices(seed_views, 'seed_views', total)
    if not seed:
        raise ValueError("'seed_views' must hold at least one view: the "
                         "first estimate needs observations")
    if candidates is None:
        candidates = [v for v in range(total) if v not in seed]
    candidates = check_view_indices(candidates, 'candidates', total)
    overlap = sorted(set(seed) & set(candidates))
    if overlap:
        raise ValueError(f"views {overlap} are both seed views and "
                         f"candidates")
    if num_views < len(seed):
        raise ValueError(f"'num_views' ({num_views}) is smaller than the "
                         f"{len(seed)} seed views")
    if num_views > len(seed) and not candidates:
        raise ValueError("there are no candidate views to choose from")
    if num_views > len(seed) + len(candidates):
        raise ValueError(f"'num_views' ({num_views}) exceeds the "
                         f"{len(seed)} seed views plus {len(candidates)} "
                         f"candidates")
    regularizer = check_positive_float(regularizer, 'regularizer')
    prefilter_alpha = check_positive_float(prefilter_alpha,
                                           'prefilter_alpha', allow_zero=True)
    chunk_size = check_positive_int(chunk_size, 'chunk_size')

    dtype = mirror_dir.dtype
    estimate = _Estimate(real_sh(mirror_dir, l_max), weight.to(dtype),
                         light.to(dtype), sh_in.to(dtype),
                         irradiance.to(dtype), regularizer, prefilter_alpha,
                         grid, sigma, chunk_size)

    def take(view):
        observed = radiance[:, view].to(dtype)
        if not bool(torch.isfinite(observed[weight[:, view] > 0]).all()):
            raise ValueError(f"'radiance' of the chosen view {view} holds "
                             f"NaN or infinite values where it sees points")
        estimate.add(view, observed)

    for view in seed:
        take(view)
    chosen, remaining = list(seed), list(candidates)
    current = estimate.fit().mean()
    mean_entropy = [current]
    while len(chosen) < num_views:
        gains = estimate.gains(remaining)
        best = int(gains.argmax())  # the first of ties
        mean_entropy.append(current - gains[best] / num)
        chosen.append(remaining.pop(best))
        if len(chosen) < num_views:  # the photo is taken: refit with it
            take(chosen[-1])
            current = estimate.fit().mean()
    return (torch.tensor(chosen, dtype=torch.long, device=mirror_dir.device),
            torch.stack(mean_entropy))
