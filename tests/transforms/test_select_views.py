"""SelectViews and keep_views: the kept capture is the chosen columns of the
original, the choice is the geometry function's, and the pipeline runs on
the result."""
import math

import pytest
import torch

from tg_intrinsic.datasets import svbrdf_scene
from tg_intrinsic.geometry.appearance import select_views
from tg_intrinsic.geometry.appearance.brdf import reflect, to_local
from tg_intrinsic.geometry.appearance.envmap import (equirect_lookup,
                                                     filter_envmap)
from tg_intrinsic.transforms import (FitSphericalHarmonics, SelectViews,
                                     SpectralUncertainty, keep_views)


@pytest.fixture(scope='module')
def scene():
    return svbrdf_scene('sphere', num_views=7, resolution=1,
                        image_size=(16, 16), dtype=torch.float64, seed=2,
                        specular_samples=16, light_samples=16,
                        image_specular_samples=2, image_light_samples=2)


def test_keep_views_slices_every_view_axis(scene):
    views = [5, 1, 3]
    kept = keep_views(scene, views)
    for key in ('obs_radiance', 'obs_dir', 'obs_mask'):
        assert torch.equal(kept[key], scene[key][:, views])
    for key in ('intrinsics', 'extrinsics', 'images'):
        assert torch.equal(kept[key], scene[key][views])
    assert kept.view_index.tolist() == views
    assert scene.obs_mask.size(1) == 7 and 'view_index' not in scene
    # indices compose with an earlier selection
    again = keep_views(kept, torch.tensor([2, 0]))
    assert again.view_index.tolist() == [3, 5]
    assert torch.equal(again.obs_radiance, scene.obs_radiance[:, [3, 5]])


def test_keep_views_bad_input(scene):
    with pytest.raises(ValueError, match='outside'):
        keep_views(scene, [0, 7])
    with pytest.raises(ValueError, match='more than once'):
        keep_views(scene, [1, 1])
    with pytest.raises(ValueError, match='at least one'):
        keep_views(scene, [])
    with pytest.raises(ValueError, match='integer'):
        keep_views(scene, torch.tensor([0.5]))
    fitted = FitSphericalHarmonics(l_max=2, num_light_samples=64)(scene)
    with pytest.raises(ValueError, match='before FitSphericalHarmonics'):
        keep_views(fitted, [0])
    with pytest.raises(ValueError, match='obs_mask'):
        keep_views(scene.clone().update({'obs_mask': None}), [0])


def test_select_views_is_the_greedy_choice(scene):
    transform = SelectViews(4, seed_views=[6], l_max=3,
                            num_light_samples=256)
    out = transform(scene)
    prefilter = max(1 / math.sqrt(4), 1 / 3)
    # the same inputs built by hand
    fitted = FitSphericalHarmonics(l_max=3, num_light_samples=256,
                                   prefilter_alpha=prefilter)(scene)
    mirror = reflect(scene.obs_dir, (scene.normal / scene.normal.norm(
        dim=-1, keepdim=True)).unsqueeze(1))
    local = to_local(mirror, fitted.frame)
    views, mean_entropy = select_views(
        local, local[..., 2].clamp_min(0) * scene.obs_mask,
        equirect_lookup(filter_envmap(scene.envmap, prefilter), mirror),
        scene.obs_radiance, fitted.sh_in, fitted.irradiance, 4,
        seed_views=[6], prefilter_alpha=prefilter)
    assert out.view_index.tolist() == views.tolist()
    assert out.view_index[0] == 6 and out.obs_mask.shape == (42, 4)
    torch.testing.assert_close(out.selection_entropy, mean_entropy)
    assert torch.equal(out.images, scene.images[views])
    # the input is not changed, and the pipeline runs on the kept views
    assert scene.obs_mask.size(1) == 7
    result = SpectralUncertainty()(FitSphericalHarmonics(
        l_max=3, num_light_samples=256)(out))
    assert result.entropy.shape == (42, )
    # expected entropy falls as views are added (on this scene)
    assert out.selection_entropy[-1] < out.selection_entropy[0]


def test_candidates_and_bad_input(scene):
    out = SelectViews(3, seed_views=[0], candidates=[2, 4], l_max=2,
                      num_light_samples=64)(scene)
    assert out.view_index[0] == 0 and sorted(out.view_index[1:].tolist()) \
        == [2, 4]
    with pytest.raises(ValueError, match='exceeds'):
        SelectViews(4, seed_views=[0], candidates=[2, 4], l_max=2,
                    num_light_samples=64)(scene)
    with pytest.raises(ValueError, match='seed_views'):
        SelectViews(2, seed_views=[9], l_max=2,
                    num_light_samples=64)(scene)
    with pytest.raises(ValueError, match='integer'):
        SelectViews(0.5)
    with pytest.raises(ValueError, match='envmap'):
        SelectViews(2)(scene.clone().update({'envmap': None}))


def test_repr():
    assert repr(SelectViews(5, seed_views=[1, 2])) == (
        'SelectViews(num_views=5, seed_views=(1, 2), l_max=5, '
        'prefilter_alpha=None)')
