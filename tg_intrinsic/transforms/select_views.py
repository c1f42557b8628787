import math
from typing import Sequence

import torch
from torch_geometric.data import Batch, Data
from torch_geometric.data.datapipes import functional_transform

from tg_intrinsic.geometry.appearance.brdf import reflect, to_local
from tg_intrinsic.geometry.appearance.envmap import (check_envmap,
                                                     equirect_lookup,
                                                     filter_envmap)
from tg_intrinsic.geometry.appearance.view_selection import \
    select_views as greedy_views
from tg_intrinsic.geometry.checks import (check_positive_float,
                                          check_positive_int,
                                          check_view_indices)

from ._batching import GraphTransform, map_graphs
from .fit_spherical_harmonics import FitSphericalHarmonics

#: Attributes with one entry per view on their first axis; the observations
#: (``obs_*``) have it second.
PER_VIEW = ('intrinsics', 'extrinsics', 'images', 'view_index',
            'view_lighting')
OBSERVATIONS = ('obs_radiance', 'obs_dir', 'obs_mask')
#: Attributes computed from the observations, stale once views are dropped.
DERIVED = ('sh_out', 'sh_in_obs', 'mirror_dir', 'entropy', 'likelihood')


def keep_views(data: Data, views) -> Data:
    r"""A copy of a capture with only :obj:`views` (in that order): slices
    the view axis of ``obs_radiance``, ``obs_dir``, ``obs_mask`` (second
    axis) and of ``intrinsics``, ``extrinsics``, ``images`` (first axis),
    and records the original indices in ``view_index`` (composed with an
    earlier ``view_index``). Run it before
    :class:`~tg_intrinsic.transforms.FitSphericalHarmonics`, whose outputs
    depend on the views. A collated
    :class:`~torch_geometric.data.Batch` keeps the same views of every
    capture in it.

    Args:
        data (Data): A capture (``obs_mask`` :math:`(N, V)` at least).
        views (sequence of int or torch.Tensor): Distinct indices in
            :math:`[0, V)`.

    Returns:
        :class:`~torch_geometric.data.Data`, or a
        :class:`~torch_geometric.data.Batch` for a batch.
    """
    if isinstance(data, Batch):
        return map_graphs(lambda graph: keep_views(graph, views), data,
                          'keep_views')
    mask = getattr(data, 'obs_mask', None)
    if mask is None or mask.dim() != 2:
        raise ValueError("keep_views needs the observations 'data.obs_mask' "
                         "[N, V] (from svbrdf_scene or ProjectViews)")
    stale = [k for k in DERIVED if getattr(data, k, None) is not None]
    if stale:
        raise ValueError(f"data already holds {stale}, computed from all "
                         f"views; select views before FitSphericalHarmonics")
    total = mask.size(1)
    index = torch.tensor(check_view_indices(views, 'views', total),
                         dtype=torch.long)
    if index.numel() == 0:
        raise ValueError("'views' must hold at least one view")
    out = data.clone()
    if getattr(out, 'view_index', None) is None:
        out.view_index = torch.arange(total, device=mask.device)
    for key in OBSERVATIONS:
        value = getattr(out, key, None)
        if value is not None:
            out[key] = value[:, index.to(value.device)]
    for key in PER_VIEW:
        value = getattr(out, key, None)
        if value is not None:
            if value.size(0) != total:
                raise ValueError(f"'data.{key}' has {value.size(0)} views, "
                                 f"obs_mask {total}")
            out[key] = value[index.to(value.device)]
    return out


def join_lightings(captures: Sequence[Data]) -> Data:
    r"""One capture of an object photographed under several lightings:
    the views of every capture (of the same surface), each under its own
    capture's ``envmap``. The observations (``obs_*``, second axis) and
    the cameras (and ``images`` tensors, first axis) are concatenated,
    and the maps become ``envmaps`` :math:`(L, H, W, 3)` with
    ``view_lighting`` :math:`(V)`, the map of each view, which
    :meth:`~tg_intrinsic.nn.FrequencySVBRDF.recover` and
    :meth:`~tg_intrinsic.nn.FrequencySVBRDF.refine` use.

    Args:
        captures (sequence of Data): Captures of one surface (the same
            ``pos``), each with its ``envmap`` (all of one size) and its
            observations or photographs, none prepared further
            (``FitSphericalHarmonics`` models one lighting).
    """
    captures = list(captures)
    if not captures:
        raise ValueError("'captures' must hold at least one capture")
    first = captures[0]
    for index, capture in enumerate(captures):
        where = f"capture {index}"
        if getattr(capture, 'envmap', None) is None \
                or getattr(capture, 'view_lighting', None) is not None:
            raise ValueError(f"{where} must have one lighting, "
                             f"'data.envmap' [H, W, 3]")
        if capture.envmap.shape != first.envmap.shape:
            raise ValueError(f"{where}'s envmap is {list(capture.envmap.shape)}"
                             f" but the first's {list(first.envmap.shape)}; "
                             f"resample the maps to one size")
        if not torch.equal(capture.pos, first.pos):
            raise ValueError(f"{where} has another surface than the first "
                             f"('pos' differs); join captures of one object")
        stale = [k for k in DERIVED if getattr(capture, k, None) is not None]
        if stale:
            raise ValueError(f"{where} already holds {stale}, computed "
                             f"under one lighting; join the captures before "
                             f"FitSphericalHarmonics")
        if not torch.is_tensor(getattr(capture, 'images', torch.empty(0))):
            raise ValueError(f"{where}'s photographs are read from disk; "
                             f"project them first (ProjectViews)")
    out = first.clone()
    del out.envmap
    for key in OBSERVATIONS:
        if getattr(first, key, None) is not None:
            out[key] = torch.cat([c[key] for c in captures], 1)
    for key in PER_VIEW:
        if getattr(first, key, None) is not None:
            out[key] = torch.cat([c[key] for c in captures], 0)
    out.envmaps = torch.stack([c.envmap for c in captures])
    views = [c.intrinsics.size(0) for c in captures]
    out.view_lighting = torch.repeat_interleave(
        torch.arange(len(captures)), torch.tensor(views)).to(
            first.intrinsics.device)
    return out


@functional_transform('select_views')
class SelectViews(GraphTransform):
    r"""Keeps the :obj:`num_views` views that are expected to lower the
    spectral uncertainty the most, chosen greedily from :obj:`seed_views`
    by :func:`~tg_intrinsic.geometry.appearance.view_selection.select_views`
    (functional name: :obj:`select_views`). It follows Fig. 5.8 of
    Wiersma et al., "Uncertainty for SVBRDF Acquisition using Frequency
    Analysis" (SIGGRAPH 2025), choosing

    .. math::
        v^* = \operatorname*{arg\,max}_{v} \sum_{i\,:\,w_{iv} > 0}
        H_i(S) - H_i(S \cup \{v\}; \hat B_{iv}),

    with :math:`\hat B_{iv}` the radiance that the spectrum estimate of the
    chosen views :math:`S` predicts for candidate :math:`v`: the
    candidates' own observations are never read, only their geometry and
    the known light, so the same selection guides a capture whose photos
    are not taken yet (call it once per new photo, with
    :obj:`num_views` one more than the views taken).

    The light is band-limited by :math:`\alpha' = \max(K^{-1/2}, 1/l^*)`
    for :math:`K` = :obj:`num_views` throughout (what
    :class:`~tg_intrinsic.transforms.FitSphericalHarmonics` uses for the
    kept views), so that a candidate changes only the points it sees.

    Writes a copy of the capture restricted to the chosen views
    (:func:`keep_views`: ``obs_*``, ``intrinsics``, ``extrinsics``,
    ``images`` sliced, ``view_index`` the original indices in the order
    chosen) and ``selection_entropy``, the mean entropy over all points
    after the seed and after each added view (from their real
    observations, with that fixed :math:`\alpha'`).

    Args:
        num_views (int): Views to keep, the seed included.
        seed_views (sequence of int, optional): Views taken first.
            (default: :obj:`(0,)`)
        candidates (sequence of int, optional): Views to choose from
            (default: all others). (default: :obj:`None`)
        l_max (int, optional): Highest SH degree :math:`l^*`.
            (default: :obj:`5`)
        regularizer (float, optional): :math:`\lambda` of the SH fit.
            (default: :obj:`1e-4`)
        num_light_samples (int, optional): Light samples per point.
            (default: :obj:`1024`)
        prefilter_alpha (float, optional): :math:`\alpha'` instead of the
            default above. (default: :obj:`None`)
        grid (tuple, optional): Cells of the uncertainty grid.
            (default: :obj:`(32, 32)`)
        sigma (float, optional): :math:`\sigma` of the likelihood.
            (default: :obj:`1e-2`)

    Shapes:
        - **input:** ``pos``, ``normal`` :math:`(N, 3)`, ``envmap``
          :math:`(H, W, 3)`, ``obs_radiance``, ``obs_dir`` :math:`(N, V,
          3)`, ``obs_mask`` :math:`(N, V)` (``obs_radiance`` read only for
          the seed and the chosen views)
        - **output:** the same with :math:`V` = :obj:`num_views`,
          ``view_index`` :math:`(\text{num\_views})`,
          ``selection_entropy`` :math:`(\text{num\_views} -
          |\text{seed}| + 1)`
    """
    def __init__(self, num_views: int, seed_views: Sequence[int] = (0, ),
                 candidates: Sequence[int] = None, l_max: int = 5,
                 regularizer: float = 1e-4, num_light_samples: int = 1024,
                 prefilter_alpha: float = None, grid=(32, 32),
                 sigma: float = 1e-2):
        self.num_views = check_positive_int(num_views, 'num_views')
        self.seed_views = tuple(seed_views)
        self.candidates = None if candidates is None else tuple(candidates)
        self.l_max = check_positive_int(l_max, 'l_max')
        self.regularizer = check_positive_float(regularizer, 'regularizer')
        self.num_light_samples = num_light_samples
        if prefilter_alpha is not None:
            prefilter_alpha = check_positive_float(
                prefilter_alpha, 'prefilter_alpha', allow_zero=True)
        self.prefilter_alpha = prefilter_alpha
        self.grid, self.sigma = grid, sigma

    def forward(self, data: Data) -> Data:
        for key in OBSERVATIONS + ('envmap', 'normal'):
            if getattr(data, key, None) is None:
                raise ValueError(f"SelectViews needs 'data.{key}' (a capture "
                                 f"from svbrdf_scene or ProjectViews)")
        prefilter = self.prefilter_alpha
        if prefilter is None:
            prefilter = max(1 / math.sqrt(self.num_views), 1 / self.l_max)
        # frame, light SH and irradiance from the seed views alone (they
        # do not depend on the radiance, and no candidate is read)
        try:
            seed = keep_views(data, list(self.seed_views))
        except ValueError as error:
            raise ValueError(f"'seed_views': {error}") from None
        seed = FitSphericalHarmonics(
            l_max=self.l_max, regularizer=self.regularizer,
            num_light_samples=self.num_light_samples,
            prefilter_alpha=prefilter)(seed)
        dtype = seed.sh_in.dtype
        normal = seed.normal.to(dtype)
        normal = normal / normal.norm(dim=-1, keepdim=True).clamp_min(1e-30)
        mirror = reflect(data.obs_dir.to(dtype), normal.unsqueeze(1))
        mirror_local = to_local(mirror, seed.frame)
        weight = mirror_local[..., 2].clamp_min(0) * data.obs_mask.bool()
        envmap = check_envmap(data.envmap).to(normal.device, dtype)
        light = filter_envmap(envmap, prefilter) if prefilter > 0 else envmap
        views, mean_entropy = greedy_views(
            mirror_local, weight, equirect_lookup(light, mirror),
            data.obs_radiance, seed.sh_in, seed.irradiance, self.num_views,
            self.seed_views, self.candidates, self.regularizer, prefilter,
            self.grid, self.sigma)
        out = keep_views(data, views)
        out.selection_entropy = mean_entropy
        return out

    def __repr__(self) -> str:
        return (f'{self.__class__.__name__}(num_views={self.num_views}, '
                f'seed_views={self.seed_views}, l_max={self.l_max}, '
                f'prefilter_alpha={self.prefilter_alpha})')
