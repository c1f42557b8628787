"""Frequency-domain SVBRDF recovery end to end, on observations from the
independent renderer (tg_intrinsic.geometry.appearance.lighting: the full reflection
integral, not the method's SH approximation).

The scene is a sphere of spatially varying metals (roughness 0.2-0.8) under
a procedural sky with a soft sun, seen by 60 cameras. The thresholds are
what the method reaches here with margin (see benchmarks/svbrdf_accuracy.py
for the measured numbers per envmap and view count); they catch a broken
pipeline, not small regressions.
"""
import pytest
import torch
from scipy.stats import spearmanr

from tg_intrinsic.datasets import svbrdf_scene
from tg_intrinsic.geometry.appearance.envmap import sun_sky_envmap
from tg_intrinsic.nn import FrequencySVBRDF
from tg_intrinsic.transforms import FitSphericalHarmonics, SpectralUncertainty


@pytest.fixture(scope='module')
def scene():
    envmap = sun_sky_envmap(64, 128, sun_angular_radius=0.3,
                            dtype=torch.float64)
    return svbrdf_scene('sphere', num_views=60, materials='metals',
                        roughness_range=(0.2, 0.8), resolution=3,
                        render_images=False, dtype=torch.float64,
                        envmap=envmap, seed=1)


def errors(data, base_color, metallic, roughness):
    seen = data.obs_mask.any(1)
    r = (roughness.double() - data.roughness)[seen].abs()
    b = ((base_color.double() - data.base_color)[seen] ** 2).mean().sqrt()
    m = (metallic.double() - data.metallic)[seen].abs().mean()
    return r, float(b), float(m)


@pytest.mark.parametrize('l_max,model', [(5, 'eq5.11'), (8, 'split_sum')])
def test_mixed_recovery_on_the_independent_renderer(scene, l_max, model):
    data = SpectralUncertainty()(FitSphericalHarmonics(l_max=l_max)(scene))
    spectrum_r, _, _ = errors(data, data.init_base_color, data.init_metallic,
                              data.init_roughness)
    result = FrequencySVBRDF(data.num_nodes, specular_model=model).fit(
        data, steps=300, lr=0.02, tv_weight=0.02, progress=False)
    r, b, m = errors(data, result.base_color, result.metallic,
                     result.roughness)
    # measured on this scene: spectrum-only roughness MAE 0.15; mixed
    # 0.08-0.09 roughness MAE, 0.14-0.17 base colour RMSE, 0.4 metallic
    assert float(r.mean()) < 0.7 * float(spectrum_r.mean())
    assert float(r.mean()) < 0.12
    assert b < 0.22
    # Entropy ranks the points by how wrong the estimates are. Measured on
    # this scene (642 seen points): Spearman's rho of entropy and the
    # spectrum-only roughness error 0.44 (eq5.11) and 0.45 (split_sum), of
    # entropy and the recovered roughness error 0.19 and 0.21. Entropy
    # unrelated to the error (shuffled over the points) gives rho around 0
    # with a standard deviation of 0.04 (above 0.11-0.12 once in 1000
    # shuffles); a constant one gives NaN; both fail, as does a reversed one.
    seen = data.obs_mask.any(1)
    entropy = data.entropy[seen].numpy()
    rho_spectrum = spearmanr(entropy, spectrum_r.numpy()).correlation
    assert rho_spectrum > 0.3
    rho = spearmanr(entropy, r.numpy()).correlation
    assert rho > 0.12
