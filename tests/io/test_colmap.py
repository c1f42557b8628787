"""COLMAP sparse models: write_colmap_model -> read_colmap_model round
trips (text and binary), hand-written text files, camera_matrix, a check
against pycolmap in both directions, and a ValueError naming the file for
every malformed model."""
import os
import struct

import numpy as np
import pytest
import torch

from tg_intrinsic.datasets import svbrdf_scene
from tg_intrinsic.io import read_scene
from tg_intrinsic.io.capture import read_capture
from tg_intrinsic.io.capture_writer import write_capture

from tg_intrinsic.io.colmap import (CAMERA_MODELS, SUPPORTED_MODELS,
                                    camera_matrix, find_colmap_model,
                                    read_colmap_model, write_colmap_model)


def random_rotations(n, seed=0):
    """Random rotations from QR, plus ones near 180 degrees about each
    axis and the identity (the hard cases of matrix -> quaternion)."""
    rng = np.random.default_rng(seed)
    Q, R = np.linalg.qr(rng.normal(size=(n, 3, 3)))
    Q = Q * np.sign(np.diagonal(R, axis1=1, axis2=2))[:, None, :]
    Q[np.linalg.det(Q) < 0] *= -1
    flips = [np.diag(d) for d in ([1., -1., -1.], [-1., 1., -1.],
                                  [-1., -1., 1.], [1., 1., 1.])]
    return np.concatenate([Q, np.stack(flips)])


def some_cameras():
    """One camera of every COLMAP model, ids not in order."""
    rng = np.random.default_rng(1)
    cameras = {}
    for model_id, (model, count) in CAMERA_MODELS.items():
        params = rng.normal(size=count) * 0.1
        params[:2] = 400 + 100 * rng.random(2)
        cameras[3 * model_id + 2] = dict(model=model, width=640 + model_id,
                                         height=480, params=params)
    return cameras


def some_images(cameras, seed=0):
    rng = np.random.default_rng(seed)
    ids = sorted(cameras)
    return [dict(image_id=int(image_id), name=f'images/view_{image_id}.png',
                 camera_id=ids[k % len(ids)], R=R, t=rng.normal(size=3) * 3)
            for k, (image_id, R) in enumerate(
                zip(rng.permutation(100)[:8] + 1, random_rotations(4, seed)))]


def rodrigues(q):
    """Independent quaternion -> matrix: axis-angle from the quaternion,
    then R = I + sin(a) N + (1 - cos(a)) N^2 with N the cross matrix."""
    q = np.asarray(q, float) / np.linalg.norm(q)
    angle = 2 * np.arctan2(np.linalg.norm(q[1:]), q[0])
    axis = q[1:] / np.linalg.norm(q[1:])
    N = np.array([[0, -axis[2], axis[1]], [axis[2], 0, -axis[0]],
                  [-axis[1], axis[0], 0]])
    return np.eye(3) + np.sin(angle) * N + (1 - np.cos(angle)) * N @ N


def check_same(cameras, images, read_cameras, read_images):
    assert sorted(read_cameras) == sorted(cameras)
    for camera_id, camera in cameras.items():
        got = read_cameras[camera_id]
        assert got['model'] == camera['model']
        assert (got['width'], got['height']) == (camera['width'],
                                                 camera['height'])
        assert got['params'].dtype == np.float64
        np.testing.assert_array_equal(got['params'], camera['params'])
    expected = sorted(images, key=lambda image: image['image_id'])
    assert [i['image_id'] for i in read_images] == \
        [i['image_id'] for i in expected]
    for got, image in zip(read_images, expected):
        assert got['name'] == image['name']
        assert got['camera_id'] == image['camera_id']
        assert got['R'].shape == (3, 3) and got['t'].shape == (3,)
        np.testing.assert_allclose(got['R'], image['R'], rtol=0, atol=1e-12)
        np.testing.assert_array_equal(got['t'], image['t'])


# ------------------------------------------------------------ round trips
@pytest.mark.parametrize('binary', [False, True])
def test_round_trip(tmp_path, binary):
    cameras, folder = some_cameras(), tmp_path / 'new' / 'model'
    images = some_images(cameras)
    paths = write_colmap_model(folder, cameras, images, binary=binary)
    ext = '.bin' if binary else '.txt'
    assert [os.path.basename(p) for p in paths] == \
        ['cameras' + ext, 'images' + ext, 'points3D' + ext]
    assert sorted(os.listdir(folder)) == sorted(map(os.path.basename, paths))
    check_same(cameras, images, *read_colmap_model(folder))
    if binary:
        assert (folder / 'points3D.bin').read_bytes() == bytes(8)
    else:
        text = (folder / 'images.txt').read_text()
        assert text.startswith('#')
        lines = [line for line in text.split('\n')
                 if not line.startswith('#')]
        # each image line, then an empty points line; the file ends in \n
        assert len(lines) == 2 * len(images) + 1 and lines[-1] == ''
        assert lines[1::2] == [''] * len(images)
        q = [float(v) for v in lines[0].split()[1:5]]
        assert q[0] >= 0 and abs(np.linalg.norm(q) - 1) < 1e-15
        assert all(line.startswith('#') for line in
                   (folder / 'points3D.txt').read_text().splitlines())


def test_round_trip_without_images(tmp_path):
    cameras = {1: dict(model='PINHOLE', width=4, height=3,
                       params=np.array([5., 6., 2., 1.5]))}
    write_colmap_model(tmp_path, cameras, [])
    read_cameras, images = read_colmap_model(tmp_path)
    assert images == [] and read_cameras[1]['model'] == 'PINHOLE'


# ----------------------------------------------------- hand-written files
CAMERAS_TXT = """# Camera list with one line of data per camera:
#   CAMERA_ID, MODEL, WIDTH, HEIGHT, PARAMS[]
# Number of cameras: 2
1 SIMPLE_RADIAL 2000 1500 1711.25 1000 750 -0.0125
7 PINHOLE 800 600 620.5 621.75 399.5 300.25
"""

IMAGES_TXT = """# Image list with two lines of data per image:
#   IMAGE_ID, QW, QX, QY, QZ, TX, TY, TZ, CAMERA_ID, NAME
#   POINTS2D[] as (X, Y, POINT3D_ID)
# Number of images: 3, mean observations per image: 1
5 0.70001 0.1 -0.5 0.5 -1.25 0.5 4 7 b/IMG_0005.JPG
10.5 20.25 -1 300.75 40.5 12
# a comment between images
2 0.8775825618903728 0.4794255386042030 0 0 1 2 3 1 IMG_0002.JPG

9 1 0 0 0 0 0 0 1 IMG_0009.JPG"""


def write_text_model(folder, cameras=CAMERAS_TXT, images=IMAGES_TXT):
    folder.mkdir(parents=True, exist_ok=True)
    (folder / 'cameras.txt').write_text(cameras)
    (folder / 'images.txt').write_text(images)
    (folder / 'points3D.txt').write_text('# 3D point list\n')
    return folder


def test_hand_written_text(tmp_path):
    cameras, images = read_colmap_model(write_text_model(tmp_path))
    assert sorted(cameras) == [1, 7]
    assert cameras[1]['model'] == 'SIMPLE_RADIAL'
    assert (cameras[1]['width'], cameras[1]['height']) == (2000, 1500)
    np.testing.assert_array_equal(cameras[1]['params'],
                                  [1711.25, 1000, 750, -0.0125])
    np.testing.assert_array_equal(cameras[7]['params'],
                                  [620.5, 621.75, 399.5, 300.25])
    assert [i['image_id'] for i in images] == [2, 5, 9]
    assert [i['name'] for i in images] == ['IMG_0002.JPG', 'b/IMG_0005.JPG',
                                           'IMG_0009.JPG']
    assert [i['camera_id'] for i in images] == [1, 7, 1]
    # (0.70001, 0.1, -0.5, 0.5) has norm 1 + 7e-6: round-off, normalised
    np.testing.assert_allclose(images[1]['R'],
                               rodrigues([.70001, .1, -.5, .5]), atol=1e-14)
    np.testing.assert_array_equal(images[1]['t'], [-1.25, 0.5, 4])
    # (cos 0.5, sin 0.5, 0, 0): 1 radian about x
    c, s = np.cos(1), np.sin(1)
    np.testing.assert_allclose(images[0]['R'], [[1, 0, 0], [0, c, -s],
                                                [0, s, c]], atol=1e-15)
    np.testing.assert_allclose(images[0]['R'], rodrigues(
        [0.8775825618903728, 0.4794255386042030, 0, 0]), atol=1e-15)
    np.testing.assert_array_equal(images[2]['R'], np.eye(3))
    for image in images:
        assert image['R'].dtype == image['t'].dtype == np.float64
        x = np.array([0.3, -2., 5.])
        np.testing.assert_allclose(image['R'].T @ (image['R'] @ x), x)


def test_world_to_camera_convention(tmp_path):
    """x_cam = R x_world + t: the camera centre is -R^T t."""
    # a camera at (0, 0, -4) looking along +z, turned 90 degrees about it
    text = '1 0.7071067811865476 0 0 0.7071067811865476 0 0 4 1 a.png\n\n'
    write_text_model(tmp_path, images=text)
    _, images = read_colmap_model(tmp_path)
    R, t = images[0]['R'], images[0]['t']
    np.testing.assert_allclose(-R.T @ t, [0, 0, -4], atol=1e-15)
    # world +x is camera +y (down in the image), world +y camera -x
    np.testing.assert_allclose(R @ [1, 0, 0], [0, 1, 0], atol=1e-15)
    np.testing.assert_allclose(R @ [0, 1, 0], [-1, 0, 0], atol=1e-15)


def test_binary_preferred_over_text(tmp_path):
    cameras = some_cameras()
    images = some_images(cameras)
    write_colmap_model(tmp_path, cameras, images, binary=True)
    (tmp_path / 'cameras.txt').write_text('garbage\n')
    (tmp_path / 'images.txt').write_text('garbage\n')
    check_same(cameras, images, *read_colmap_model(tmp_path))


def test_find_colmap_model(tmp_path):
    assert find_colmap_model(tmp_path) is None
    capture = tmp_path / 'capture'
    (capture / 'images').mkdir(parents=True)
    cameras = some_cameras()
    images = some_images(cameras)
    write_colmap_model(capture / 'sparse', cameras, images[:2])
    assert find_colmap_model(capture) == str(capture / 'sparse')
    write_colmap_model(capture / 'sparse' / '1', cameras, images[:3])
    write_colmap_model(capture / 'sparse' / '0', cameras, images,
                       binary=True)
    assert find_colmap_model(capture) == os.path.join(capture, 'sparse', '0')
    assert find_colmap_model(capture / 'sparse' / '1') == \
        str(capture / 'sparse' / '1')
    check_same(cameras, images, *read_colmap_model(capture))
    check_same(cameras, images[:3],
               *read_colmap_model(str(capture / 'sparse' / '1')))


# ------------------------------------------------------------ camera_matrix
@pytest.mark.parametrize('model, params, K, distortion', [
    ('SIMPLE_PINHOLE', [500, 320, 240],
     [[500, 0, 320], [0, 500, 240], [0, 0, 1]], [0, 0, 0, 0]),
    ('PINHOLE', [500, 510, 320.5, 240.25],
     [[500, 0, 320.5], [0, 510, 240.25], [0, 0, 1]], [0, 0, 0, 0]),
    ('SIMPLE_RADIAL', [500, 320, 240, -0.1],
     [[500, 0, 320], [0, 500, 240], [0, 0, 1]], [-0.1, 0, 0, 0]),
    ('RADIAL', [500, 320, 240, -0.1, 0.02],
     [[500, 0, 320], [0, 500, 240], [0, 0, 1]], [-0.1, 0.02, 0, 0]),
    ('OPENCV', [500, 510, 320, 240, -0.1, 0.02, 1e-3, -2e-3],
     [[500, 0, 320], [0, 510, 240], [0, 0, 1]], [-0.1, 0.02, 1e-3, -2e-3]),
])
def test_camera_matrix(model, params, K, distortion):
    got_K, got_distortion = camera_matrix(
        dict(model=model, width=640, height=480, params=np.array(params)))
    assert got_K.shape == (3, 3) and got_distortion.shape == (4,)
    assert got_K.dtype == got_distortion.dtype == np.float64
    np.testing.assert_array_equal(got_K, K)
    np.testing.assert_array_equal(got_distortion, distortion)


def test_camera_matrix_unsupported():
    assert SUPPORTED_MODELS == ('SIMPLE_PINHOLE', 'PINHOLE', 'SIMPLE_RADIAL',
                                'RADIAL', 'OPENCV')
    camera = dict(model='OPENCV_FISHEYE', width=64, height=48,
                  params=np.zeros(8))
    with pytest.raises(ValueError, match='OPENCV_FISHEYE.*PINHOLE.*'
                       'image_undistorter'):
        camera_matrix(camera)
    with pytest.raises(ValueError, match='PINHOLE needs 4 parameters'):
        camera_matrix(dict(model='PINHOLE', params=np.zeros(3)))


# --------------------------------------------------------------- bad input
def test_missing_folder_and_files(tmp_path):
    with pytest.raises(ValueError, match='nowhere.*does not exist'):
        read_colmap_model(tmp_path / 'nowhere')
    with pytest.raises(ValueError, match="holds no cameras.txt or "
                       r"cameras.bin: give the folder of a COLMAP sparse "
                       r"model \(sparse/0\)"):
        read_colmap_model(tmp_path)
    (tmp_path / 'file').write_text('')
    with pytest.raises(ValueError, match="file' is a file"):
        read_colmap_model(tmp_path / 'file')
    (tmp_path / 'cameras.txt').write_text(CAMERAS_TXT)
    with pytest.raises(ValueError, match='holds no images.txt or images.bin'):
        read_colmap_model(tmp_path)
    (tmp_path / 'cameras.txt').unlink()
    (tmp_path / 'images.bin').write_bytes(bytes(8))
    with pytest.raises(ValueError, match='holds no cameras.txt'):
        read_colmap_model(tmp_path)


@pytest.mark.parametrize('file, old, new, match', [
    ('cameras', '750 -0.0125', '750 x1', r"cameras.txt' line 4: a parameter "
     r"'x1' is not a number"),
    ('cameras', '2000 1500', '2000.5 1500', r"cameras.txt' line 4: WIDTH "
     r"'2000.5' is not an integer"),
    ('cameras', '750 -0.0125', '750', r"cameras.txt' line 4: camera 1 of "
     r"model SIMPLE_RADIAL needs 4 parameters \(f, cx, cy, k\) but has 3"),
    ('cameras', '621.75 399.5', '621.75 399.5 1', r"cameras.txt' line 5: "
     r"camera 7 of model PINHOLE needs 4"),
    ('cameras', 'SIMPLE_RADIAL', 'SIMPLE_RADIAL_X', r"cameras.txt' line 4: "
     r"unknown camera model 'SIMPLE_RADIAL_X'"),
    ('cameras', '7 PINHOLE 800 600', '7 PINHOLE 0 600', r"cameras.txt' line "
     r"5: camera 7 is 0 x 600 pixels"),
    ('cameras', '7 PINHOLE', '1 PINHOLE', r"cameras.txt' line 5: camera 1 "
     r"appears twice"),
    ('cameras', ' 600 620.5 621.75 399.5 300.25', '', r"cameras.txt' line "
     r"5: a camera line needs"),
    ('images', '0.5 4 7 b', '0.5 4 8 b', r"images.txt' line 5: image 5 "
     r"\('b/IMG_0005.JPG'\) uses camera 8, which cameras.txt does not hold"),
    ('images', '2 0.8775825618903728 0.4794255386042030 0 0',
     '2 0 0 0 0', r"images.txt' line 8: image 2 \('IMG_0002.JPG'\) has a "
     r"quaternion of zero length"),
    ('images', '-1.25 0.5', '-1.25 O.5', r"images.txt' line 5: TY 'O.5' is "
     r"not a number"),
    ('images', '5 0.7', '5.0 0.7', r"images.txt' line 5: IMAGE_ID '5.0' is "
     r"not an integer"),
    ('images', '\n10.5 20.25 -1 300.75 40.5 12\n', '\n',
     r"images.txt' line 6: the line after image 5 must hold its 2D points"),
    ('images', ' 7 b/IMG_0005.JPG', ' 7', r"images.txt' line 5: an image "
     r"line needs"),
    ('images', '\n9 1 0 0 0', '\n2 1 0 0 0', r"images.txt' line 10: image 2 "
     r"appears twice"),
])
def test_bad_text(tmp_path, file, old, new, match):
    texts = dict(cameras=CAMERAS_TXT, images=IMAGES_TXT)
    assert texts[file].count(old) == 1
    texts[file] = texts[file].replace(old, new)
    write_text_model(tmp_path, **texts)
    with pytest.raises(ValueError, match=match):
        read_colmap_model(tmp_path)


def binary_model(folder):
    cameras = {1: dict(model='PINHOLE', width=64, height=48,
                       params=np.array([50., 51., 32., 24.])),
               2: dict(model='OPENCV', width=64, height=48,
                       params=np.array([50., 51., 32., 24., .1, .2, .3, .4]))}
    images = [dict(image_id=i, name=f'img{i}.png', camera_id=1 + i % 2,
                   R=np.eye(3), t=np.arange(3.) + i) for i in (1, 2)]
    write_colmap_model(folder, cameras, images, binary=True)
    return ((folder / 'cameras.bin').read_bytes(),
            (folder / 'images.bin').read_bytes())


def test_truncated_binary(tmp_path):
    cameras_bin, images_bin = binary_model(tmp_path)
    # every cut of images.bin: in the count, a pose, a name, the points count
    for size in range(len(images_bin)):
        (tmp_path / 'images.bin').write_bytes(images_bin[:size])
        with pytest.raises(ValueError, match=r"images.bin' ends after "
                           f"{size} bytes, inside .*truncated"):
            read_colmap_model(tmp_path)
    (tmp_path / 'images.bin').write_bytes(images_bin)
    for size in range(len(cameras_bin)):
        (tmp_path / 'cameras.bin').write_bytes(cameras_bin[:size])
        with pytest.raises(ValueError, match=r"cameras.bin' ends after "
                           f"{size} bytes, inside .*truncated"):
            read_colmap_model(tmp_path)
    # a points count larger than the file
    (tmp_path / 'cameras.bin').write_bytes(cameras_bin)
    (tmp_path / 'images.bin').write_bytes(images_bin[:-8] + struct.pack(
        '<Q', 5))
    with pytest.raises(ValueError, match=r"images.bin' ends after .* inside "
                       r"image 2 of 2: the file is truncated"):
        read_colmap_model(tmp_path)


def test_bad_binary(tmp_path):
    cameras_bin, images_bin = binary_model(tmp_path)
    # the model id of the first camera: after the count and the camera id
    bad = cameras_bin[:12] + struct.pack('<i', 42) + cameras_bin[16:]
    (tmp_path / 'cameras.bin').write_bytes(bad)
    with pytest.raises(ValueError, match=r"cameras.bin' \(camera 1 of 2\): "
                       r"unknown camera model id 42"):
        read_colmap_model(tmp_path)
    (tmp_path / 'cameras.bin').write_bytes(cameras_bin)
    # the camera id of the first image: after count, id and 7 doubles
    bad = images_bin[:68] + struct.pack('<I', 9) + images_bin[72:]
    (tmp_path / 'images.bin').write_bytes(bad)
    with pytest.raises(ValueError, match=r"images.bin' \(image 1 of 2\): "
                       r"image 1 \('img1.png'\) uses camera 9, which "
                       r"cameras.bin does not hold"):
        read_colmap_model(tmp_path)
    bad = images_bin[:12] + bytes(32) + images_bin[44:]
    (tmp_path / 'images.bin').write_bytes(bad)
    with pytest.raises(ValueError, match=r"images.bin' \(image 1 of 2\): "
                       r"image 1 \('img1.png'\) has a quaternion of zero"):
        read_colmap_model(tmp_path)


def test_bad_writes(tmp_path):
    cameras = some_cameras()
    image = some_images(cameras)[0]
    with pytest.raises(ValueError, match=r'whitespace\): write it '
                       'with binary=True'):
        write_colmap_model(tmp_path, cameras, [dict(image, name='a b.png')])
    write_colmap_model(tmp_path, cameras, [dict(image, name='a b.png')],
                       binary=True)
    assert read_colmap_model(tmp_path)[1][0]['name'] == 'a b.png'
    with pytest.raises(ValueError, match='uses camera 1000'):
        write_colmap_model(tmp_path, cameras, [dict(image, camera_id=1000)])
    with pytest.raises(ValueError, match='R must be a'):
        write_colmap_model(tmp_path, cameras, [dict(image, R=2 * image['R'])])
    with pytest.raises(ValueError, match='image 4 appears twice'):
        write_colmap_model(tmp_path, cameras, [dict(image, image_id=4)] * 2)
    with pytest.raises(ValueError, match="unknown model 'FISH'"):
        write_colmap_model(tmp_path, {1: dict(cameras[2], model='FISH')}, [])
    with pytest.raises(ValueError, match='PINHOLE needs 4 parameters'):
        write_colmap_model(tmp_path, {1: dict(model='PINHOLE', width=2,
                                              height=2, params=[1, 2])}, [])


# ----------------------------------------------------------------- pycolmap
def distorted_pixel(K, distortion, x_cam):
    """OpenCV's projection, written out: the normalised point, Brown-Conrady
    distortion, then K."""
    k1, k2, p1, p2 = distortion
    x, y = x_cam[0] / x_cam[2], x_cam[1] / x_cam[2]
    r2 = x * x + y * y
    radial = 1 + k1 * r2 + k2 * r2 * r2
    xd = x * radial + 2 * p1 * x * y + p2 * (r2 + 2 * x * x)
    yd = y * radial + p1 * (r2 + 2 * y * y) + 2 * p2 * x * y
    return (K @ np.array([xd, yd, 1.]))[:2]


def pycolmap_pose(image):
    pose = image.cam_from_world
    pose = pose() if callable(pose) else pose
    return pose.rotation.matrix(), np.asarray(pose.translation)


def check_against_pycolmap(reconstruction, cameras, images):
    assert sorted(reconstruction.cameras) == sorted(cameras)
    for camera_id, camera in cameras.items():
        theirs = reconstruction.cameras[camera_id]
        assert theirs.model.name == camera['model']
        assert (theirs.width, theirs.height) == (camera['width'],
                                                 camera['height'])
        np.testing.assert_array_equal(theirs.params, camera['params'])
    assert sorted(reconstruction.images) == \
        sorted(image['image_id'] for image in images)
    for image in images:
        theirs = reconstruction.images[image['image_id']]
        assert theirs.name == image['name']
        assert theirs.camera_id == image['camera_id']
        R, t = pycolmap_pose(theirs)
        np.testing.assert_allclose(R, image['R'], rtol=0, atol=1e-12)
        np.testing.assert_allclose(t, image['t'], rtol=0, atol=1e-12)


@pytest.mark.parametrize('binary', [False, True])
def test_pycolmap_reads_ours(tmp_path, binary):
    pycolmap = pytest.importorskip('pycolmap')
    cameras = some_cameras()
    images = some_images(cameras)
    write_colmap_model(tmp_path, cameras, images, binary=binary)
    check_against_pycolmap(pycolmap.Reconstruction(str(tmp_path)), cameras,
                           images)


@pytest.mark.parametrize('binary', [False, True])
def test_we_read_pycolmap(tmp_path, binary):
    pycolmap = pytest.importorskip('pycolmap')
    reconstruction = pycolmap.Reconstruction()
    cameras = some_cameras()
    for camera_id, camera in cameras.items():
        theirs = pycolmap.Camera.create_from_model_name(
            camera_id, camera['model'], 100.0, camera['width'],
            camera['height'])
        theirs.params = camera['params']
        reconstruction.add_camera_with_trivial_rig(theirs)
    images = some_images(cameras, seed=3)
    for image in images:
        pose = pycolmap.Rigid3d(np.concatenate(
            [image['R'], image['t'][:, None]], 1))
        # 2D points, so that the reader skips non-empty points lines
        keypoints = np.random.default_rng(image['image_id']).uniform(
            0, 400, (image['image_id'] % 4, 2))
        reconstruction.add_image_with_trivial_frame(pycolmap.Image(
            name=image['name'], keypoints=keypoints,
            camera_id=image['camera_id'], image_id=image['image_id']), pose)
    # the poses as pycolmap holds them (it keeps quaternions)
    for image in images:
        image['R'], image['t'] = pycolmap_pose(
            reconstruction.images[image['image_id']])
    if binary:
        reconstruction.write_binary(str(tmp_path))
    else:
        reconstruction.write_text(str(tmp_path))
        lines = (tmp_path / 'images.txt').read_text().split('\n')
        assert any(len(line.split()) == 9 for line in lines)
    read_cameras, read_images = read_colmap_model(tmp_path)
    assert sorted(read_cameras) == sorted(cameras)
    for camera_id, camera in cameras.items():
        assert read_cameras[camera_id]['model'] == camera['model']
        np.testing.assert_array_equal(read_cameras[camera_id]['params'],
                                      camera['params'])
    assert [i['name'] for i in read_images] == [
        i['name'] for i in sorted(images, key=lambda i: i['image_id'])]
    for got, image in zip(read_images, sorted(
            images, key=lambda i: i['image_id'])):
        np.testing.assert_allclose(got['R'], image['R'], rtol=0, atol=1e-12)
        np.testing.assert_allclose(got['t'], image['t'], rtol=0, atol=1e-12)


@pytest.mark.parametrize('model, params', [
    ('PINHOLE', [520.5, 515.25, 320.5, 240.75]),
    ('OPENCV', [520.5, 515.25, 320.5, 240.75, -0.12, 0.03, 1.5e-3, -2e-3]),
])
def test_projection_matches_pycolmap(tmp_path, model, params):
    pycolmap = pytest.importorskip('pycolmap')
    cameras = {1: dict(model=model, width=640, height=480,
                       params=np.array(params))}
    write_colmap_model(tmp_path, cameras, [])
    theirs = pycolmap.Reconstruction(str(tmp_path)).cameras[1]
    K, distortion = camera_matrix(read_colmap_model(tmp_path)[0][1])
    rng = np.random.default_rng(0)
    points = np.concatenate([rng.uniform(-0.5, 0.5, (20, 2)),
                             np.ones((20, 1))], 1) * rng.uniform(1, 5, (20, 1))
    expected = theirs.img_from_cam(points)
    ours = np.stack([distorted_pixel(K, distortion, p) for p in points])
    np.testing.assert_allclose(ours, expected, rtol=1e-9)


def test_colmap_principal_point_is_taken_as_it_is(tmp_path):
    """COLMAP: the upper-left pixel's centre is (0.5, 0.5), the library's
    convention, so cx, cy go into K unchanged."""
    from tg_intrinsic.io.colmap import camera_matrix
    K, distortion = camera_matrix({'model': 'PINHOLE', 'width': 24,
                                   'height': 20, 'params': np.array(
                                       [30.0, 31.0, 11.3, 9.1])})
    assert np.array_equal(K, [[30, 0, 11.3], [0, 31, 9.1], [0, 0, 1]])
    assert not distortion.any()

def test_distorted_colmap_photographs_are_undistorted(tmp_path):
    cv2 = pytest.importorskip('cv2')
    from tg_intrinsic.io.colmap import read_colmap_model, write_colmap_model
    # large enough for the lens to move pixels by more than the blur of
    # two resamplings
    capture = svbrdf_scene('sphere', num_views=2, image_size=(60, 72),
                           materials='metals', seed=1, resolution=2)
    write_capture(tmp_path / 'n', capture, 'native')
    native = read_scene(tmp_path / 'n', dtype=torch.float64)
    written = write_capture(tmp_path / 'c', capture, 'colmap')
    folder = written['capture']
    model = os.path.join(folder, 'sparse', '0')
    cameras, images = read_colmap_model(model)
    coefficients = np.array([-0.3, 0.1, 0.002, -0.002])
    height, width = native.images.shape[1:3]
    for camera in cameras.values():
        fx, fy, cx, cy = camera['params']
        camera['model'] = 'OPENCV'
        camera['params'] = np.array([fx, fy, cx, cy, *coefficients])
    write_colmap_model(model, cameras, images)
    # distort each photograph with OpenCV (pixel centres at integers)
    K_cv = native.intrinsics[0].numpy().copy()
    K_cv[:2, 2] -= 0.5
    map_x, map_y = cv2.initInverseRectificationMap(
        K_cv, coefficients, None, K_cv, (width, height), cv2.CV_32FC1)
    from tg_intrinsic.io.hdr import read_exr, write_hdr
    distorted = []
    for image in images:
        path = os.path.join(folder, 'images', image['name'])
        pinhole = read_exr(path)
        distorted.append(cv2.remap(pinhole, map_x, map_y, cv2.INTER_LINEAR,
                                   borderMode=cv2.BORDER_REPLICATE))
        os.remove(path)
        image['name'] = image['name'].replace('.exr', '.hdr')
        write_hdr(os.path.join(folder, 'images', image['name']),
                  distorted[-1])
    write_colmap_model(model, cameras, images)
    data = read_capture(folder, dtype=torch.float64)
    distorted = torch.from_numpy(np.stack(distorted)).double()
    images = data.images[:]
    kept = ~torch.isnan(images).any(-1)
    # the photographs as read come back to the pinhole ones: much closer
    # than the distorted ones are (the blur of two resamplings at the
    # sphere's outline stays; undistorting the wrong way gives 1.8 x raw)
    undistorted = (images - native.images).abs()[kept].mean()
    raw = (distorted - native.images).abs()[kept].mean()
    assert float(undistorted) < 0.6 * float(raw)


def test_photographs_the_model_does_not_list_are_named(capture, tmp_path):
    import shutil
    from tg_intrinsic.io.colmap import colmap_spec
    written = write_capture(tmp_path / 'c', capture, 'colmap')
    images = os.path.join(written['capture'], 'images')
    shutil.copy(os.path.join(images, '000.exr'),
                os.path.join(images, 'unregistered.exr'))
    spec = colmap_spec(written['capture'])
    assert len(spec.views) == capture.images.size(0)
    assert spec.notes == ["1 photograph(s) in images/ are not in the model "
                          "(not registered), left out: unregistered.exr"]
