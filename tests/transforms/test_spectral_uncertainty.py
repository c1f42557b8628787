import math

import pytest
import torch
from torch_geometric.data import Batch

from tg_intrinsic.transforms import FitSphericalHarmonics, SpectralUncertainty
from tests.conftest import svbrdf_observation_geometry


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


def test_batching():
    a = SpectralUncertainty(grid=(8, 8))(FitSphericalHarmonics()(
        svbrdf_observation_geometry(30, 12)))
    b = SpectralUncertainty(grid=(8, 8))(FitSphericalHarmonics()(
        svbrdf_observation_geometry(20, 12, seed=3)))
    batch = Batch.from_data_list([a, b])
    assert batch.sh_in.shape == (50, 36, 3)
    assert batch.entropy.shape == (50, )
    assert batch.sh_prefilter.shape == (2, )


def test_repr():
    assert 'grid=(32, 32)' in repr(SpectralUncertainty())


def test_bad_input():
    data = svbrdf_observation_geometry(20, 8)
    with pytest.raises(ValueError, match='grid'):
        SpectralUncertainty(grid=(32, ))
    with pytest.raises(ValueError, match='sigma'):
        SpectralUncertainty(sigma=0)
    with pytest.raises(ValueError, match='run FitSphericalHarmonics'):
        SpectralUncertainty()(data)
