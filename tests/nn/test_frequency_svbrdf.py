"""FrequencySVBRDF: the differentiable eq. 5.11 model and its fit.

Observations here come from the model itself (a self-consistency check
of the optimisation); accuracy against the independent renderer is in
tests/test_svbrdf_end_to_end.py."""
import math
import os

import numpy as np
import pytest
import torch

from tg_intrinsic.nn import FrequencySVBRDF, SVBRDFResult
from tg_intrinsic.transforms import FitSphericalHarmonics, SpectralUncertainty

from tests.conftest import svbrdf_observation_geometry


def ground_truth(pos, metal=True):
    """Smooth spatially varying parameters on the unit sphere."""
    base = torch.stack([0.55 + 0.35 * pos[:, 0], 0.5 + 0.3 * pos[:, 1],
                        0.4 + 0.25 * pos[:, 2]], -1)
    roughness = 0.5 + 0.2 * pos[:, 2]
    metallic = torch.ones_like(roughness) if metal else 0.5 + 0.4 * pos[:, 0]
    return base, metallic, roughness


def self_consistent_data(num_points=150, num_views=40, metal=True):
    data = FitSphericalHarmonics()(svbrdf_observation_geometry(
        num_points, num_views))
    truth = FrequencySVBRDF(num_points)
    base, metallic, roughness = ground_truth(data.pos, metal)
    with torch.no_grad():
        truth.base_color.copy_(base)
        truth.metallic.copy_(metallic)
        truth.roughness.copy_(roughness)
        radiance = truth(data, truth.shadowed_light(data))
    data.obs_radiance = torch.where(data.obs_mask.unsqueeze(-1), radiance,
                                    torch.zeros_like(radiance))
    data = FitSphericalHarmonics()(data)
    return data, (base, metallic, roughness)


def test_fit_recovers_its_own_model():
    data, (base, metallic, roughness) = self_consistent_data(150, 100)
    model = FrequencySVBRDF(data.num_nodes)
    result = model.fit(data, steps=300, lr=0.02, progress=False)
    assert isinstance(result, SVBRDFResult)
    assert result.loss[-1] < 0.05 * result.loss[0]
    assert (result.roughness - roughness).abs().mean() < 0.03
    assert ((result.base_color - base) ** 2).mean().sqrt() < 0.02
    assert (result.metallic - metallic).abs().mean() < 0.05
    assert result.entropy.shape == (data.num_nodes, )
    # the spectrum-only answer is the initialisation
    spectrum = FrequencySVBRDF(data.num_nodes).fit(data, steps=0,
                                                   progress=False)
    prepared = SpectralUncertainty()(data)
    floor = math.sqrt(1e-3)  # the fit keeps r^2 off the model's alpha floor
    assert torch.allclose(spectrum.roughness,
                          prepared.init_roughness.float().clamp_min(floor))
    assert len(spectrum.loss) == 1


def test_forward_shapes_gradients_and_options():
    data, _ = self_consistent_data(60, 12)
    model = FrequencySVBRDF(60, fresnel=False, masking=False,
                            shadowing=False)
    out = model(data)
    assert out.shape == (60, 12, 3) and out.dtype == torch.float64
    out.sum().backward()
    for p in model.parameters():
        assert p.grad is not None and bool(torch.isfinite(p.grad).all())
    assert 'FrequencySVBRDF(60' in repr(model)
    # total variation pulls a noisy map together
    model = FrequencySVBRDF(60)
    with torch.no_grad():
        model.roughness.uniform_(0, 1, generator=torch.Generator()
                                 .manual_seed(0))
    edges = model._graph(data, 6)
    before = float(model.total_variation(edges))
    result = model.fit(data, steps=40, init='constant', tv_weight=5.0,
                       progress=False)
    model.roughness.data.copy_(result.roughness)
    assert float(model.total_variation(edges)) < before


@pytest.mark.parametrize('model', ['eq5.11', 'split_sum'])
def test_levenberg_marquardt_recovers_its_own_model(model):
    data, (base, metallic, roughness) = self_consistent_data(150, 100)
    if model == 'split_sum':  # observations of the split-sum model
        truth = FrequencySVBRDF(150, specular_model=model)
        with torch.no_grad():
            truth.base_color.copy_(base)
            truth.metallic.copy_(metallic)
            truth.roughness.copy_(roughness)
            radiance = truth(data)
        data.obs_radiance = torch.where(data.obs_mask.unsqueeze(-1),
                                        radiance, torch.zeros_like(radiance))
        data = FitSphericalHarmonics()(data)
    fitted = FrequencySVBRDF(data.num_nodes, specular_model=model)
    result = fitted.fit(data, solver='lm', progress=False)
    assert result.loss[-1] < 0.05 * result.loss[0]
    assert (result.roughness - roughness).abs().mean() < 0.01
    assert ((result.base_color - base) ** 2).mean().sqrt() < 0.01
    assert (result.metallic - metallic).abs().mean() < 0.02
    # a lower objective than Adam's in its default budget
    adam = FrequencySVBRDF(data.num_nodes, specular_model=model).fit(
        data, lr=0.02, progress=False)
    assert result.loss[-1] < adam.loss[-1]
    # a known metallic is held
    held = FrequencySVBRDF(data.num_nodes, specular_model=model).fit(
        data, solver='lm', metallic=1.0, progress=False)
    assert bool((held.metallic == 1).all())
    assert ((held.base_color - base) ** 2).mean().sqrt() < 0.02


def test_levenberg_marquardt_total_variation_smooths():
    data, _ = self_consistent_data(150, 100)
    noisy = data.clone()
    g = torch.Generator().manual_seed(0)
    noisy.obs_radiance = data.obs_radiance * (
        1 + 0.3 * torch.randn(data.obs_radiance.shape, dtype=torch.float64,
                              generator=g)).clamp_min(0)
    model = FrequencySVBRDF(150)
    edges = model._graph(noisy, 6)
    plain = model.fit(noisy, solver='lm', tv_k=6, progress=False)
    tv_plain = float(model.total_variation(edges))
    smooth = model.fit(noisy, solver='lm', tv_weight=0.05, tv_k=6,
                       progress=False)
    assert float(model.total_variation(edges)) < 0.8 * tv_plain
    assert smooth.loss[-1] > plain.loss[-1]  # traded for smoothness


def test_known_metallic_is_held():
    data, (base, metallic, roughness) = self_consistent_data(150, 60)
    data = SpectralUncertainty()(data)
    model = FrequencySVBRDF(data.num_nodes)
    start = model.fit(data, steps=0, metallic=1.0, progress=False)
    # a metal's base colour is its specular reflectance
    assert torch.allclose(start.base_color,
                          data.init_specular.float().clamp(0, 1))
    result = model.fit(data, steps=200, lr=0.02, metallic=1.0,
                       progress=False)
    assert bool((result.metallic == 1).all())
    free = FrequencySVBRDF(data.num_nodes).fit(data, steps=200, lr=0.02,
                                               progress=False)
    error = ((result.base_color - base) ** 2).mean().sqrt()
    assert error < 0.02
    assert error <= ((free.base_color - base) ** 2).mean().sqrt() + 1e-3
    constant = FrequencySVBRDF(data.num_nodes).fit(
        data, steps=3, init='constant', metallic=0.0, progress=False)
    assert bool((constant.metallic == 0).all())


def test_texels_and_export(tmp_path):
    data, _ = self_consistent_data(64, 12)
    model = FrequencySVBRDF(64, texture_shape=(8, 8))
    result = model.fit(data, steps=5, progress=False)
    paths = result.save(str(tmp_path))
    names = sorted(os.path.basename(p) for p in paths)
    assert names == ['base_color.png', 'entropy.png', 'maps.npz',
                     'metallic.png', 'roughness.png']
    maps = np.load(tmp_path / 'maps.npz')
    assert maps['base_color'].shape == (8, 8, 3)
    assert np.allclose(maps['roughness'].ravel(), result.roughness.numpy())
    assert not any(p.startswith('.tmp') for p in os.listdir(tmp_path))
    # point maps are splatted into a view
    points = FrequencySVBRDF(64).fit(data, steps=1, progress=False)
    out = points.save(str(tmp_path / 'points'), pos=data.pos,
                      image_size=(64, 64))
    import matplotlib.pyplot as plt
    image = plt.imread(out[1])
    assert image.shape[:2] == (64, 64) and image[..., :3].max() > 0


def test_bad_input():
    data, _ = self_consistent_data(30, 8)
    with pytest.raises(ValueError, match='holds 31 points'):
        FrequencySVBRDF(31).fit(data, progress=False)
    missing = data.clone()
    del missing.sh_in
    with pytest.raises(ValueError, match="'data.sh_in' is missing"):
        FrequencySVBRDF(30)(missing)
    with pytest.raises(ValueError, match='init'):
        FrequencySVBRDF(30).fit(data, init='random', progress=False)
    with pytest.raises(ValueError, match='texture_shape'):
        FrequencySVBRDF(30, texture_shape=(4, 4))
    with pytest.raises(ValueError, match='steps'):
        FrequencySVBRDF(30).fit(data, steps=-1, progress=False)
    with pytest.raises(ValueError, match="'metallic' must be None"):
        FrequencySVBRDF(30).fit(data, metallic=1.5, progress=False)
    with pytest.raises(ValueError, match="'solver' must be one of"):
        FrequencySVBRDF(30).fit(data, solver='newton', progress=False)
    with pytest.raises(ValueError, match="'rounds' must be at least 1"):
        FrequencySVBRDF(30).fit(data, solver='lm', rounds=0, progress=False)
    broken = data.clone()
    broken.obs_radiance = broken.obs_radiance.clone()
    broken.obs_radiance[0, 0, 0] = math.nan
    broken.obs_mask = broken.obs_mask.clone()
    broken.obs_mask[0, 0] = True
    with pytest.raises(ValueError, match='NaN or infinite radiance'):
        FrequencySVBRDF(30).fit(broken, steps=3, progress=False)
