"""assemble_capture: EXIF exposures of 8-bit photographs, the cameras
checked against the surface, and what a capture's options do."""
import json
import os

import numpy as np
import pytest
import torch

from tg_intrinsic.io.capture import detect_format, read_capture
from tg_intrinsic.io.capture_writer import write_capture

def test_the_usual_mistakes_are_said_in_words(capture, tmp_path):
    written = write_capture(tmp_path / 'c', capture, 'colmap')
    folder = written['capture']
    os.remove(os.path.join(folder, 'images', '001.exr'))
    with pytest.raises(ValueError, match=r"lists 1 photograph\(s\) that "
                       r".* does not hold: '001.exr'"):
        read_capture(folder)
    # OpenCV cameras written where OpenGL ones belong: they look away
    written = write_capture(tmp_path / 'n', capture, 'nerfstudio')
    path = os.path.join(written['capture'], 'transforms.json')
    spec = json.loads(open(path).read())
    for frame in spec['frames']:
        matrix = np.array(frame['transform_matrix'])
        matrix[:3, 1:3] *= -1
        frame['transform_matrix'] = matrix.tolist()
    open(path, 'w').write(json.dumps(spec))
    with pytest.raises(ValueError, match='no camera .* sees any of the'):
        read_capture(written['capture'])
    with pytest.raises(ValueError, match='no capture this library reads'):
        detect_format(tmp_path)
    with pytest.raises(ValueError, match='does not exist'):
        detect_format(tmp_path / 'nothing')

def test_per_image_exif_exposures_scale_ldr_photographs(capture, tmp_path):
    from PIL import Image
    written = write_capture(tmp_path / 'c', capture, 'nerfstudio', ldr=True)
    folder = written['capture']
    spec = json.loads(open(os.path.join(folder, 'transforms.json')).read())
    times = [1 / 100, 1 / 50, 1 / 100, 1 / 25, 1 / 100]
    for frame, seconds in zip(spec['frames'], times):
        png = os.path.join(folder, frame['file_path'])
        jpeg = os.path.splitext(png)[0] + '.jpg'
        image = Image.open(png)
        exif = Image.Exif()
        ifd = exif.get_ifd(0x8769)
        ifd[0x829A] = seconds
        ifd[0x829D] = 4.0
        ifd[0x8827] = 100
        image.save(jpeg, quality=100, exif=exif)
        os.remove(png)
        frame['file_path'] = os.path.relpath(jpeg, folder)
    open(os.path.join(folder, 'transforms.json'), 'w').write(
        json.dumps(spec))
    data = read_capture(folder, exposure=written['exposure'])
    assert data.capture_info['relative_exposures'] == pytest.approx(
        [t / times[0] for t in times])


def test_a_y_up_world_is_turned_to_z_up(capture, native, tmp_path):
    """The same capture with its world turned so that y is up (the mesh
    and the COLMAP poses), read with up='y', is the z-up one."""
    from tg_intrinsic.io import read_surface, write_ply
    from tg_intrinsic.io.colmap import read_colmap_model, write_colmap_model
    y_up_to_z_up = np.array([[1.0, 0, 0], [0, 0, -1], [0, 1, 0]])
    written = write_capture(tmp_path / 'c', capture, 'colmap')
    folder = written['capture']
    model = os.path.join(folder, 'sparse', '0')
    cameras, images = read_colmap_model(model)
    for image in images:
        image['R'] = image['R'] @ y_up_to_z_up
    write_colmap_model(model, cameras, images)
    geometry = os.path.join(folder, 'geometry.ply')
    pos, face, properties = read_surface(geometry)
    normal = np.stack([properties[k] for k in ('nx', 'ny', 'nz')], 1)
    normal = normal @ y_up_to_z_up  # Q^T applied to every row
    write_ply(geometry, pos @ y_up_to_z_up, face,
              {k: normal[:, i] for i, k in enumerate(('nx', 'ny', 'nz'))})
    data = read_capture(folder, dtype=torch.float64, up='y')
    assert torch.allclose(data.pos, native.pos, atol=1e-12)
    assert torch.allclose(data.normal, native.normal, atol=1e-12)
    assert torch.allclose(data.extrinsics, native.extrinsics, atol=1e-6)
    assert data.capture_info['up'] == 'y'
    with pytest.raises(ValueError, match="'up' must be one of"):
        read_capture(folder, up='x')


def test_the_lighting_turned_and_an_exposure_checked(capture, native,
                                                     tmp_path):
    from tg_intrinsic.geometry.appearance.envmap import rotate_envmap
    written = write_capture(tmp_path / 'c', capture, 'nerfstudio')
    data = read_capture(written['capture'], dtype=torch.float64,
                        envmap_rotation=90.0)
    assert torch.equal(data.envmap, rotate_envmap(native.envmap, 90.0))
    with pytest.raises(ValueError, match='exposure must be a positive'):
        read_capture(written['capture'], exposure=0.0)
