"""Scene folders: write_scene -> read_scene round trips, and every malformed
folder raises a ValueError that names the file and the problem."""
import json
import os

import numpy as np
import pytest
import torch
from torch_geometric.data import Data

from tg_intrinsic.geometry import vertex_normals
from tg_intrinsic.geometry.appearance.cameras import look_at_cameras
from tg_intrinsic.io import read_scene, scene_summary, write_ply, write_scene
from tg_intrinsic.io import scene as scene_module

from tests.conftest import icosphere, sky_envmap

try:
    import OpenEXR  # noqa: F401
    HAS_EXR = hasattr(OpenEXR, 'File')
except ImportError:
    HAS_EXR = False


def tiny_scene(num_views=3, height=6, width=8, seed=0):
    """A 42-vertex icosphere, a few cameras and random HDR images (the
    format does not care what the pixels show)."""
    pos, face = icosphere(1, torch.float32)
    rng = np.random.default_rng(seed)
    directions = torch.tensor(rng.normal(size=(num_views, 3)))
    directions = directions / directions.norm(dim=1, keepdim=True)
    K, E = look_at_cameras(3 * directions, fov_degrees=50,
                           image_size=(height, width))
    images = np.exp(rng.normal(0, 2, (num_views, height, width, 3)))
    return Data(pos=pos, normal=vertex_normals(pos, face), face=face,
                images=torch.tensor(images, dtype=torch.float32),
                intrinsics=K.float(), extrinsics=E.float(),
                envmap=sky_envmap(8, 16).float())


@pytest.fixture
def scene(tmp_path):
    folder = tmp_path / 'scene'
    write_scene(folder, tiny_scene(), 'npy')
    return folder


def load_cameras(folder):
    return json.loads((folder / 'cameras.json').read_text())


def save_cameras(folder, spec):
    (folder / 'cameras.json').write_text(json.dumps(spec))


FORMATS = ['npy', 'hdr'] + (['exr'] if HAS_EXR else [])


# ------------------------------------------------------------ round trips
@pytest.mark.parametrize('image_format', FORMATS)
def test_round_trip(tmp_path, image_format):
    data = tiny_scene()
    paths = write_scene(tmp_path / 's', data, image_format)
    assert os.path.basename(paths[-1]) == 'cameras.json'
    assert all(os.path.isfile(p) for p in paths)
    assert not [n for n in os.listdir(tmp_path / 's') if n.startswith('.')]
    back = read_scene(tmp_path / 's')
    assert set(back.keys()) == {'pos', 'normal', 'face', 'images',
                                'intrinsics', 'extrinsics', 'envmap'}
    for key in ('pos', 'normal', 'intrinsics', 'extrinsics'):
        assert back[key].dtype == torch.float32
        assert torch.equal(back[key], data[key]), key
    assert torch.equal(back.face, data.face)
    assert back.images.dtype == torch.float32
    if image_format == 'hdr':  # 8-bit mantissas: 1/256 of a pixel's peak
        for key in ('images', 'envmap'):
            peak = data[key].amax(-1, keepdim=True)
            assert bool(((back[key] - data[key]).abs()
                         <= peak / 256 + 1e-30).all()), key
    else:
        assert torch.equal(back.images, data.images)
        assert torch.equal(back.envmap, data.envmap)
    double = read_scene(tmp_path / 's', dtype=torch.float64)
    assert double.pos.dtype == double.extrinsics.dtype == torch.float64
    assert '42 points, 80 triangles; 3 view(s) of 6 x 8' in \
        scene_summary(back)


def test_rewrite_removes_stale_photographs(tmp_path):
    write_scene(tmp_path, tiny_scene(num_views=4), 'npy')
    write_scene(tmp_path, tiny_scene(num_views=2), 'npy')
    assert sorted(os.listdir(tmp_path / 'images')) == ['000.npy', '001.npy']
    assert read_scene(tmp_path).images.shape[0] == 2


def test_bare_list_finds_geometry_and_envmap(scene):
    spec = load_cameras(scene)
    save_cameras(scene, spec['cameras'])  # no "geometry", no "envmap"
    data = read_scene(scene)
    assert data.pos.shape == (42, 3) and data.envmap.shape == (8, 16, 3)
    # photographs at the top level are not taken for the envmap
    os.replace(scene / 'images' / '000.npy', scene / 'view0.npy')
    cameras = spec['cameras']
    cameras[0]['image'] = 'view0.npy'
    save_cameras(scene, cameras)
    assert read_scene(scene).images.shape[0] == 3


def test_point_cloud_normals(tmp_path):
    data = tiny_scene()
    write_scene(tmp_path, data, 'npy')
    # a cloud without normals: estimated, pointing outwards
    write_ply(tmp_path / 'geometry.ply', data.pos.numpy())
    cloud = read_scene(tmp_path)
    assert 'face' not in cloud
    assert torch.allclose(cloud.normal.norm(dim=1), torch.ones(42))
    assert bool(((cloud.normal * cloud.pos).sum(1) > 0.9).all())
    # a cloud with normals: the file's, normalised
    stored = torch.tensor([[0.0, 0.0, 2.0]]).expand(42, 3).numpy()
    write_ply(tmp_path / 'geometry.ply', data.pos.numpy(), properties={
        'nx': stored[:, 0], 'ny': stored[:, 1], 'nz': stored[:, 2]})
    assert torch.equal(read_scene(tmp_path).normal,
                       torch.tensor([0.0, 0.0, 1.0]).expand(42, 3))


def test_format_is_documented():
    assert scene_module.FORMAT in scene_module.__doc__.replace('\n    ',
                                                               '\n')
    for word in ('cameras.json', '"K"', '"R"', '"t"', 'images/'):
        assert word in scene_module.FORMAT


def test_ldr_photographs_warn(tmp_path):
    data = tiny_scene()
    rng = np.random.default_rng(1)
    data.images = torch.tensor(rng.integers(0, 256, data.images.shape)
                               / 255.0, dtype=torch.float32)
    write_scene(tmp_path, data, 'npy')
    with pytest.warns(UserWarning, match=r"3 of 3 photographs look "
                      r"low-dynamic-range .*: 'images/000.npy'"):
        read_scene(tmp_path)


# ------------------------------------------------------------ bad folders
def test_missing_or_wrong_folder(tmp_path):
    with pytest.raises(ValueError, match="scene folder '.*nowhere' does "
                       "not exist"):
        read_scene(tmp_path / 'nowhere')
    (tmp_path / 'file').write_text('x')
    with pytest.raises(ValueError, match="is a file, not a scene folder"):
        read_scene(tmp_path / 'file')
    with pytest.raises(ValueError, match="has no cameras.json"):
        read_scene(tmp_path)


@pytest.mark.parametrize('edit, message', [
    (lambda s: '{"cameras": [', r"cameras.json' is not valid JSON: .* line "
     r"1"),
    (lambda s: [], 'non-empty "cameras" list'),
    (lambda s: {'views': s['cameras']}, 'non-empty "cameras" list'),
    (lambda s: 7, 'must hold an object'),
    (lambda s: s['cameras'][:1] + ['x'], 'camera 1 must be an object'),
    (lambda s: [{k: v for k, v in c.items() if k != 'K'}
                for c in s['cameras']], "camera 0 has no 'K'"),
    (lambda s: [dict(c, R=c['R'][:2]) for c in s['cameras']],
     r'camera 0: "R" must be a 3x3 matrix, got shape \[2, 3\]'),
    (lambda s: [dict(c, t=[1, 2]) for c in s['cameras']],
     r'"t" must be a list of 3 numbers'),
    (lambda s: [dict(c, K=[[1, 0], [0, 1, 2], [0, 0, 1]])
                for c in s['cameras']], r'"K" must be a 3x3 matrix'),
    (lambda s: [dict(c, t=[0, float('nan'), 1]) for c in s['cameras']],
     r'"t" holds NaN or infinite'),
    (lambda s: [dict(c, R=(2 * np.array(c['R'])).tolist())
                for c in s['cameras']], r'"R" must be a rotation'),
    (lambda s: [dict(c, R=(-np.array(c['R'])).tolist())
                for c in s['cameras']], r'det R = -1'),
    (lambda s: [dict(c, K=[[-5, 0, 4], [0, 5, 3], [0, 0, 1]])
                for c in s['cameras']], r'positive focal lengths'),
    (lambda s: [dict(c, K=[[5, 0, 4], [0, 5, 3], [0, 1, 1]])
                for c in s['cameras']], r'must be a pinhole matrix'),
    (lambda s: [dict(c, image=3) for c in s['cameras']],
     r'"image" must be a file name'),
    (lambda s: dict(s, geometry=5), r'"geometry" must be a file name'),
])
def test_malformed_cameras_json(scene, edit, message):
    spec = edit(load_cameras(scene))
    if isinstance(spec, str):
        (scene / 'cameras.json').write_text(spec)
    else:
        save_cameras(scene, spec)
    with pytest.raises(ValueError, match=message) as info:
        read_scene(scene)
    assert 'cameras.json' in str(info.value)


def test_image_and_camera_counts(scene):
    spec = load_cameras(scene)
    save_cameras(scene, dict(spec, cameras=spec['cameras'][:2]))
    with pytest.raises(ValueError, match=r"lists 2 camera\(s\) but .*images"
                       r"' holds 3 image\(s\): '002.npy' has no camera"):
        read_scene(scene)
    save_cameras(scene, spec)
    os.remove(scene / 'images' / '001.npy')
    with pytest.raises(ValueError, match=r"camera 1 of .* lists the image "
                       r"'images/001.npy', but .* does not exist"):
        read_scene(scene)
    spec['cameras'][1]['image'] = spec['cameras'][0]['image']
    save_cameras(scene, spec)
    with pytest.raises(ValueError, match=r"camera 1 lists the image "
                       r"'images/000.npy' again"):
        read_scene(scene)


@pytest.mark.parametrize('image, message', [
    (np.ones((6, 9, 3), np.float32), r"'.*002.npy' is 6 x 9 pixels but "
     r"'images/000.npy' is 6 x 8; all photographs must have one size"),
    (np.ones((6, 8), np.float32), r"002.npy' has shape \[6, 8\]; a "
     r"photograph must be \[H, W, 3\] \(3 channels"),
    (np.ones((6, 8, 4), np.float32), r"002.npy' has shape \[6, 8, 4\]"),
    (np.ones((6, 8, 3), np.uint8), r"002.npy' holds uint8, not "
     r"floating-point"),
    (np.full((6, 8, 3), np.inf, np.float32), r"002.npy' has infinite or "
     r"negative radiance"),
    (-np.ones((6, 8, 3), np.float32), r"002.npy' has infinite or negative"),
])
def test_bad_photographs(scene, image, message):
    np.save(scene / 'images' / '002.npy', image)
    with pytest.raises(ValueError, match=message):
        read_scene(scene)


def test_nan_pixels_are_kept_for_projectviews(scene):
    image = np.load(scene / 'images' / '002.npy')
    image[0, 0] = np.nan
    np.save(scene / 'images' / '002.npy', image)
    assert bool(torch.isnan(read_scene(scene).images[2, 0, 0]).all())


def test_unreadable_or_ldr_format_photograph(scene):
    spec = load_cameras(scene)
    (scene / 'images' / '002.npy').write_bytes(b'not numpy')
    with pytest.raises(ValueError, match=r"could not read '.*002.npy': it "
                       r"is not a NumPy .npy file") as info:
        read_scene(scene)
    assert 'pickle' not in str(info.value)  # numpy's advice is not ours
    os.remove(scene / 'images' / '002.npy')
    (scene / 'images' / '002.png').write_bytes(b'\x89PNG')
    spec['cameras'][2]['image'] = 'images/002.png'
    save_cameras(scene, spec)
    with pytest.raises(ValueError, match=r"002.png' is not a linear HDR "
                       r"image \(8-bit .png photographs are not HDR\)"):
        read_scene(scene)


@pytest.mark.parametrize('envmap, message', [
    (np.ones((8, 16, 4), np.float32), r"envmap.npy.*must be an "
     r"equirectangular image of shape \[H, W, 3\]"),
    (np.ones((8, 16), np.float32), r"envmap.npy.*equirectangular"),
    (-np.ones((8, 16, 3), np.float32), r"envmap.npy.*negative radiance"),
])
def test_bad_envmap(scene, envmap, message):
    np.save(scene / 'envmap.npy', envmap)
    with pytest.raises(ValueError, match=message):
        read_scene(scene)


def test_envmap_not_twice_as_wide_is_refused(scene):
    np.save(scene / 'envmap.npy', np.ones((8, 8, 3), np.float32) * 0.3)
    with pytest.raises(ValueError, match=r"envmap.npy' is 8 x 8 pixels; an "
                       r"equirectangular .* twice as wide as high"):
        read_scene(scene)


def test_geometry_and_envmap_files(scene):
    spec = load_cameras(scene)
    cameras = spec['cameras']
    save_cameras(scene, dict(spec, geometry='mesh.obj'))
    with pytest.raises(ValueError, match=r"geometry file '.*mesh.obj' named "
                       r"in cameras.json does not exist"):
        read_scene(scene)
    save_cameras(scene, dict(spec, envmap='sky.hdr'))
    with pytest.raises(ValueError, match=r"environment map '.*sky.hdr' "
                       r"named in cameras.json does not exist"):
        read_scene(scene)
    save_cameras(scene, cameras)  # found by extension now
    (scene / 'other.off').write_text('OFF\n3 1 0\n0 0 0\n1 0 0\n0 1 0\n'
                                     '3 0 1 2\n')
    with pytest.raises(ValueError, match=r"holds several geometry .* files:"
                       r" 'geometry.ply', 'other.off'; name the one to use "
                       r"as \"geometry\""):
        read_scene(scene)
    os.remove(scene / 'other.off')
    os.remove(scene / 'geometry.ply')
    with pytest.raises(ValueError, match=r"holds no geometry .* file "
                       r"\(.obj/.off/.ply/.stl\)"):
        read_scene(scene)
    write_ply(scene / 'geometry.ply', np.eye(3))
    np.save(scene / 'sky.npy', np.ones((8, 16, 3), np.float32))
    with pytest.raises(ValueError, match=r"several environment-map files: "
                       r"'envmap.npy', 'sky.npy'"):
        read_scene(scene)
    os.remove(scene / 'sky.npy')
    with pytest.raises(ValueError, match=r"geometry.ply' is a point cloud "
                       r"of 3 point\(s\) without normals"):
        read_scene(scene)
    (scene / 'geometry.ply').write_bytes(b'ply\nbroken')
    with pytest.raises(ValueError, match=r"could not read '.*geometry.ply'"):
        read_scene(scene)


def test_write_scene_checks_its_input(tmp_path):
    data = tiny_scene()
    with pytest.raises(ValueError, match="'image_format' must be one of"):
        write_scene(tmp_path, data, 'png')
    del data.images
    with pytest.raises(ValueError, match="write_scene needs 'data.images'"):
        write_scene(tmp_path, data, 'npy')
    data = tiny_scene()
    data.intrinsics = data.intrinsics[:2]
    with pytest.raises(ValueError, match=r"there are 3 images, so "
                       r"'data.intrinsics' must be \[3, 3, 3\]"):
        write_scene(tmp_path, data, 'npy')
    data = tiny_scene()
    data.images[1, 0, 0, 0] = float('nan')
    with pytest.raises(ValueError, match="image 1: 'image' has NaN"):
        write_scene(tmp_path, data, 'hdr')
    assert not (tmp_path / 'cameras.json').exists()


# ----------------------------------------- folders and files in each other's
# place, unreadable .npy files, nothing to fit: said as such
def test_folder_where_a_file_belongs(scene):
    spec = load_cameras(scene)
    image = np.load(scene / 'images' / '002.npy')
    os.remove(scene / 'images' / '002.npy')
    (scene / 'images' / '002.npy').mkdir()
    with pytest.raises(ValueError, match=r"camera 2 of .* lists the image "
                       r"'images/002.npy', but '.*002.npy' is a folder, not "
                       r"a file"):
        read_scene(scene)
    os.rmdir(scene / 'images' / '002.npy')
    os.symlink(scene / 'gone.npy', scene / 'images' / '002.npy')
    with pytest.raises(ValueError, match=r"002.npy' is a link to "
                       r"'.*gone.npy', which does not exist"):
        read_scene(scene)
    os.remove(scene / 'images' / '002.npy')
    np.save(scene / 'images' / '002.npy', image)
    geometry = (scene / 'geometry.ply').read_bytes()
    os.remove(scene / 'geometry.ply')
    (scene / 'geometry.ply').mkdir()
    with pytest.raises(ValueError, match=r"geometry file '.*geometry.ply' "
                       r"named in cameras.json is a folder, not a file"):
        read_scene(scene)
    save_cameras(scene, spec['cameras'])  # looked for, not named
    with pytest.raises(ValueError, match=r"holds no geometry .* file .* "
                       r"\('geometry.ply' is a folder, not a file\)"):
        read_scene(scene)
    save_cameras(scene, spec)
    os.rmdir(scene / 'geometry.ply')
    (scene / 'geometry.ply').write_bytes(geometry)
    os.remove(scene / 'envmap.npy')
    (scene / 'envmap.npy').mkdir()
    with pytest.raises(ValueError, match=r"environment map '.*envmap.npy' "
                       r"named in cameras.json is a folder, not a file"):
        read_scene(scene)
    os.remove(scene / 'cameras.json')
    (scene / 'cameras.json').mkdir()
    with pytest.raises(ValueError, match=r"cameras.json' is a folder, not a "
                       r"file"):
        read_scene(scene)


def test_file_where_the_image_folder_belongs(scene):
    for name in os.listdir(scene / 'images'):
        os.remove(scene / 'images' / name)
    os.rmdir(scene / 'images')
    (scene / 'images').write_text('x')
    with pytest.raises(ValueError, match=r"'images/000.npy', but .* does "
                       r"not exist: '.*images' is a file, not a folder"):
        read_scene(scene)


@pytest.mark.parametrize('content, message', [
    (b'', r'it is empty'),
    (b'\x00garbage', r'it is not a NumPy .npy file'),
    (np.array([{'a': 1}], dtype=object), r'it holds Python objects'),
    ({'a': np.ones(3)}, r'it is a .npz archive \(numpy.savez\), not one '
     r'.npy array'),
])
def test_unreadable_npy_photograph_and_envmap(scene, content, message):
    for name in ('images/001.npy', 'envmap.npy'):
        path = scene / name
        original = path.read_bytes()
        if isinstance(content, bytes):
            path.write_bytes(content)
        elif isinstance(content, dict):
            with open(path, 'wb') as f:
                np.savez(f, **content)
        else:
            np.save(path, content, allow_pickle=True)
        with pytest.raises(ValueError, match=r"could not read '.*"
                           + name.split('/')[-1] + "': " + message) as info:
            read_scene(scene)
        assert 'allow_pickle' not in str(info.value)
        path.write_bytes(original)


def test_nothing_to_fit(scene):
    np.save(scene / 'envmap.npy', np.zeros((8, 16, 3), np.float32))
    with pytest.raises(ValueError, match=r"environment map '.*envmap.npy' "
                       r"is black \(every pixel 0\): it lights nothing"):
        read_scene(scene)
    np.save(scene / 'envmap.npy', np.ones((8, 16, 3), np.float32))
    for i, value in enumerate((0.0, np.nan, 0.0)):  # 0 or NaN, nothing else
        np.save(scene / 'images' / f'00{i}.npy',
                np.full((6, 8, 3), value, np.float32))
    with pytest.raises(ValueError, match=r"no photograph listed in "
                       r"'.*cameras.json' has a pixel above 0"):
        read_scene(scene)
    np.save(scene / 'images' / '002.npy', np.full((6, 8, 3), 0.5, np.float32))
    assert read_scene(scene).images.shape == (3, 6, 8, 3)


def test_scene_files(scene, tmp_path):
    names = [os.path.relpath(p, scene)
             for p in scene_module.scene_files(scene)]
    assert names == ['cameras.json', 'geometry.ply', 'envmap.npy',
                     'images/000.npy', 'images/001.npy', 'images/002.npy']
    with pytest.raises(ValueError, match='does not exist'):
        scene_module.scene_files(tmp_path / 'nowhere')
