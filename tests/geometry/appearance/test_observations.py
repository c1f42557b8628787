import pytest
import torch
from torch_geometric.data import Data

from tg_intrinsic.geometry.appearance.observations import (
    compact_observations, observed_slots)


def capture(num=40, views=12, seed=0):
    g = torch.Generator().manual_seed(seed)
    mirror = torch.nn.functional.normalize(
        torch.randn(num, views, 3, generator=g, dtype=torch.float64), dim=-1)
    return Data(obs_mask=torch.rand(num, views, generator=g) < 0.5,
                obs_radiance=torch.rand(num, views, 3, generator=g,
                                        dtype=torch.float64),
                obs_dir=torch.randn(num, views, 3, generator=g,
                                    dtype=torch.float64),
                mirror_dir=mirror, pos=torch.randn(num, 3, generator=g))


def test_every_observation_in_its_slot():
    data = capture()
    data.obs_mask[3] = False  # a point no view sees
    compact = compact_observations(data)
    count = data.obs_mask.sum(1)
    assert compact.obs_mask.shape == (40, int(count.max()))
    for point in range(40):
        views = data.obs_mask[point].nonzero().flatten()
        slots = compact.obs_mask[point]
        assert int(slots.sum()) == len(views) and bool(slots[:len(views)]
                                                       .all())
        assert torch.equal(compact.obs_view[point, :len(views)], views)
        for key in ('obs_radiance', 'obs_dir', 'mirror_dir'):
            assert torch.equal(compact[key][point, :len(views)],
                               data[key][point, views])
            assert (compact[key][point, len(views):] == 0).all()
    assert torch.equal(compact.pos, data.pos)


def coverage(mirror, kept):
    """The largest distance (1 - cosine) from an observed mirror
    direction to its nearest kept one (brute force)."""
    distance = 1 - mirror @ mirror[kept].T
    return float(distance.min(1).values.max())


def test_a_capped_point_keeps_its_highlights_and_covers_its_reflections():
    data = capture(60, 40, seed=1)
    data.obs_mask[:] = True
    view, valid = observed_slots(data.obs_mask, 12, data.mirror_dir,
                                 data.obs_radiance)
    assert view.shape == (60, 12) and bool(valid.all())
    for point in range(60):
        kept = view[point]
        assert len(set(kept.tolist())) == 12 and bool((kept.diff() > 0).all())
        brightest = data.obs_radiance[point].sum(-1).topk(3).indices
        assert set(brightest.tolist()) <= set(kept.tolist())
        # farthest-point sampling covers the hemisphere better than
        # taking the first twelve views
        mirror = data.mirror_dir[point]
        assert coverage(mirror, kept) <= coverage(mirror, torch.arange(12))


def test_a_point_seen_less_than_the_cap_keeps_every_view():
    data = capture(30, 10, seed=2)
    capped = compact_observations(data, max_views=10)
    full = compact_observations(data)
    for key in ('obs_mask', 'obs_radiance', 'obs_view'):
        assert torch.equal(capped[key], full[key])


def test_bad_input():
    data = capture()
    with pytest.raises(ValueError, match="'max_views'"):
        observed_slots(data.obs_mask, 0)
    with pytest.raises(ValueError, match="'mirror_dir' and 'radiance'"):
        observed_slots(data.obs_mask, 2)
