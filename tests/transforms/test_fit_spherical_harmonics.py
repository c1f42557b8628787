import math

import pytest
import torch

from torch_geometric.data import Data

from tg_intrinsic.geometry.appearance.brdf import reflect, to_local
from tg_intrinsic.geometry.appearance.envmap import equirect_directions
from tg_intrinsic.geometry.appearance.sh import (fibonacci_sphere,
                                                 light_directions, real_sh)
from tg_intrinsic.geometry.pointcloud.frames import tangent_frames
from tg_intrinsic.transforms import FitSphericalHarmonics
from tests.conftest import sky_envmap, svbrdf_observation_geometry
from tests.symmetry import rotate_frames, rotate_vectors


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
    local = light_directions(out.light_radiance.size(1))
    want = real_sh(local @ out.frame, 3) @ coefficients
    # bilinear lookup of a smooth map: close to the analytic light above
    # the horizon; below it no light reaches the surface
    upper = local[:, 2] > 0
    assert (out.light_radiance[:, upper] - want[:, upper]).abs().max() < 0.02
    assert bool((out.light_radiance[:, ~upper] == 0).all())
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
    assert repr(FitSphericalHarmonics()) == (
        'FitSphericalHarmonics(l_max=5, regularizer=0.0001, '
        'num_light_samples=1024, prefilter_alpha=None)')
    assert repr(FitSphericalHarmonics(3, 1e-3, 256, 0.0)) == (
        'FitSphericalHarmonics(l_max=3, regularizer=0.001, '
        'num_light_samples=256, prefilter_alpha=0.0)')


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


def test_known_outgoing_coefficients_are_recovered():
    """Points that see their upper hemisphere of mirror directions densely
    get back the degree-5 coefficients the observations were made of."""
    pos = fibonacci_sphere(3)
    frame = tangent_frames(pos)
    local = fibonacci_sphere(600)
    local = local[local[:, 2] > 0.05]
    views = local.size(0)
    # the view direction whose mirror is ``local``: reflect it back
    view = reflect(local @ frame, pos.unsqueeze(1))
    g = torch.Generator().manual_seed(2)
    coefficients = torch.randn(3, 36, 3, generator=g, dtype=torch.float64)
    data = Data(pos=pos, normal=pos.clone(), frame=frame, obs_dir=view,
                obs_mask=torch.ones(3, views, dtype=torch.bool),
                obs_radiance=real_sh(local.expand(3, views, 3), 5)
                @ coefficients, envmap=sky_envmap())
    out = FitSphericalHarmonics(regularizer=1e-12)(data)
    assert torch.allclose(out.mirror_dir, local.expand(3, views, 3),
                          atol=1e-12)
    assert torch.allclose(out.sh_out, coefficients, atol=1e-4)


def test_a_constant_environment():
    """Light c from everywhere: every light sample is c, the irradiance is
    pi c, and the fitted light is c over the upper hemisphere."""
    data = svbrdf_observation_geometry(20, 4)
    data.envmap = torch.full((32, 64, 3), 0.7, dtype=torch.float64)
    out = FitSphericalHarmonics()(data)
    # four views: the default band limit is 4^-1/2
    assert torch.allclose(out.sh_prefilter,
                          torch.tensor([0.5], dtype=torch.float64))
    upper = light_directions(out.light_radiance.size(1))[:, 2] > 0
    assert torch.allclose(out.light_radiance[:, upper], torch.full_like(
        out.light_radiance[:, upper], 0.7))
    assert torch.allclose(out.irradiance, torch.full_like(
        out.irradiance, 0.7 * math.pi), rtol=2e-3)
    up = fibonacci_sphere(500)
    up = up[up[:, 2] > 0.2]
    light = real_sh(up, 5) @ out.sh_in
    assert (light - 0.7).abs().max() < 2e-3


def test_keys_shapes_and_dtypes():
    data = svbrdf_observation_geometry(12, 6)
    out = FitSphericalHarmonics(l_max=3, regularizer=1e-3,
                                num_light_samples=128)(data)
    for key, shape in [('sh_in', (12, 16, 3)), ('sh_out', (12, 16, 3)),
                       ('sh_in_obs', (12, 16, 3)),
                       ('light_radiance', (12, 128, 3)),
                       ('mirror_dir', (12, 6, 3)), ('irradiance', (12, 3)),
                       ('frame', (12, 3, 3)), ('sh_prefilter', (1, )),
                       ('sh_regularizer', (1, ))]:
        assert tuple(out[key].shape) == shape, key
        assert torch.isfinite(out[key]).all(), key
    for key in ('sh_in', 'sh_out', 'sh_in_obs', 'mirror_dir', 'irradiance'):
        assert out[key].dtype == torch.float64, key
    assert out.light_radiance.dtype == torch.float32  # N * S * 3: kept small
    assert float(out.sh_regularizer) == 1e-3
    # frames built on the normals; the mirror directions are unit vectors
    # of the upper hemisphere wherever the point is seen
    assert torch.allclose(out.frame, tangent_frames(data.normal))
    assert torch.allclose(out.mirror_dir.norm(dim=-1),
                          torch.ones(12, 6, dtype=torch.float64))
    assert (out.mirror_dir[..., 2][data.obs_mask] > 0).all()
    assert 'sh_in' not in data  # the input is not mutated


def test_turning_the_frames_changes_coordinates_not_the_fit():
    data = svbrdf_observation_geometry(15, 40)
    g = torch.Generator().manual_seed(3)
    data.obs_radiance = torch.rand(15, 40, 3, generator=g,
                                   dtype=torch.float64)
    data.frame = tangent_frames(data.normal)
    a = FitSphericalHarmonics()(data)
    angle = torch.rand(15, generator=g, dtype=torch.float64) * 6
    turned = data.clone()
    turned.frame = rotate_frames(data.frame, angle)
    b = FitSphericalHarmonics()(turned)
    assert torch.equal(b.frame, turned.frame)
    # mirror directions: tangent coordinates turn, the height stays
    assert torch.allclose(b.mirror_dir[..., :2],
                          rotate_vectors(a.mirror_dir[..., :2], angle),
                          atol=1e-12)
    assert torch.allclose(b.mirror_dir[..., 2], a.mirror_dir[..., 2])
    # the fitted functions are the same (the regulariser is the same on
    # every degree, whatever the frame), so they agree where observed
    for key in ('sh_out', 'sh_in_obs'):
        fa = real_sh(a.mirror_dir, 5) @ a[key]
        fb = real_sh(b.mirror_dir, 5) @ b[key]
        assert torch.allclose(fa, fb, atol=1e-8), key
    assert not torch.allclose(a.sh_out, b.sh_out, atol=1e-3)
    assert torch.allclose(a.irradiance, b.irradiance)


def test_normals_of_any_length_are_normalised():
    data = svbrdf_observation_geometry(10, 8)
    long = data.clone()
    long.normal = 3.0 * data.normal
    a, b = FitSphericalHarmonics()(data), FitSphericalHarmonics()(long)
    for key in ('sh_in', 'sh_out', 'mirror_dir', 'irradiance', 'frame'):
        assert torch.allclose(a[key], b[key], atol=1e-12), key


def test_bad_values_are_named():
    data = svbrdf_observation_geometry(10, 8)
    without = data.clone()
    del without.normal
    with pytest.raises(ValueError, match='EstimateNormals'):
        FitSphericalHarmonics()(without)
    short = data.clone()
    short.normal = data.normal[:9]
    with pytest.raises(ValueError, match="'normal' has 9 rows"):
        FitSphericalHarmonics()(short)
    bent = data.clone()
    bent.frame = 2 * tangent_frames(data.normal)
    with pytest.raises(ValueError, match='orthonormal'):
        FitSphericalHarmonics()(bent)
    with pytest.raises(ValueError, match="'l_max' must be at least 1"):
        FitSphericalHarmonics(l_max=0)
    with pytest.raises(ValueError, match="'prefilter_alpha' must be"):
        FitSphericalHarmonics(prefilter_alpha=-0.1)
    with pytest.raises(ValueError, match='at least 144'):
        FitSphericalHarmonics(num_light_samples=100)


def test_chunks_of_points_give_the_same_fits(monkeypatch):
    """The fit runs on chunks of points to bound its memory; each point's
    fit is its own, so any chunking gives the same numbers."""
    import tg_intrinsic.transforms.fit_spherical_harmonics as module
    from tg_intrinsic.datasets import svbrdf_scene
    from tg_intrinsic.transforms import FitSphericalHarmonics, ProjectViews
    data = ProjectViews()(svbrdf_scene('sphere', num_views=6,
                                       image_size=(24, 24), seed=0,
                                       resolution=1))
    whole = FitSphericalHarmonics()(data)
    monkeypatch.setattr(module, 'POINTS_PER_CHUNK', 7)
    chunked = FitSphericalHarmonics()(data)
    for key in ('sh_in', 'sh_out', 'sh_in_obs', 'light_radiance',
                'mirror_dir'):
        assert torch.equal(getattr(whole, key), getattr(chunked, key)), key
