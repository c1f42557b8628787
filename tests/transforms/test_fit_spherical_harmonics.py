import math

import pytest
import torch

from tg_intrinsic.geometry.appearance.brdf import reflect, to_local
from tg_intrinsic.geometry.appearance.envmap import equirect_directions
from tg_intrinsic.geometry.appearance.sh import real_sh
from tg_intrinsic.transforms import FitSphericalHarmonics
from tests.conftest import svbrdf_observation_geometry


def band_limited_envmap(coefficients, height=64, width=128):
    d = equirect_directions(height, width)
    return (real_sh(d, 3) @ coefficients).clamp_min(0)


def test_light_samples_follow_the_local_frame():
    g = torch.Generator().manual_seed(0)
    coefficients = 0.3 * torch.randn(16, 3, generator=g, dtype=torch.float64)
    coefficients[0] = 4.0
    data = svbrdf_observation_geometry(50, 30)
    data.envmap = band_limited_envmap(coefficients)
    out = FitSphericalHarmonics(prefilter_alpha=0.0)(data)
    from tg_intrinsic.geometry.appearance.sh import light_directions
    world = light_directions(out.light_radiance.size(1)) @ out.frame
    want = real_sh(world, 3) @ coefficients
    # bilinear lookup of a smooth map: close to the analytic light
    assert (out.light_radiance - want).abs().max() < 0.02
    assert out.sh_in.shape == (50, 36, 3)
    assert torch.allclose(out.frame[:, 2], data.normal)


def test_outgoing_fit_recovers_a_band_limited_reflection():
    """Observations that are a degree-5 function of the local mirror
    direction are fitted back exactly (up to the tiny regulariser)."""
    data = svbrdf_observation_geometry(20, 150)
    g = torch.Generator().manual_seed(1)
    coefficients = torch.randn(20, 36, 3, generator=g, dtype=torch.float64)
    from tg_intrinsic.geometry.pointcloud.frames import tangent_frames
    frame = tangent_frames(data.normal)
    mirror = to_local(reflect(data.obs_dir, data.normal.unsqueeze(1)), frame)
    data.obs_radiance = real_sh(mirror, 5) @ coefficients
    data.frame = frame
    out = FitSphericalHarmonics(regularizer=1e-10)(data)
    assert torch.allclose(out.mirror_dir, mirror)
    # compare the fitted function where it was observed
    fitted = real_sh(mirror, 5) @ out.sh_out
    mask = data.obs_mask
    assert (fitted - data.obs_radiance)[mask].abs().max() < 1e-4


def test_repr():
    assert 'l_max=5' in repr(FitSphericalHarmonics())


def test_bad_input():
    data = svbrdf_observation_geometry(20, 8)
    with pytest.raises(ValueError, match='regularizer'):
        FitSphericalHarmonics(regularizer=0.0)
    with pytest.raises(ValueError, match='num_light_samples'):
        FitSphericalHarmonics(num_light_samples=10)
    missing = data.clone()
    del missing.envmap
    with pytest.raises(ValueError, match='envmap'):
        FitSphericalHarmonics()(missing)
    wrong = data.clone()
    wrong.envmap = data.envmap[..., :2]
    with pytest.raises(ValueError, match=r'\[H, W, 3\]'):
        FitSphericalHarmonics()(wrong)
    wrong.envmap = data.envmap.clone()
    wrong.envmap[0, 0, 0] = math.nan
    with pytest.raises(ValueError, match='NaN'):
        FitSphericalHarmonics()(wrong)
    del missing.obs_mask
    missing.envmap = data.envmap
    with pytest.raises(ValueError, match='run ProjectViews first'):
        FitSphericalHarmonics()(missing)
    short = data.clone()
    short.obs_dir = data.obs_dir[:, :4]
    with pytest.raises(ValueError, match=r'obs_dir'):
        FitSphericalHarmonics()(short)
