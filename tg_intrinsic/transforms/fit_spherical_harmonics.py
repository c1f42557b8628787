import math

import torch
from torch_geometric.data import Data
from torch_geometric.data.datapipes import functional_transform

from tg_intrinsic.geometry import tangent_frames
from tg_intrinsic.geometry.appearance.brdf import reflect, to_local
from tg_intrinsic.geometry.appearance.envmap import (check_envmap,
                                                     equirect_lookup,
                                                     filter_envmap, irradiance,
                                                     view_lightings)
from tg_intrinsic.geometry.appearance.observations import observed_slots
from tg_intrinsic.geometry.appearance.sh import (fit_light, fit_sh,
                                                 light_directions,
                                                 num_coefficients)
from tg_intrinsic.geometry.checks import (check_frames, check_points,
                                          check_positive_float,
                                          check_positive_int, check_vectors)
from tg_intrinsic.transforms._batching import GraphTransform


#: Points fitted at once: each point's fits are its own, and the
#: per-point matrices of all points at once held 3.9 GiB for 41k points
#: (25 views, 256 light samples, float64); in chunks of 8192 the fit
#: stays under a gigabyte whatever the number of points.
POINTS_PER_CHUNK = 8192


def _chunks(num: int, size: int):
    """Slices of ``range(num)`` of at most ``size``."""
    return [slice(start, min(start + size, num))
            for start in range(0, max(num, 1), size)]


@functional_transform('fit_spherical_harmonics')
class FitSphericalHarmonics(GraphTransform):
    r"""Fits spherical harmonics to the incoming and the observed outgoing
    radiance of every point, in its local frame (functional name:
    :obj:`fit_spherical_harmonics`). It follows eq. 5.12 of Wiersma et al.,
    "Uncertainty for SVBRDF Acquisition using Frequency Analysis"
    (SIGGRAPH 2025).

    Coefficients solve, per point and channel,

    .. math::
        (Y^\top W Y + \lambda \operatorname{diag}(e^{l}))\, c = Y^\top W f,
        \qquad W = \operatorname{diag}(\max(0, \cos\theta)),

    where the regulariser :math:`\lambda > 0` keeps points with fewer
    samples than coefficients solvable (a point seen by no view gets zero
    outgoing coefficients). The environment is first band-limited by a
    spherical Gaussian of width :math:`\alpha' = \max(V^{-1/2}, 1/l^*)`
    (:math:`V` views),
    so that the light holds no frequencies the sparse views cannot resolve;
    the lobe model undoes it with :math:`e^{-(\alpha^2 - \alpha'^2)l^2}`.

    Writes ``frame`` (if absent), ``sh_in`` (the light that reaches the
    surface: samples at :obj:`num_light_samples` Fibonacci directions of the
    local frame, zero below the horizon, fitted over the whole sphere so
    the lobe convolution sees no made-up light from below),
    ``light_radiance`` (those samples, for the shadowing refit of
    :meth:`~tg_intrinsic.nn.FrequencySVBRDF.fit`; :math:`12 S` bytes per
    point, 3 GB for 250k points, so it can be left out),
    ``sh_out`` (the observations as a function of their mirror direction
    :math:`r = 2(n \cdot \omega_o)n - \omega_o`), ``sh_in_obs`` (the light
    sampled at the same mirror directions with the same weights, so that
    its spectrum compares like with like against ``sh_out``), ``mirror_dir``
    (:math:`r` in the local frame), ``irradiance`` :math:`E(n) = \int L
    \max(0, n \cdot \omega)\, d\omega` of the unfiltered map, and
    ``sh_prefilter`` (:math:`\alpha'`) and ``sh_regularizer``.

    Args:
        l_max (int, optional): Highest degree :math:`l^*`. (default: :obj:`5`)
        regularizer (float, optional): :math:`\lambda`. (default: :obj:`1e-4`)
        num_light_samples (int, optional): Light samples per point, at
            least :math:`4 (l^* + 1)^2`. (default: :obj:`1024`)
        prefilter_alpha (float, optional): :math:`\alpha'`; by default
            :math:`\max(V^{-1/2}, 1/l^*)`; 0 switches the band limit off.
            (default: :obj:`None`)
        store_light_radiance (bool, optional): Keep ``light_radiance``
            (needed by :meth:`~tg_intrinsic.nn.FrequencySVBRDF.fit` with
            the shadowing of eq. 5.11, not by the refinement).
            (default: :obj:`True`)

    Shapes:
        - **input:** ``normal`` :math:`(N, 3)`, ``envmap`` :math:`(H, W, 3)`,
          ``obs_radiance`` :math:`(N, V, 3)`, ``obs_dir`` :math:`(N, V, 3)`,
          ``obs_mask`` :math:`(N, V)` (from
          :class:`~tg_intrinsic.transforms.ProjectViews`)
        - **output:** ``sh_in``, ``sh_out``, ``sh_in_obs`` :math:`(N, K, 3)`
          with :math:`K = (l^*+1)^2`, ``light_radiance`` :math:`(N, S, 3)`,
          ``mirror_dir`` :math:`(N, V, 3)`, ``irradiance`` :math:`(N, 3)`,
          ``frame`` :math:`(N, 3, 3)`, ``sh_prefilter`` and ``sh_regularizer``
          :math:`(1)`
    """
    def __init__(self, l_max: int = 5, regularizer: float = 1e-4,
                 num_light_samples: int = 1024,
                 prefilter_alpha: float = None,
                 store_light_radiance: bool = True):
        self.l_max = check_positive_int(l_max, 'l_max')
        self.regularizer = check_positive_float(regularizer, 'regularizer')
        self.num_light_samples = check_positive_int(num_light_samples,
                                                    'num_light_samples')
        if 4 * num_coefficients(l_max) > num_light_samples:
            raise ValueError(f"'num_light_samples' must be at least "
                             f"{4 * num_coefficients(l_max)} (4 per "
                             f"coefficient) for l_max={l_max}, got "
                             f"{num_light_samples}")
        if prefilter_alpha is not None:
            prefilter_alpha = check_positive_float(prefilter_alpha,
                                                   'prefilter_alpha',
                                                   allow_zero=True)
        self.prefilter_alpha = prefilter_alpha
        self.store_light_radiance = bool(store_light_radiance)

    def forward(self, data: Data) -> Data:
        pos = check_points(data.pos, 'pos')
        normal = getattr(data, 'normal', None)
        if normal is None:
            raise ValueError("FitSphericalHarmonics needs 'data.normal'; "
                             "estimate it with EstimateNormals")
        normal = check_vectors(normal, 'normal', pos.size(0), pos)
        normal = normal / normal.norm(dim=-1, keepdim=True).clamp_min(1e-30)
        if view_lightings(data) is not None:
            raise ValueError(
                "the views of this capture are lit by several maps "
                "('data.envmaps'); the harmonics model one lighting: fit "
                "each lighting's views on their own (keep_views, with its "
                "map as 'data.envmap'), as FrequencySVBRDF.recover does")
        envmap = getattr(data, 'envmap', None)
        if envmap is None:
            raise ValueError("FitSphericalHarmonics needs the lighting as "
                             "'data.envmap' [H, W, 3] (equirectangular, "
                             "z up; see tg_intrinsic.geometry.appearance.envmap)")
        envmap = check_envmap(envmap).to(pos.device, pos.dtype)
        for key in ('obs_radiance', 'obs_dir', 'obs_mask'):
            if getattr(data, key, None) is None:
                raise ValueError(f"FitSphericalHarmonics needs 'data.{key}'; "
                                 f"run ProjectViews first")
        radiance, view, mask = data.obs_radiance, data.obs_dir, data.obs_mask
        num, num_views = mask.shape
        if radiance.shape != (num, num_views, 3) or view.shape != (
                num, num_views, 3) or num != pos.size(0):
            raise ValueError(f"observations must be obs_radiance and obs_dir "
                             f"[N, V, 3] and obs_mask [N, V] with N = "
                             f"{pos.size(0)}, got {list(radiance.shape)}, "
                             f"{list(view.shape)}, {list(mask.shape)}")
        frame = getattr(data, 'frame', None)
        frame = tangent_frames(normal) if frame is None else check_frames(
            frame, num, pos)

        prefilter = self.prefilter_alpha
        if prefilter is None:
            prefilter = max(1 / math.sqrt(num_views), 1 / self.l_max)
        light = filter_envmap(envmap, prefilter) if prefilter > 0 else envmap

        local = light_directions(self.num_light_samples, pos.dtype,
                                 pos.device)
        # each point's fit over the views that see it (the others weigh
        # 0): a third of the work where a point is seen by a third of them
        slots, filled = observed_slots(mask)
        parts = [self._fit_points(light, local, normal[rows], frame[rows],
                                  view[rows], radiance[rows], slots[rows],
                                  filled[rows])
                 for rows in _chunks(num, POINTS_PER_CHUNK)]
        sh_in, light_radiance, mirror_local, sh_out, sh_in_obs = (
            torch.cat(column) for column in zip(*parts))

        data = data.clone()
        data.frame = frame
        data.sh_in = sh_in
        data.sh_out = sh_out
        data.sh_in_obs = sh_in_obs
        if self.store_light_radiance:
            data.light_radiance = light_radiance
        else:
            data.light_radiance = None
        data.mirror_dir = mirror_local
        data.irradiance = irradiance(envmap, normal)
        data.sh_prefilter = torch.tensor([prefilter], dtype=pos.dtype,
                                         device=pos.device)
        data.sh_regularizer = torch.tensor([self.regularizer],
                                           dtype=pos.dtype, device=pos.device)
        return data

    def _fit_points(self, light, local, normal, frame, view, radiance,
                    slots, filled):
        """The fits of some points (each point's are its own): light
        coefficients, the light at the samples (float32), the mirror
        directions of every view, and the outgoing and incoming
        coefficients at the observations, which sit in ``slots`` (N, K)
        where ``filled``."""
        # Incoming light at Fibonacci directions of every local frame, read
        # above the horizon only (the fit gives the others weight 0).
        upper = local[:, 2] > 0
        light_radiance = torch.zeros(normal.size(0), local.size(0), 3,
                                     dtype=normal.dtype, device=normal.device)
        light_radiance[:, upper] = equirect_lookup(light,
                                                   local[upper] @ frame)
        sh_in = fit_light(local, light_radiance, self.l_max,
                          self.regularizer)

        # Outgoing radiance as a function of the mirror direction.
        mirror = reflect(view, normal.unsqueeze(1))
        mirror_local = to_local(mirror, frame)

        def observed(t):
            return t.gather(1, slots.unsqueeze(-1).expand(-1, -1,
                                                          t.size(-1)))
        seen_local = observed(mirror_local)
        weights = seen_local[..., 2].clamp_min(0) * filled
        values = torch.where(filled.unsqueeze(-1),
                             observed(radiance).to(normal.dtype),
                             torch.zeros_like(seen_local))
        # one factorisation for both: same directions, same weights
        both = fit_sh(seen_local, torch.cat(
            [values, equirect_lookup(light, observed(mirror))], -1),
            self.l_max, weights, self.regularizer)
        return (sh_in, light_radiance.float() if self.store_light_radiance
                else light_radiance.new_zeros(0), mirror_local, both[..., :3],
                both[..., 3:])

    def __repr__(self) -> str:
        return (f'{self.__class__.__name__}(l_max={self.l_max}, '
                f'regularizer={self.regularizer}, num_light_samples='
                f'{self.num_light_samples}, prefilter_alpha='
                f'{self.prefilter_alpha})')
