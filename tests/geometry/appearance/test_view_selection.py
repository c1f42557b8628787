"""Greedy view selection by expected entropy reduction: the choice against
a brute force that refits every candidate with FitSphericalHarmonics and
SpectralUncertainty, the candidates' photos never read, views that see
nothing, determinism and bad input."""
import math

import pytest
import torch

from tg_intrinsic.datasets import svbrdf_scene
from tg_intrinsic.geometry.appearance import select_views
from tg_intrinsic.geometry.appearance.brdf import reflect, to_local
from tg_intrinsic.geometry.appearance.envmap import (equirect_lookup,
                                                     filter_envmap)
from tg_intrinsic.geometry.appearance.sh import real_sh
from tg_intrinsic.transforms import (FitSphericalHarmonics,
                                     SpectralUncertainty, keep_views)

PREFILTER = 0.3
L_MAX = 3


@pytest.fixture(scope='module')
def scene():
    return svbrdf_scene('sphere', num_views=8, resolution=1,
                        render_images=False, dtype=torch.float64, seed=3,
                        specular_samples=16, light_samples=16)


def fit(data):
    return FitSphericalHarmonics(l_max=L_MAX, num_light_samples=256,
                                 prefilter_alpha=PREFILTER)(data)


def inputs(data):
    """What select_views needs, for every view, from the geometry and the
    light only (FitSphericalHarmonics on one view gives frame, light SH
    and irradiance, which do not depend on the views)."""
    one = fit(keep_views(data, [0]))
    normal = data.normal / data.normal.norm(dim=-1, keepdim=True)
    mirror = reflect(data.obs_dir, normal.unsqueeze(1))
    local = to_local(mirror, one.frame)
    weight = local[..., 2].clamp_min(0) * data.obs_mask
    light = equirect_lookup(filter_envmap(data.envmap, PREFILTER), mirror)
    return dict(mirror_dir=local, weight=weight, light=light,
                radiance=data.obs_radiance, sh_in=one.sh_in,
                irradiance=one.irradiance, prefilter_alpha=PREFILTER)


def predicted(data, chosen, view):
    """The model's radiance for one candidate view from the spectrum
    estimate of the chosen views, written out term by term."""
    state = SpectralUncertainty()(fit(keep_views(data, chosen)))
    ks, rough = state.init_specular, state.init_roughness
    kd = (math.pi * (state.sh_out[:, 0] - ks * state.sh_in_obs[:, 0])
          / (math.sqrt(4 * math.pi) * state.irradiance)).clamp(0, 1)
    seen = data.obs_mask[:, chosen].any(1)
    unseen = ~seen
    rough = torch.where(unseen, rough[seen].mean(), rough)
    ks = torch.where(unseen[:, None], ks[seen].mean(0), ks)
    kd = torch.where(unseen[:, None], kd[seen].mean(0), kd)
    full = inputs(data)
    basis = real_sh(full['mirror_dir'][:, view], L_MAX)  # (N, K)
    degree = torch.tensor([l for l in range(L_MAX + 1)  # noqa: E741
                           for _ in range(2 * l + 1)], dtype=torch.float64)
    alpha = (rough * rough).clamp_min(1e-3)
    lobe = torch.exp(-(alpha[:, None] ** 2 - PREFILTER ** 2) * degree ** 2)
    specular = ((basis * lobe)[:, :, None] * state.sh_in).sum(1)
    return (kd * state.irradiance / math.pi + ks * specular).clamp_min(0)


def brute_force_next(data, chosen, candidates):
    """The candidate whose predicted photo, appended, gives the lowest mean
    entropy (refitting every point with the full transforms)."""
    scores = []
    for view in candidates:
        guess = keep_views(data, chosen + [view])
        guess.obs_radiance = guess.obs_radiance.clone()
        guess.obs_radiance[:, -1] = torch.where(
            guess.obs_mask[:, -1, None], predicted(data, chosen, view), 0.0)
        scores.append(float(SpectralUncertainty()(fit(guess)).entropy.mean()))
    return candidates[min(range(len(scores)), key=scores.__getitem__)], scores


def test_greedy_choices_match_brute_force(scene):
    seed, candidates = [0, 5], [1, 2, 3, 4, 6, 7]
    views, mean_entropy = select_views(**inputs(scene), num_views=5,
                                       seed_views=seed)
    # the trace starts at the entropy of the seed's real observations
    truth = SpectralUncertainty()(fit(keep_views(scene, seed))).entropy
    assert mean_entropy[0].item() == pytest.approx(truth.mean().item(),
                                                   abs=1e-9)
    chosen, remaining = list(seed), list(candidates)
    for step in range(3):
        best, scores = brute_force_next(scene, chosen, remaining)
        # a clear winner, so rounding cannot decide the comparison
        assert sorted(scores)[1] - min(scores) > 1e-6
        assert views[len(seed) + step].item() == best
        # and the expected entropy is the brute force's, to rounding
        assert mean_entropy[step + 1].item() == pytest.approx(
            min(scores), abs=1e-9)
        chosen.append(best)
        remaining.remove(best)
    assert views.tolist() == chosen


def test_the_candidates_photos_are_never_read(scene):
    args = inputs(scene)
    views, mean_entropy = select_views(**args, num_views=5, seed_views=[0])
    hidden = args['radiance'].clone()
    hidden[:, [v for v in range(8) if v != 0]] = float('nan')
    args['radiance'] = hidden
    # only the seed's photo is known: the next view is the same, and its
    # expected entropy too
    first, expected = select_views(**args, num_views=2, seed_views=[0])
    assert first.tolist() == views[:2].tolist()
    torch.testing.assert_close(expected, mean_entropy[:2])
    # a chosen view's photo is read once the view after it is asked for
    with pytest.raises(ValueError, match='chosen view'):
        select_views(**args, num_views=3, seed_views=[0])


def test_deterministic(scene):
    a = select_views(**inputs(scene), num_views=6, seed_views=[2])
    b = select_views(**inputs(scene), num_views=6, seed_views=[2])
    assert torch.equal(a[0], b[0]) and torch.equal(a[1], b[1])
    assert a[0].dtype == torch.long and a[1].shape == (6, )


def test_a_blind_view_loses_to_one_that_sees_uncertain_points(scene):
    args = inputs(scene)
    seen_by_seed = args['weight'][:, 0] > 0
    # view 4 after blinding it sees nothing; the other candidate sees
    # points that the seed never saw (entropy 1)
    args['weight'] = args['weight'].clone()
    args['weight'][:, 4] = 0
    sees_new = [v for v in range(1, 8) if v != 4 and bool(
        ((args['weight'][:, v] > 0) & ~seen_by_seed).any())]
    assert sees_new
    before = select_views(**args, num_views=1, seed_views=[0])[1][0]
    assert before < 1
    views, _ = select_views(**args, num_views=2, seed_views=[0],
                            candidates=[4, sees_new[0]])
    assert views[1].item() == sees_new[0]
    # and among all candidates the blind one is never first
    views, _ = select_views(**args, num_views=2, seed_views=[0],
                            candidates=[4] + [v for v in range(1, 8)
                                              if v != 4])
    assert views[1].item() != 4


def test_bad_input(scene):
    args = inputs(scene)
    with pytest.raises(ValueError, match='exceeds'):
        select_views(**args, num_views=9, seed_views=[0])
    with pytest.raises(ValueError, match='no candidate'):
        select_views(**args, num_views=2, seed_views=[0], candidates=[])
    with pytest.raises(ValueError, match='outside'):
        select_views(**args, num_views=2, seed_views=[8])
    with pytest.raises(ValueError, match='at least 0'):
        select_views(**args, num_views=2, seed_views=[-1])
    with pytest.raises(ValueError, match='outside'):
        select_views(**args, num_views=2, candidates=[1, 9])
    with pytest.raises(ValueError, match='at least one'):
        select_views(**args, num_views=2, seed_views=[])
    with pytest.raises(ValueError, match='more than once'):
        select_views(**args, num_views=3, seed_views=[1, 1])
    with pytest.raises(ValueError, match='both seed'):
        select_views(**args, num_views=3, seed_views=[1], candidates=[1, 2])
    with pytest.raises(ValueError, match='smaller than'):
        select_views(**args, num_views=1, seed_views=[0, 1])
    with pytest.raises(ValueError, match='integer'):
        select_views(**args, num_views=2.5)
    with pytest.raises(ValueError, match='non-negative'):
        select_views(**dict(args, weight=-args['weight']), num_views=2)
    with pytest.raises(ValueError, match='light'):
        select_views(**dict(args, light=args['light'][:, :3]), num_views=2)
    with pytest.raises(ValueError, match='mirror_dir'):
        select_views(**dict(args, mirror_dir=args['mirror_dir'][0]),
                     num_views=2)
    with pytest.raises(ValueError, match='sh_in'):
        select_views(**dict(args, sh_in=args['sh_in'][:, :5]), num_views=2)
    nan = args['light'].clone()
    nan[0, 0, 0] = float('nan')
    with pytest.raises(ValueError, match='NaN'):
        select_views(**dict(args, light=nan), num_views=2)
