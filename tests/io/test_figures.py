"""Figures: valid PNG files of the documented size written atomically
(no temporary left, the old file kept when drawing fails), the rendered
views against the camera geometry (framing, z up on screen, headlight
shading, nearest point in front), and the colour range."""
import math
import os

import matplotlib
import numpy as np
import pytest
import torch
from PIL import Image

from tg_intrinsic.geometry.appearance.cameras import look_at_cameras
from tg_intrinsic.io import figures
from tg_intrinsic.io.figures import (VIEWS, draw_surface, line_figure,
                                     render_surface, save_figure,
                                     value_range)
from tg_intrinsic.geometry.appearance.splat import splat_index
from tests.conftest import fibonacci_sphere, icosphere

PNG_SIGNATURE = b'\x89PNG\r\n\x1a\n'


def read_png(path):
    """The file as an RGB array in [0, 1], after checking it is a PNG."""
    with open(path, 'rb') as f:
        assert f.read(8) == PNG_SIGNATURE
    with Image.open(path) as image:
        image.verify()  # a complete, uncorrupted file
    with Image.open(path) as image:
        return np.asarray(image.convert('RGB'), dtype=np.float64) / 255


def only_file(folder, name):
    assert os.listdir(folder) == [name]  # no temporary left behind


def ball():
    pos, face = icosphere(2)
    return pos.numpy(), face.numpy()


# --- the colour range ----------------------------------------------------


def test_value_range():
    assert value_range([3.0, -1.0, 2.0]) == (-1.0, 3.0)
    assert value_range([3.0, np.nan, -1.0]) == (-1.0, 3.0)  # NaN skipped
    assert value_range([3.0, -1.0], vmin=0) == (0.0, 3.0)
    assert value_range([3.0, -1.0], vmin=0, vmax=10) == (0.0, 10.0)
    assert value_range([2.0, 2.0, 2.0]) == (2.0, 3.0)  # constant: width 1
    assert value_range([1.0, 5.0], vmin=6) == (6.0, 7.0)  # empty range


# --- rendering -------------------------------------------------------------


def test_a_sphere_fills_the_frame_as_the_cameras_say():
    # the camera sits at 4 radii with a field of view 1.1 times the
    # sphere's angular diameter: the disc covers pi/4 (tan a / tan 1.1a)^2
    pos, face = ball()
    images = render_surface(pos, face, size=96,
                            views=('front-left', 'top', 'back'))
    assert images.shape == (3, 96, 96, 3)
    assert images.min() >= 0 and images.max() <= 1
    a = math.asin(1 / 4)
    disc = math.pi / 4 * (math.tan(a) / math.tan(1.1 * a)) ** 2
    for image in images:
        hit = (image != 1).any(-1)
        assert abs(hit.mean() - disc) < 0.03
        assert (image[[0, 0, -1, -1], [0, -1, 0, -1]] == 1).all()  # white
        rows, cols = np.nonzero(hit)  # centred
        assert abs(rows.mean() - 47.5) < 1.5 and abs(cols.mean() - 47.5) < 1.5


def test_z_is_up_on_screen_and_colours_are_shaded_by_a_headlight():
    pos, face = ball()
    colors = np.where(pos[:, 2:] > 0, [1.0, 0.0, 0.0], [0.0, 0.0, 1.0])
    (image, ) = render_surface(pos, face, colors=colors, size=96,
                               views=('front-right', ))
    hit = (image != 1).any(-1)
    red = hit & (image[..., 0] > 0) & (image[..., 2] == 0)
    blue = hit & (image[..., 2] > 0) & (image[..., 0] == 0)
    # seen from 20 degrees above the equator, whose near side runs about
    # 13 pixels below the centre (rows 48 to 61, give or take a triangle)
    assert hit[:40].sum() > 1000 and hit[76:].sum() > 500
    assert np.array_equal(red[:40], hit[:40])  # the top is z > 0
    assert np.array_equal(blue[76:], hit[76:])
    assert not red[76:].any() and not blue[:40].any()
    # c (0.35 + 0.65 |n.d|): red + blue = 1 before shading, so their sum
    # is the shade: bright where the sphere faces the camera, never below
    # 0.35, darkest at the silhouette
    shade = image[..., 0] + image[..., 2]
    assert shade[hit].min() >= 0.35 - 1e-9 and shade[hit].max() <= 1 + 1e-9
    assert shade[40:56, 40:56].min() > 0.9
    rim = hit & ~np.roll(hit, 2, axis=1)  # a pixel or two inside the edge
    assert shade[rim].mean() < 0.7
    assert image[hit][:, 1].max() == 0  # no green anywhere


def test_values_go_through_the_colour_map_and_nan_is_grey():
    pos, face = ball()
    values = np.full(len(pos), 2.0)
    (image, ) = render_surface(pos, face, values=values, vmin=0, vmax=4,
                               cmap='viridis', size=64, views=('top', ))
    hit = (image != 1).any(-1)
    colour = np.asarray(matplotlib.colormaps['viridis'](0.5)[:3])
    shade = image[hit] / colour  # the same factor on every channel
    assert np.allclose(shade, shade[:, :1], atol=1e-9)
    assert shade.min() >= 0.35 - 1e-9 and shade.max() <= 1 + 1e-9
    values[:] = np.nan
    with pytest.warns(RuntimeWarning, match='All-NaN'):  # numpy's nanmin
        (image, ) = render_surface(pos, face, values=values, size=64,
                                   views=('top', ))
    grey = image[(image != 1).any(-1)]
    assert np.allclose(grey, grey[:, :1]) and grey.max() <= 0.5 + 1e-9


def test_faces_in_pyg_layout_only():
    pos, face = ball()  # face (3, F)
    values = pos[:, 0]
    a = render_surface(pos, face, values=values, size=48)
    b = render_surface(torch.from_numpy(pos), torch.from_numpy(face),
                       values=values, size=48)
    assert np.array_equal(a, b)
    # one layout: a guess made a mesh of 3 triangles ambiguous
    with pytest.raises(ValueError, match=r"shape \(3, F\), PyG's layout, "
                                         r"got \(320, 3\)"):
        render_surface(pos, face.T, values=values, size=48)
    three = np.array([[0, 0, 0], [1, 0, 0], [0, 1, 0], [0, 0, 1.0]])
    tris = np.array([[0, 1, 2], [0, 1, 3], [0, 2, 3]]).T
    image = render_surface(three, tris, size=48)
    assert (image < 1).any()  # drawn, not refused


def test_point_clouds_show_the_nearest_point():
    pos = fibonacci_sphere(600)
    direction = torch.tensor(VIEWS['front-left'], dtype=torch.float64)
    direction = direction / direction.norm()
    K, E = look_at_cameras(4 * direction[None], fov_degrees=35.0,
                           image_size=(64, 64))
    index = splat_index(pos, K[0], E[0], (64, 64))
    assert index.shape == (64, 64) and index.dtype == np.int64
    hit = index >= 0
    assert 0.4 < hit.mean() < 0.9 and index[0, 0] == -1
    # nearest in front: the pixels show the hemisphere facing the camera
    facing = (pos[index[hit]] @ direction).numpy()
    assert (facing > 0).mean() > 0.97
    # rendered grey (0.75) with normals: shaded by the headlight like a
    # mesh, facing points at the centre nearly unshaded
    (image, ) = render_surface(pos, normal=pos, size=64,
                               views=('front-left', ))
    centre = image[28:36, 28:36]
    assert np.allclose(centre, centre[..., :1])  # grey
    assert centre.min() > 0.7 and centre.max() <= 0.75 + 1e-9
    assert (image[[0, 0, -1, -1], [0, -1, 0, -1]] == 1).all()


# --- files -----------------------------------------------------------------


def test_draw_surface_writes_a_png_with_a_colour_bar(tmp_path):
    pos, face = ball()
    path = tmp_path / 'height.png'
    assert draw_surface(str(path), pos, face, values=pos[:, 2],
                        title='height', label='z (m)', size=64) == str(path)
    only_file(tmp_path, 'height.png')
    image = read_png(path)
    # figsize (3.2 per view + 1.0, 3.6) inches at 110 dpi
    assert image.shape == (396, 814, 3)
    # a colour bar right of the views, from viridis(0) to viridis(1)
    yellow = np.asarray(matplotlib.colormaps['viridis'](1.0)[:3])
    purple = np.asarray(matplotlib.colormaps['viridis'](0.0)[:3])
    for end in (yellow, purple):
        rows, cols = np.nonzero(np.abs(image - end).max(-1) < 0.03)
        assert len(cols) > 10 and cols.min() > 0.8 * image.shape[1]
    # colours instead of values: no colour bar, no viridis yellow
    draw_surface(str(path), pos, face, colors=np.tile([1.0, 0, 0],
                                                      (len(pos), 1)),
                 views=('top', ), size=64)
    image = read_png(path)
    assert image.shape == (396, int(4.2 * 110), 3)
    assert (np.abs(image - yellow).max(-1) < 0.03).sum() == 0
    red = (image[..., 0] > 0.3) & (image[..., 1:].max(-1) < 0.05)
    assert red.sum() > 1000


def test_line_figure_draws_the_series(tmp_path):
    path = tmp_path / 'curve.png'
    x = np.arange(1, 11)
    line_figure(str(path), [('loss', x, 1.0 / x, 'r-'),
                            ('accuracy', x, 1 - 1.0 / x, 'b--')],
                title='training', xlabel='epoch', ylabel='value', logy=True,
                integer_x=True, hlines=[('goal', 0.5, ':')],
                vlines=[('best', 4, '--')])
    only_file(tmp_path, 'curve.png')
    image = read_png(path)
    assert image.shape == (418, 616, 3)  # 5.6 x 3.8 inches at 110 dpi
    red = (image[..., 0] > 0.9) & (image[..., 1:].max(-1) < 0.1)
    blue = (image[..., 2] > 0.9) & (image[..., :2].max(-1) < 0.1)
    assert red.sum() > 100 and blue.sum() > 50


def test_saving_is_atomic_and_closes_the_figure(tmp_path, monkeypatch):
    plt = figures._pyplot()
    path = tmp_path / 'figure.png'
    fig = plt.figure(figsize=(2, 1))
    save_figure(fig, str(path), dpi=50)
    assert not plt.fignum_exists(fig.number)
    assert read_png(path).shape == (50, 100, 3)
    before = path.read_bytes()

    def broken(self, *args, **kwargs):
        raise RuntimeError('renderer crashed')

    monkeypatch.setattr(matplotlib.figure.Figure, 'savefig', broken)
    with pytest.raises(RuntimeError, match='renderer crashed'):
        line_figure(str(path), [('a', [0, 1], [0, 1], 'k-')], 't', 'x', 'y')
    assert path.read_bytes() == before  # the old figure is kept whole
    only_file(tmp_path, 'figure.png')


def test_draw_cameras_counts_the_cameras_that_see_nothing(tmp_path,
                                                         monkeypatch):
    import matplotlib.figure
    from tg_intrinsic.datasets import svbrdf_scene
    from tg_intrinsic.io.figures import draw_cameras
    data = svbrdf_scene('sphere', num_views=4, image_size=(16, 16),
                        materials='metals', seed=0, resolution=0)
    turn = torch.diag(torch.tensor([-1.0, 1.0, -1.0]))  # about its y axis
    extrinsics = data.extrinsics.clone()
    extrinsics[1] = turn @ extrinsics[1]  # the same centre, looking away
    titles = []
    monkeypatch.setattr(matplotlib.figure.Figure, 'suptitle',
                        lambda self, text, **kw: titles.append(text))
    path = draw_cameras(str(tmp_path / 'c.png'), data.pos, data.intrinsics,
                        extrinsics, (16, 16), 'four')
    assert (tmp_path / 'c.png').stat().st_size > 0 and path.endswith('c.png')
    assert titles == ['four\n4 cameras, 3 see the surface, 1 (orange) see '
                      'none of it']
