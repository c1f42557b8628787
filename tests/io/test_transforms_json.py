"""transforms.json: the NeRF/Blender and nerfstudio pixel conventions
against their definitions written out here, masks and applied_transform."""
import json
import math
import os

import numpy as np
import pytest
import torch

from tg_intrinsic.io.capture import read_capture
from tg_intrinsic.io.capture_writer import write_capture
from tg_intrinsic.io.transforms_json import transforms_spec

def nerf_file(folder, frames, **top):
    folder.mkdir(parents=True, exist_ok=True)
    (folder / 'transforms.json').write_text(json.dumps(dict(top,
                                                            frames=frames)))

def test_nerf_and_nerfstudio_pixel_conventions(tmp_path, capture):
    """A ray through the centre of pixel (i, j) of an OpenGL camera at the
    origin: NeRF/Blender, ((j + 0.5 - W/2) / f, -(i + 0.5 - H/2) / f, -1);
    nerfstudio, ((j + 0.5 - cx) / fx, -(i + 0.5 - cy) / fy, -1). The point
    on it must project to (j + 0.5, i + 0.5)."""
    from tg_intrinsic.geometry.appearance.cameras import project
    from tg_intrinsic.io.hdr import write_hdr
    height, width, angle = 20, 24, 0.9
    image = np.ones((height, width, 3), np.float32)
    write_hdr(str(tmp_path / 'p.hdr'), image)
    frame = {'file_path': '../p.hdr', 'transform_matrix': np.eye(4).tolist()}
    nerf_file(tmp_path / 'nerf', [frame], camera_angle_x=angle)
    fx, fy, cx, cy = 30.0, 31.0, 11.3, 9.1
    nerf_file(tmp_path / 'ns', [frame], fl_x=fx, fl_y=fy, cx=cx, cy=cy,
              w=width, h=height)
    i, j = 7, 15
    f = 0.5 * width / math.tan(angle / 2)
    rays = {'nerf': ((j + 0.5 - width / 2) / f, -(i + 0.5 - height / 2) / f),
            'ns': ((j + 0.5 - cx) / fx, -(i + 0.5 - cy) / fy)}
    from tg_intrinsic.io.transforms_json import transforms_spec
    for name, (dx, dy) in rays.items():
        view = transforms_spec(tmp_path / name).views[0]
        point = 2.5 * np.array([dx, dy, -1.0])
        uv, depth = project(
            torch.tensor(point)[None], torch.tensor(view.K)[None],
            torch.tensor(np.concatenate([view.R, view.t[:, None]], 1))[None])
        assert torch.allclose(uv[0, 0], torch.tensor([j + 0.5, i + 0.5],
                                                     dtype=torch.float64))
        assert float(depth[0, 0]) == pytest.approx(2.5)

def test_masks_leave_pixels_out(capture, tmp_path):
    from PIL import Image
    written = write_capture(tmp_path / 'c', capture, 'nerfstudio')
    folder = written['capture']
    spec = json.loads(open(os.path.join(folder, 'transforms.json')).read())
    height, width = capture.images.shape[1:3]
    mask = np.zeros((height, width), np.uint8)
    mask[:, : width // 2] = 255
    Image.fromarray(mask).save(os.path.join(folder, 'mask.png'))
    spec['frames'][0]['mask_path'] = 'mask.png'
    open(os.path.join(folder, 'transforms.json'), 'w').write(
        json.dumps(spec))
    data = read_capture(folder)
    assert bool(torch.isnan(data.images[0, :, width // 2:]).all())
    assert data.capture_info['pixels_left_out']['masked'] == \
        height * (width - width // 2)
    Image.fromarray(mask[:-2]).save(os.path.join(folder, 'mask.png'))
    with pytest.raises(ValueError, match='mask.png'):
        read_capture(folder)


def test_applied_transform_is_undone(capture, native, tmp_path):
    """nerfstudio's ns-process-data moves COLMAP's world by
    applied_transform; the cameras go back to meet the mesh."""
    written = write_capture(tmp_path / 'c', capture, 'nerfstudio')
    path = os.path.join(written['capture'], 'transforms.json')
    spec = json.loads(open(path).read())
    a = math.radians(30)
    applied = np.array([[0.0, 1, 0, 0.3], [1, 0, 0, -0.2], [0, 0, -1, 0.1]])
    applied[:, :3] = applied[:, :3] @ np.array(
        [[math.cos(a), -math.sin(a), 0], [math.sin(a), math.cos(a), 0],
         [0, 0, 1]])
    for frame in spec['frames']:
        c2w = np.array(frame['transform_matrix'])
        c2w[:3] = applied[:, :3] @ c2w[:3]
        c2w[:3, 3] += applied[:, 3]
        frame['transform_matrix'] = c2w.tolist()
    spec['applied_transform'] = applied.tolist()
    open(path, 'w').write(json.dumps(spec))
    data = read_capture(written['capture'], dtype=torch.float64)
    # (the written rotations are float32's, rescaled to unit columns)
    assert torch.allclose(data.extrinsics, native.extrinsics, atol=1e-6)
    assert any('applied_transform undone' in note
               for note in data.capture_info['notes'])


def test_each_frame_may_name_its_own_environment_map(capture, tmp_path):
    """hdri_path (the NeRD datasets): the maps in order of first use, the
    map of each view, --envmap lighting them all, and mistakes named."""
    import shutil
    from tg_intrinsic.io.hdr import read_envmap, write_hdr
    written = write_capture(tmp_path / 'c', capture, 'nerfstudio')
    folder = written['capture']
    path = os.path.join(folder, 'transforms.json')
    spec = json.loads(open(path).read())
    envmap = [name for name in os.listdir(folder)
              if name.startswith('envmap')][0]
    sky = np.asarray(read_envmap(os.path.join(folder, envmap)))
    write_hdr(os.path.join(folder, 'dusk.hdr'), 0.5 * sky[:, ::-1])
    names = ['dusk.hdr', envmap, 'dusk.hdr', envmap, envmap]
    for frame, name in zip(spec['frames'], names):
        frame['hdri_path'] = name
    open(path, 'w').write(json.dumps(spec))
    data = read_capture(folder, dtype=torch.float64)
    assert 'envmap' not in data and data.envmaps.shape[0] == 2
    assert data.view_lighting.tolist() == [0, 1, 0, 1, 1]
    assert torch.allclose(data.envmaps[1], torch.as_tensor(sky).double())
    # dusk.hdr: RGBE, 8-bit mantissas shared by a pixel's channels
    assert torch.allclose(data.envmaps[0], 0.5 * torch.as_tensor(
        sky[:, ::-1].copy()).double(), rtol=0.02, atol=0.005)
    assert len(data.capture_info['lightings']) == 2
    one = read_capture(folder, envmap=os.path.join(folder, envmap))
    assert 'envmaps' not in one and '--envmap lights every' in \
        one.capture_info['notes'][-1]
    # a frame without a map, a missing map, maps of two sizes
    del spec['frames'][3]['hdri_path']
    open(path, 'w').write(json.dumps(spec))
    with pytest.raises(ValueError, match='but not for 1'):
        read_capture(folder)
    spec['frames'][3]['hdri_path'] = 'nowhere.hdr'
    open(path, 'w').write(json.dumps(spec))
    with pytest.raises(ValueError, match="frame 3 names the environment map"
                                         " 'nowhere.hdr'"):
        read_capture(folder)
    write_hdr(os.path.join(folder, 'small.hdr'), sky[::2, ::2])
    spec['frames'][3]['hdri_path'] = 'small.hdr'
    open(path, 'w').write(json.dumps(spec))
    with pytest.raises(ValueError, match='resample them to one size'):
        read_capture(folder)
    shutil.rmtree(folder)
