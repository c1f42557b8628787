"""FitSphericalHarmonics and SpectralUncertainty."""
import math

import pytest
import torch
from torch_geometric.data import Batch

from tg_intrinsic.geometry.appearance.brdf import reflect, to_local
from tg_intrinsic.geometry.appearance.envmap import equirect_directions
from tg_intrinsic.geometry.appearance.sh import real_sh
from tg_intrinsic.transforms import FitSphericalHarmonics, SpectralUncertainty

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


def test_unseen_points_and_few_samples():
    data = svbrdf_observation_geometry(40, 20)
    data.obs_mask[:5] = False  # seen by no view
    data.obs_mask[5:10] = False
    data.obs_mask[5:10, :3] = True  # 3 samples for 36 coefficients
    data.obs_radiance = torch.rand(40, 20, 3, dtype=torch.float64)
    out = SpectralUncertainty()(FitSphericalHarmonics()(data))
    assert torch.equal(out.sh_out[:5], torch.zeros_like(out.sh_out[:5]))
    assert torch.allclose(out.entropy[:5], torch.ones(5, dtype=torch.float64))
    assert bool(torch.isfinite(out.sh_out).all())
    assert bool(torch.isfinite(out.entropy).all())
    assert bool(((out.entropy >= 0) & (out.entropy <= 1)).all())


def test_diffuse_surface_is_uncertain():
    """Constant radiance Kd E / pi carries no specular signal: a very rough
    lobe explains it as well as none, so the entropy is high everywhere and
    only the colour's hue is pinned down."""
    data = FitSphericalHarmonics()(svbrdf_observation_geometry(60, 60))
    kd = torch.tensor([0.7, 0.45, 0.2], dtype=torch.float64)
    data.obs_radiance = (kd * data.irradiance / math.pi).unsqueeze(1).expand(
        -1, 60, -1) * data.obs_mask.unsqueeze(-1)
    out = SpectralUncertainty()(FitSphericalHarmonics()(data))
    assert out.entropy.min() > 0.7
    base = out.init_base_color
    assert bool(((base[:, 0] > base[:, 1]) & (base[:, 1] > base[:, 2])).all())
    assert out.likelihood.shape == (60, 32, 32)


def test_batching_and_repr():
    a = SpectralUncertainty(grid=(8, 8))(FitSphericalHarmonics()(
        svbrdf_observation_geometry(30, 12)))
    b = SpectralUncertainty(grid=(8, 8))(FitSphericalHarmonics()(
        svbrdf_observation_geometry(20, 12, seed=3)))
    batch = Batch.from_data_list([a, b])
    assert batch.sh_in.shape == (50, 36, 3)
    assert batch.entropy.shape == (50, )
    assert batch.sh_prefilter.shape == (2, )
    assert 'l_max=5' in repr(FitSphericalHarmonics())
    assert 'grid=(32, 32)' in repr(SpectralUncertainty())


def test_bad_input():
    data = svbrdf_observation_geometry(20, 8)
    with pytest.raises(ValueError, match='regularizer'):
        FitSphericalHarmonics(regularizer=0.0)
    with pytest.raises(ValueError, match='num_light_samples'):
        FitSphericalHarmonics(num_light_samples=10)
    with pytest.raises(ValueError, match='grid'):
        SpectralUncertainty(grid=(32, ))
    with pytest.raises(ValueError, match='sigma'):
        SpectralUncertainty(sigma=0)
    with pytest.raises(ValueError, match='run FitSphericalHarmonics'):
        SpectralUncertainty()(data)
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
