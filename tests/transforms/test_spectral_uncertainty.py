import math

import pytest
import torch
from torch_geometric.data import Batch, Data

from tg_intrinsic.geometry.appearance.sh import \
    principled_to_torrance_sparrow
from tg_intrinsic.transforms import FitSphericalHarmonics, SpectralUncertainty
from tests.conftest import svbrdf_observation_geometry

DEGREE = torch.tensor([0, 1, 1, 1, 2, 2, 2, 2, 2, 3, 3, 3, 3, 3, 3, 3])


def spectra_data(num=6, seed=0, prefilter=0.1):
    """Random degree-3 coefficients of the light and of the observations,
    the outgoing ones about half the incoming."""
    g = torch.Generator().manual_seed(seed)
    sh_in = torch.randn(num, 16, 3, generator=g, dtype=torch.float64)
    sh_out = 0.5 * sh_in + 0.1 * torch.randn(num, 16, 3, generator=g,
                                             dtype=torch.float64)
    return Data(sh_in_obs=sh_in, sh_out=sh_out,
                irradiance=1 + torch.rand(num, 3, generator=g,
                                          dtype=torch.float64),
                sh_prefilter=torch.tensor([prefilter], dtype=torch.float64))


def brute_force(data, grid, sigma):
    """Eqs. 5.19-5.25 cell by cell: the spectra per degree divided by the
    light's power, D over the grid for every channel, the likelihood and
    its normalised entropy; the channel of lowest entropy decides the
    roughness (its likelihood's argmax), every channel's K_s is its
    argmin of D there."""
    s_in = torch.zeros(data.sh_out.size(0), 4, 3,
                       dtype=torch.float64).index_add_(
                           1, DEGREE, data.sh_in_obs ** 2)
    s_out = torch.zeros_like(s_in).index_add_(1, DEGREE, data.sh_out ** 2)
    power = s_in.sum(1, keepdim=True)
    s_in, s_out = s_in[:, 1:] / power, s_out[:, 1:] / power
    ks = torch.linspace(0, 1, grid[0], dtype=torch.float64)
    r = torch.linspace(0, 1, grid[1], dtype=torch.float64)
    prefilter = float(data.sh_prefilter)
    num = s_in.size(0)
    distance = torch.zeros(num, 3, grid[0], grid[1], dtype=torch.float64)
    for a in range(grid[0]):
        for b in range(grid[1]):
            for l in range(1, 4):  # noqa: E741
                lobe = math.exp(-2 * (float(r[b]) ** 4 - prefilter ** 2)
                                * l * l)
                distance[:, :, a, b] += (s_out[:, l - 1] - float(ks[a]) ** 2
                                         * lobe * s_in[:, l - 1]) ** 2
    log_p = torch.log_softmax(-distance.flatten(2) / (2 * sigma ** 2), -1)
    p = log_p.exp()
    entropy = -(p * log_p).sum(-1) / math.log(grid[0] * grid[1])
    best = entropy.argmin(1)
    rows = torch.arange(num)
    likelihood = p[rows, best].view(num, *grid)
    r_index = likelihood.amax(1).argmax(1)
    ks_index = distance[rows, :, :, r_index].argmin(-1)
    return entropy.min(1).values, likelihood, r[r_index], ks[ks_index]


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


def test_against_a_cell_by_cell_computation():
    data = spectra_data()
    out = SpectralUncertainty(grid=(9, 7), sigma=0.05)(data)
    entropy, likelihood, roughness, specular = brute_force(data, (9, 7),
                                                           0.05)
    assert torch.allclose(out.entropy, entropy, atol=1e-9)
    assert torch.allclose(out.likelihood, likelihood, atol=1e-9)
    assert torch.equal(out.init_roughness, roughness)
    assert torch.equal(out.init_specular, specular)
    # informative but not decided: strictly inside (0, 1)
    assert (out.entropy > 0.1).all() and (out.entropy < 0.9).all()


def test_a_known_material_is_recovered():
    """Observations made by the lobe model from principled parameters on
    the grid: D is zero in their cell, so the argmax returns them, and
    degree 0 less the specular mean gives K_d, hence the base colour and
    metallic."""
    base = torch.tensor([0.76, 0.36, 0.56], dtype=torch.float64)
    metallic, roughness = torch.tensor(0.5, dtype=torch.float64), 0.5
    kd, r0, alpha = principled_to_torrance_sparrow(
        base, metallic, torch.tensor(roughness, dtype=torch.float64))
    data = spectra_data(4, seed=1)
    lobe = torch.exp(-(alpha ** 2 - 0.1 ** 2) * DEGREE.double() ** 2)
    sh_out = r0 * lobe[:, None] * data.sh_in_obs
    sh_out[:, 0] += kd * math.sqrt(4 * math.pi) * data.irradiance / math.pi
    data.sh_out = sh_out
    out = SpectralUncertainty(grid=(11, 11))(data)
    assert torch.allclose(out.init_roughness, torch.full(
        (4, ), roughness, dtype=torch.float64))
    assert torch.allclose(out.init_specular, r0.expand(4, 3))
    assert torch.allclose(out.init_base_color, base.expand(4, 3), atol=1e-9)
    assert torch.allclose(out.init_metallic, metallic.expand(4), atol=1e-9)
    assert (out.entropy < 0.5).all()


def test_only_the_power_spectra_and_the_scale_free_ratios_matter():
    data = spectra_data(5, seed=2)
    ref = SpectralUncertainty(grid=(8, 6), sigma=0.05)(data)
    # any orthogonal change of basis within every degree l >= 1, different
    # for light and observations (a rotation of either, for instance)
    g = torch.Generator().manual_seed(3)
    mixed = data.clone()
    for key in ('sh_in_obs', 'sh_out'):
        value = data[key].clone()
        for l in range(1, 4):  # noqa: E741
            q, _ = torch.linalg.qr(torch.randn(2 * l + 1, 2 * l + 1,
                                               generator=g,
                                               dtype=torch.float64))
            block = slice(l * l, (l + 1) ** 2)
            value[:, block] = torch.einsum('ab,nbc->nac', q,
                                           data[key][:, block])
        mixed[key] = value
    assert not torch.allclose(mixed.sh_out, data.sh_out)
    # and brighter light with brighter observations
    scaled = data.clone()
    for key in ('sh_in_obs', 'sh_out', 'irradiance'):
        scaled[key] = 7.0 * data[key]
    for other in (mixed, scaled):
        out = SpectralUncertainty(grid=(8, 6), sigma=0.05)(other)
        for key in ('entropy', 'likelihood', 'init_specular',
                    'init_roughness', 'init_base_color', 'init_metallic'):
            assert torch.allclose(out[key], ref[key], atol=1e-9), key


def test_keys_shapes_and_the_likelihood_option():
    data = spectra_data(5, seed=4)
    out = SpectralUncertainty(grid=(8, 6), sigma=0.05)(data)
    for key, shape in [('entropy', (5, )), ('likelihood', (5, 8, 6)),
                       ('init_specular', (5, 3)), ('init_base_color', (5, 3)),
                       ('init_metallic', (5, )), ('init_roughness', (5, ))]:
        assert tuple(out[key].shape) == shape, key
        assert out[key].dtype == torch.float64, key
        assert ((out[key] >= 0) & (out[key] <= 1)).all(), key
    assert torch.allclose(out.likelihood.sum((1, 2)),
                          torch.ones(5, dtype=torch.float64))
    assert 'entropy' not in data  # the input is not mutated
    lean = SpectralUncertainty(grid=(8, 6), sigma=0.05,
                               store_likelihood=False)(data)
    assert 'likelihood' not in lean
    assert torch.equal(lean.entropy, out.entropy)


def test_bad_values_are_named():
    with pytest.raises(ValueError, match="'grid' must be a pair"):
        SpectralUncertainty(grid=32)
    with pytest.raises(ValueError, match="'grid' must be at least 2"):
        SpectralUncertainty(grid=(1, 8))
    with pytest.raises(ValueError, match="'grid' must be an integer"):
        SpectralUncertainty(grid=(8.5, 8))
    with pytest.raises(ValueError, match="'sigma' must be finite"):
        SpectralUncertainty(sigma=float('nan'))
    for key in ('sh_in_obs', 'sh_out', 'irradiance', 'sh_prefilter'):
        data = spectra_data(2)
        del data[key]
        with pytest.raises(ValueError, match=f"needs 'data.{key}'"):
            SpectralUncertainty()(data)
    assert repr(SpectralUncertainty(grid=(8, 6), sigma=0.05)) == \
        'SpectralUncertainty(grid=(8, 6), sigma=0.05)'
