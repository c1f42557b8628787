"""A capture whose photographs are lit by different environment maps
(``data.envmaps``, ``data.view_lighting``): each view is modelled under
its own map, and what models one lighting refuses such a capture."""
import math

import pytest
import torch

from tg_intrinsic.datasets import svbrdf_scene
from tg_intrinsic.geometry.appearance.envmap import (sun_sky_envmap,
                                                     view_lightings)
from tg_intrinsic.nn import FrequencySVBRDF, SVBRDFResult
from tg_intrinsic.transforms import (FitSphericalHarmonics, join_lightings,
                                     keep_views)


def sun(elevation, azimuth):
    e, a = math.radians(elevation), math.radians(azimuth)
    return (math.cos(e) * math.cos(a), math.cos(e) * math.sin(a),
            math.sin(e))


def two_lightings(views=12, seed=1):
    """One object (the same materials and cameras) under two suns."""
    maps = [sun_sky_envmap(32, 64, sun(60, 30), sun_angular_radius=0.1,
                           dtype=torch.float64),
            sun_sky_envmap(32, 64, sun(20, 200), sun_angular_radius=0.2,
                           dtype=torch.float64)]
    return [svbrdf_scene('sphere', num_views=views, resolution=2,
                         materials='mixed', render_images=False,
                         dtype=torch.float64, envmap=envmap, seed=seed,
                         specular_samples=64, light_samples=64)
            for envmap in maps]


def roughness_mae(result, truth, seen):
    return float((result.roughness - truth.roughness)[seen].abs().mean())


def test_every_view_is_modelled_under_its_own_map():
    """At the true parameters the refinement's loss is small when each
    view is paired with the map it was rendered under, and several times
    larger with the maps swapped."""
    captures = two_lightings()
    joined = join_lightings(captures)
    assert joined.envmaps.shape == (2, 32, 64, 3)
    assert joined.view_lighting.tolist() == [0] * 12 + [1] * 12
    truth = captures[0]

    def loss_at_truth(data):
        model = FrequencySVBRDF(data.num_nodes).double()
        with torch.no_grad():
            model.base_color.copy_(truth.base_color)
            model.metallic.copy_(truth.metallic)
            model.roughness.copy_(truth.roughness)
        prepared = FrequencySVBRDF(data.num_nodes).recover(
            data, refine_steps=1, progress=False)[1]
        return model.refine(prepared, steps=0, tv_weight=0.0,
                            metallic_starts=False, progress=False).loss[-1]
    right = loss_at_truth(joined)
    swapped = joined.clone()
    swapped.view_lighting = 1 - joined.view_lighting
    assert 4 * right < loss_at_truth(swapped)


def test_recovery_under_several_lightings():
    """One recovery from every photograph under its own map: close to the
    truth, and comparable with merging the recoveries of each lighting
    (benchmarks/svbrdf_merge.py measures both on its scenes)."""
    captures = two_lightings()
    truth = captures[0]
    singles = [FrequencySVBRDF(c.num_nodes).recover(c, progress=False)
               for c in captures]
    seen = singles[0][1].obs_mask.any(1)
    merged, _ = SVBRDFResult.merge_by_uncertainty([r for r, _ in singles])
    result, prepared = FrequencySVBRDF(truth.num_nodes).recover(
        join_lightings(captures), progress=False)
    assert prepared.mirror_dir.shape == (truth.num_nodes, 24, 3)
    assert result.pipeline['refine'] is not None
    joint = roughness_mae(result, truth, seen)
    assert joint < 0.05
    assert joint < 1.5 * roughness_mae(merged, truth, seen)


def test_what_models_one_lighting_refuses_several():
    captures = two_lightings(views=6)
    joined = join_lightings(captures)
    projected = FrequencySVBRDF(joined.num_nodes)
    with pytest.raises(ValueError, match='lit by several maps'):
        FitSphericalHarmonics()(joined)
    with pytest.raises(ValueError, match='only the refinement models'):
        projected.recover(joined, refine=False, progress=False)
    with pytest.raises(ValueError, match='does not apply'):
        projected.recover(joined, solver='lm', progress=False)
    # one lighting's views alone are an ordinary capture
    part = keep_views(joined, [6, 7, 8])
    assert part.view_lighting.tolist() == [1, 1, 1]
    fitted = FrequencySVBRDF(joined.num_nodes).recover(
        captures[0], progress=False)[1]
    fitted.envmaps, fitted.view_lighting = joined.envmaps, torch.zeros(
        6, dtype=torch.long)
    with pytest.raises(ValueError, match='fit models one lighting'):
        FrequencySVBRDF(joined.num_nodes).fit(fitted, steps=1,
                                              progress=False)


def test_bad_lightings():
    captures = two_lightings(views=6)
    joined = join_lightings(captures)
    assert view_lightings(captures[0]) is None
    bad = joined.clone()
    del bad.view_lighting
    with pytest.raises(ValueError, match="needs both 'data.envmaps'"):
        view_lightings(bad)
    bad = joined.clone()
    bad.view_lighting = torch.zeros(5, dtype=torch.long)
    with pytest.raises(ValueError, match=r'one integer per view \(12\)'):
        view_lightings(bad)
    bad.view_lighting = torch.full((12, ), 2)
    with pytest.raises(ValueError, match='must index the 2 maps'):
        view_lightings(bad)
    bad.view_lighting = torch.zeros(12)
    with pytest.raises(ValueError, match='one integer per view'):
        view_lightings(bad)
    bad = joined.clone()
    bad.envmaps = -bad.envmaps
    with pytest.raises(ValueError, match='negative radiance'):
        view_lightings(bad)
    other = captures[1].clone()
    other.envmap = other.envmap[:16]
    with pytest.raises(ValueError, match='resample the maps to one size'):
        join_lightings([captures[0], other])
    other = captures[1].clone()
    other.pos = other.pos + 1
    with pytest.raises(ValueError, match="another surface"):
        join_lightings([captures[0], other])
    with pytest.raises(ValueError, match='one lighting'):
        join_lightings([captures[0], joined])
