"""SVBRDFResult: the maps as arrays and textures, the .npz round trip, and
the images written for texel and point maps, pixel by pixel against
quantised values and matplotlib's colormap."""
import os

import numpy as np
import pytest
import torch

from tg_intrinsic.nn import SVBRDFResult
from tg_intrinsic.nn.svbrdf_result import MAP_INFO
from tests.conftest import grid_mesh


def result(n=6, entropy=True, texture_shape=None, seed=0, std=False):
    g = torch.Generator().manual_seed(seed)
    return SVBRDFResult(
        base_color=torch.rand(n, 3, generator=g, dtype=torch.float64),
        metallic=torch.rand(n, generator=g, dtype=torch.float64),
        roughness=torch.rand(n, generator=g, dtype=torch.float64),
        entropy=(torch.rand(n, generator=g, dtype=torch.float64)
                 if entropy else None),
        roughness_std=(0.01 + 0.1 * torch.rand(n, generator=g,
                                               dtype=torch.float64)
                       if std else None),
        loss=[2.0, 1.0], seconds=0.5, texture_shape=texture_shape)


def quantised(value):
    """What an 8-bit image stores of a value in [0, 1], back in [0, 1]."""
    return np.floor(np.clip(value, 0, 1) * 255 + 0.5) / 255


def read_png(path):
    import matplotlib.pyplot as plt
    return plt.imread(path)[..., :3]


def test_maps_are_arrays_and_textures():
    res = result()
    maps = res.maps()
    assert sorted(maps) == ['base_color', 'entropy', 'metallic', 'roughness']
    for name, value in maps.items():
        assert isinstance(value, np.ndarray)
        np.testing.assert_array_equal(value, getattr(res, name).numpy())
    assert 'entropy' not in result(entropy=False).maps()
    # texels are listed row by row
    textures = result(texture_shape=(2, 3)).maps()
    assert textures['base_color'].shape == (2, 3, 3)
    assert textures['roughness'].shape == (2, 3)
    np.testing.assert_array_equal(textures['base_color'][1, 2],
                                  res.base_color[5].numpy())
    np.testing.assert_array_equal(textures['metallic'][1, 0],
                                  res.metallic[3].item())


def test_maps_detach_tensors_that_need_gradients():
    res = result()
    res.roughness = res.roughness.clone().requires_grad_(True)
    np.testing.assert_array_equal(res.maps()['roughness'],
                                  res.roughness.detach().numpy())


def test_npz_round_trip(tmp_path):
    res = result(texture_shape=(3, 2))
    path = str(tmp_path / 'sub' / 'maps.npz')
    assert res.save_npz(path) == path
    stored = np.load(path)
    assert sorted(stored.files) == sorted(res.maps())
    for name, value in res.maps().items():
        np.testing.assert_array_equal(stored[name], value)
    assert os.listdir(tmp_path / 'sub') == ['maps.npz']


def test_texel_maps_are_written_as_textures(tmp_path):
    res = result(texture_shape=(2, 3), std=True)
    res.base_color[0] = torch.tensor([1.3, -0.2, 0.5])  # clipped
    paths = res.save(str(tmp_path / 'out'))
    names = [os.path.basename(p) for p in paths]
    assert names == ['maps.npz', 'base_color.png', 'metallic.png',
                     'roughness.png', 'entropy.png', 'roughness_std.png']
    maps = res.maps()
    np.testing.assert_allclose(read_png(paths[1]),
                               quantised(maps['base_color']), atol=1e-6)
    for name, path in zip(('metallic', 'roughness'), paths[2:4]):
        grey = np.repeat(maps[name][..., None], 3, -1)
        np.testing.assert_allclose(read_png(path), quantised(grey),
                                   atol=1e-6)
    import matplotlib
    turbo = matplotlib.colormaps[MAP_INFO['entropy']['cmap']]
    np.testing.assert_allclose(read_png(paths[4]),
                               quantised(turbo(maps['entropy'])[..., :3]),
                               atol=1e-6)
    # the roughness's standard deviation over its range, 0 to 0.1
    assert MAP_INFO['roughness_std']['range'] == (0.0, 0.1)
    np.testing.assert_allclose(
        read_png(paths[5]), quantised(turbo(np.clip(
            maps['roughness_std'] / 0.1, 0, 1))[..., :3]), atol=1e-6)
    assert sorted(os.listdir(tmp_path / 'out')) == sorted(names)


def test_point_maps_are_drawn_from_above(tmp_path):
    # a flat square of points with constant maps, seen by the default
    # camera above it: the square in the middle, black outside its
    # bounding circle
    pos, face = grid_mesh(6)
    res = SVBRDFResult(
        base_color=torch.tensor([0.2, 0.4, 0.6]).repeat(36, 1),
        metallic=torch.full((36, ), 0.75), roughness=torch.full((36, ), 0.3))
    expected = {'base_color': quantised(np.array([0.2, 0.4, 0.6])),
                'metallic': quantised(0.75), 'roughness': quantised(0.3)}
    for label, extra in (('splats', {}), ('faces', {'face': face}),
                         ('trimesh faces', {'face': face.t()})):
        paths = res.save(str(tmp_path / label.replace(' ', '_')), pos=pos,
                         image_size=(32, 40), **extra)
        assert len(paths) == 4  # no entropy map
        for name, path in zip(('base_color', 'metallic', 'roughness'),
                              paths[1:]):
            image = read_png(path)
            assert image.shape == (32, 40, 3), label
            hit = image.max(-1) > 0
            assert hit[16, 20] and not hit[0, 0], label
            np.testing.assert_allclose(
                image[hit], np.broadcast_to(expected[name], image[hit].shape),
                atol=1e-6, err_msg=label)


def test_point_maps_need_positions(tmp_path):
    with pytest.raises(ValueError, match="saving point maps as images needs "
                                         "'pos'"):
        result().save(str(tmp_path))


# ------------------------------------------------------ merge by entropy
def test_merge_by_entropy_takes_each_point_from_the_most_certain():
    inputs = [result(n=50, seed=s) for s in range(4)]
    # ties: the first of the tied inputs wins
    inputs[2].entropy[:5] = inputs[0].entropy[:5]
    inputs[0].entropy[:5] = 0.0
    inputs[3].entropy[:5] = 0.0
    merged, source = SVBRDFResult.merge_by_entropy(inputs)
    assert source.dtype == torch.long and source.shape == (50, )
    for i in range(50):  # brute force, point by point
        values = [r.entropy[i].item() for r in inputs]
        best = values.index(min(values))
        assert source[i].item() == best
        for name in ('base_color', 'metallic', 'roughness', 'entropy'):
            torch.testing.assert_close(getattr(merged, name)[i],
                                       getattr(inputs[best], name)[i])
    assert (source[:5] == 0).all()
    assert merged.seconds == pytest.approx(4 * 0.5)
    assert merged.loss == [] and merged.texture_shape is None
    # one input is itself
    alone, which = SVBRDFResult.merge_by_entropy([inputs[1]])
    assert (which == 0).all()
    torch.testing.assert_close(alone.roughness, inputs[1].roughness)


def test_merge_by_entropy_is_symmetric_under_permuting_the_inputs():
    inputs = [result(n=40, seed=s) for s in range(5)]  # no ties
    merged, source = SVBRDFResult.merge_by_entropy(inputs)
    order = [3, 0, 4, 1, 2]
    permuted, permuted_source = SVBRDFResult.merge_by_entropy(
        [inputs[k] for k in order])
    for name in ('base_color', 'metallic', 'roughness', 'entropy'):
        torch.testing.assert_close(getattr(permuted, name),
                                   getattr(merged, name))
    assert torch.equal(torch.tensor(order)[permuted_source], source)


def test_merge_by_entropy_keeps_the_texture_shape():
    inputs = [result(n=6, seed=s, texture_shape=(2, 3)) for s in range(2)]
    merged, _ = SVBRDFResult.merge_by_entropy(inputs)
    assert merged.texture_shape == (2, 3)
    assert merged.maps()['roughness'].shape == (2, 3)


def test_merge_by_entropy_rejects_bad_inputs():
    with pytest.raises(ValueError, match='non-empty'):
        SVBRDFResult.merge_by_entropy([])
    with pytest.raises(ValueError, match='non-empty'):
        SVBRDFResult.merge_by_entropy(r for r in [result()])
    with pytest.raises(ValueError, match='not an SVBRDFResult'):
        SVBRDFResult.merge_by_entropy([result(), {'roughness': 1}])
    with pytest.raises(ValueError, match='same 6 points'):
        SVBRDFResult.merge_by_entropy([result(n=6), result(n=7)])
    short = result(n=6)
    short.base_color = short.base_color[:5]
    with pytest.raises(ValueError, match=r'results\[1\].base_color'):
        SVBRDFResult.merge_by_entropy([result(n=6), short])
    with pytest.raises(ValueError, match='no entropy'):
        SVBRDFResult.merge_by_entropy([result(), result(entropy=False)])
    nan = result()
    nan.entropy[2] = float('nan')
    with pytest.raises(ValueError, match='NaN'):
        SVBRDFResult.merge_by_entropy([result(), nan])
    with pytest.raises(ValueError, match='texture_shape'):
        SVBRDFResult.merge_by_entropy([result(), result(
            texture_shape=(2, 3))])


# ------------------------------------------------- merge by uncertainty
def test_merge_by_uncertainty_weights_by_inverse_variance():
    inputs = [result(n=30, seed=s, std=True) for s in range(3)]
    merged, weight = SVBRDFResult.merge_by_uncertainty(inputs)
    assert weight.shape == (3, 30)
    torch.testing.assert_close(weight.sum(0), torch.ones(30,
                                                         dtype=weight.dtype))
    for i in range(30):  # brute force, point by point
        precision = [1 / r.roughness_std[i].item() ** 2 for r in inputs]
        total = sum(precision)
        for name in ('base_color', 'metallic', 'roughness'):
            expected = sum(p * getattr(r, name)[i] for p, r in zip(
                precision, inputs)) / total
            torch.testing.assert_close(getattr(merged, name)[i], expected)
        assert merged.roughness_std[i].item() == pytest.approx(
            total ** -0.5)
    # the merged uncertainty is below every input's
    assert bool((merged.roughness_std <= torch.stack(
        [r.roughness_std for r in inputs]).min(0).values).all())
    assert merged.entropy is None and merged.loss == []
    assert merged.seconds == pytest.approx(3 * 0.5)


def test_merge_by_uncertainty_equal_is_the_average_and_certain_wins():
    inputs = [result(n=20, seed=s, std=True) for s in range(4)]
    for r in inputs:
        r.roughness_std = torch.full_like(r.roughness, 0.05)
    merged, _ = SVBRDFResult.merge_by_uncertainty(inputs)
    torch.testing.assert_close(merged.base_color, torch.stack(
        [r.base_color for r in inputs]).mean(0))
    # a recovery a thousand times more certain decides the point
    inputs[2].roughness_std[:5] = 5e-5
    merged, weight = SVBRDFResult.merge_by_uncertainty(inputs)
    assert bool((weight[2, :5] > 0.999).all())
    torch.testing.assert_close(merged.roughness[:5],
                               inputs[2].roughness[:5], atol=1e-3, rtol=0)
    # the order of the inputs does not matter
    permuted, permuted_weight = SVBRDFResult.merge_by_uncertainty(
        inputs[::-1])
    torch.testing.assert_close(permuted.roughness, merged.roughness)
    torch.testing.assert_close(permuted_weight, weight.flip(0))


def test_merge_by_uncertainty_rejects_bad_inputs():
    with pytest.raises(ValueError, match='non-empty'):
        SVBRDFResult.merge_by_uncertainty([])
    with pytest.raises(ValueError, match='no roughness_std'):
        SVBRDFResult.merge_by_uncertainty([result(std=True), result()])
    zero = result(std=True)
    zero.roughness_std[1] = 0.0
    with pytest.raises(ValueError, match='zero or negative'):
        SVBRDFResult.merge_by_uncertainty([result(std=True), zero])
    nan = result(std=True)
    nan.roughness_std[3] = float('inf')
    with pytest.raises(ValueError, match='NaN or infinite'):
        SVBRDFResult.merge_by_uncertainty([result(std=True), nan])
    with pytest.raises(ValueError, match='same 6 points'):
        SVBRDFResult.merge_by_uncertainty([result(std=True),
                                           result(n=7, std=True)])


def texel_result(texel_index=(5, 0, 2, 3), texture_shape=(2, 3)):
    """Points on some texels of a texture: a partial texture."""
    res = result(n=len(texel_index), texture_shape=texture_shape)
    res.texel_index = torch.tensor(texel_index)
    return res


def test_some_texels_are_scattered_into_textures(tmp_path):
    res = texel_result()
    maps = res.maps()
    assert list(maps) == ['base_color', 'metallic', 'roughness', 'entropy',
                          'coverage']
    coverage = np.array([[True, False, True], [True, False, True]])
    np.testing.assert_array_equal(maps['coverage'], coverage)
    for name in ('base_color', 'metallic', 'roughness', 'entropy'):
        value = getattr(res, name).numpy()
        texture = maps[name]
        assert texture.shape == (2, 3) + value.shape[1:]
        flat = texture.reshape((6, ) + value.shape[1:])
        np.testing.assert_array_equal(flat[[5, 0, 2, 3]], value)
        assert np.isnan(flat[[1, 4]]).all()
    paths = res.save(str(tmp_path / 'out'))
    assert [os.path.basename(p) for p in paths] == [
        'maps.npz', 'base_color.png', 'metallic.png', 'roughness.png',
        'entropy.png', 'coverage.png']
    stored = np.load(paths[0])
    np.testing.assert_array_equal(stored['coverage'], coverage)
    np.testing.assert_array_equal(stored['roughness'], maps['roughness'])
    # uncovered texels are black, covered ones their (quantised) values
    colour = read_png(paths[1])
    assert (colour[~coverage] == 0).all()
    np.testing.assert_allclose(colour[coverage],
                               quantised(maps['base_color'][coverage]),
                               atol=1e-6)
    assert (read_png(paths[4])[~coverage] == 0).all()  # entropy
    np.testing.assert_array_equal(read_png(paths[5])[..., 0], coverage)
    # every texel, listed: the texture as without a texel_index
    full = texel_result(tuple(range(6)))
    np.testing.assert_array_equal(full.maps()['roughness'],
                                  full.roughness.numpy().reshape(2, 3))
    assert full.maps()['coverage'].all()


def test_texel_index_bad_input():
    for index, match in (((0, 1, 6), r'outside \[0, 6\)'),
                         ((0, 1, 1), 'repeats texels'),
                         ((-1, 0, 1), r'outside \[0, 6\)')):
        with pytest.raises(ValueError, match=match):
            texel_result(index).maps()
    wrong = texel_result((0, 1, 2))
    wrong.texel_index = torch.tensor([0, 1])
    with pytest.raises(ValueError, match=r'one integer texel per point'):
        wrong.maps()
    wrong.texel_index = torch.tensor([0.0, 1.0, 2.0])
    with pytest.raises(ValueError, match=r'one integer texel per point'):
        wrong.maps()
    lost = texel_result((0, 1, 2))
    lost.texture_shape = None
    with pytest.raises(ValueError, match="'texel_index' needs a "
                                         "'texture_shape'"):
        lost.maps()
