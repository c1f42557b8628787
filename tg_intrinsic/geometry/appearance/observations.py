r"""The observations of a capture held per point rather than per view:
:math:`(N, K)` slots of the views that see each point, in place of the
:math:`(N, V)` grid whose unobserved entries are zeros. A point of a large
capture is seen by a fraction of the views (a third to a half around an
object), so the refinement's tables and solves cost :math:`N K` instead
of :math:`N V`; with :math:`K` capped, a point seen by more views keeps
those that cover its reflections best.
"""
from typing import Optional, Tuple

import torch
from torch import Tensor
from torch_geometric.data import Data

from ..checks import check_positive_int

__all__ = ['observed_slots', 'compact_observations', 'OBSERVED']

#: Attributes of the observations, the view on their second axis.
OBSERVED = ('obs_radiance', 'obs_dir', 'obs_mask', 'mirror_dir')


def observed_slots(mask: Tensor, max_views: Optional[int] = None,
                   mirror_dir: Optional[Tensor] = None,
                   radiance: Optional[Tensor] = None
                   ) -> Tuple[Tensor, Tensor]:
    r"""Per point, the views that observe it, in increasing order, as
    :math:`K` slots (:math:`K` the most views of any point, at most
    :obj:`max_views`). A point seen by more than :obj:`max_views` views
    keeps its brightest quarter (the highlights, which settle the
    roughness) and then, one at a time, the view whose mirror direction
    lies farthest from those kept (farthest-point sampling on the
    hemisphere: the rest of the lobe and the diffuse level from all
    sides).

    Args:
        mask (torch.Tensor): Observed pairs :math:`(N, V)`.
        max_views (int, optional): Most slots per point; :obj:`None` keeps
            every observation. (default: :obj:`None`)
        mirror_dir (torch.Tensor, optional): Unit mirror directions
            :math:`(N, V, 3)`, needed when a point has more than
            :obj:`max_views` views. (default: :obj:`None`)
        radiance (torch.Tensor, optional): Observed radiance
            :math:`(N, V, 3)`, as :obj:`mirror_dir`. (default: :obj:`None`)

    Returns:
        ``(view, valid)``: the view of every slot :math:`(N, K)` (0 in the
        empty ones) and whether it holds an observation :math:`(N, K)`.
    """
    mask = mask.bool()
    if max_views is not None:
        max_views = check_positive_int(max_views, 'max_views')
    count = mask.sum(1)
    over = count > max_views if max_views is not None else \
        torch.zeros_like(mask[:, 0])
    if bool(over.any()):
        if mirror_dir is None or radiance is None:
            raise ValueError("'mirror_dir' and 'radiance' are needed to "
                             "choose the views of points seen more than "
                             "'max_views' times")
        rows = over.nonzero().flatten()
        mask = mask.clone()
        mask[rows] = _cover(mask[rows], mirror_dir[rows], radiance[rows],
                            max_views)
        count = mask.sum(1)
    slots = max(int(count.max()), 1) if count.numel() else 1
    # observed views first, each in increasing order (a stable sort)
    order = torch.sort((~mask).to(torch.uint8), dim=1, stable=True).indices
    view = order[:, :slots]
    valid = torch.arange(slots, device=mask.device) < count.unsqueeze(1)
    return torch.where(valid, view, torch.zeros_like(view)), valid


def _cover(mask: Tensor, mirror_dir: Tensor, radiance: Tensor,
           max_views: int) -> Tensor:
    """The kept observations of points seen more than ``max_views``
    times: the brightest quarter, then farthest-point sampling of the
    mirror directions (vectorised over the points, a view per step)."""
    brightness = torch.where(mask, radiance.sum(-1),
                             torch.full_like(radiance[..., 0], -1.0))
    direction = mirror_dir.to(torch.float32)
    rows = torch.arange(mask.size(0), device=mask.device)
    kept = torch.zeros_like(mask)
    # each view's distance (1 - cosine) to the nearest kept direction
    nearest = torch.full(mask.shape, 3.0, dtype=torch.float32,
                         device=mask.device)

    def keep(pick: Tensor):
        nonlocal nearest
        kept[rows, pick] = True
        nearest = torch.minimum(nearest, 1 - (
            direction * direction[rows, pick].unsqueeze(1)).sum(-1))

    bright = max_views // 4
    if bright:
        for pick in brightness.topk(bright, dim=1).indices.t():
            keep(pick)
    for _ in range(max_views - bright):
        keep(torch.where(mask & ~kept, nearest,
                         torch.full_like(nearest, -1.0)).argmax(1))
    return kept & mask


def compact_observations(data: Data, max_views: Optional[int] = None
                         ) -> Data:
    r"""A shallow copy of a prepared capture whose observations
    (:data:`OBSERVED`) are held in the slots of :func:`observed_slots`,
    :math:`(N, K, \ldots)` in place of :math:`(N, V, \ldots)`, with
    ``obs_view`` :math:`(N, K)` the view of each slot. Everything computed
    per point from the observations (a fit, tables, losses) is the same,
    entry by entry, when no point loses a view.

    Args:
        data (Data): A capture prepared by
            :class:`~tg_intrinsic.transforms.ProjectViews` and
            :class:`~tg_intrinsic.transforms.FitSphericalHarmonics`.
        max_views (int, optional): As for :func:`observed_slots`.
            (default: :obj:`None`)
    """
    view, valid = observed_slots(
        data.obs_mask, max_views, getattr(data, 'mirror_dir', None),
        data.obs_radiance)
    compact = Data(**{key: value for key, value in data})
    for key in OBSERVED:
        value = getattr(data, key, None)
        if value is None:
            continue
        index = view.view(*view.shape, *[1] * (value.dim() - 2)).expand(
            -1, -1, *value.shape[2:])
        taken = value.gather(1, index)
        compact[key] = taken.bool() & valid if key == 'obs_mask' else \
            torch.where(valid.view(*valid.shape, *[1] * (value.dim() - 2)),
                        taken, torch.zeros_like(taken))
    compact.obs_view = view
    return compact
