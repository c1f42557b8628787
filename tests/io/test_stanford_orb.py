"""The Stanford-ORB layout: the scene named two ways, its mesh, first
environment map and masks found where the dataset keeps them."""
import os

import numpy as np
import pytest
import torch

from tg_intrinsic.io.capture_writer import write_capture
from tg_intrinsic.io.stanford_orb import (find_orb_scene, orb_spec,
                                          read_stanford_orb)


def test_the_layout_is_found(capture, native, tmp_path):
    from PIL import Image
    write_capture(tmp_path, capture, 'orb')
    scene = tmp_path / 'blender_HDR' / 'example_scene001'
    assert find_orb_scene(scene) == (str(tmp_path), 'blender_HDR',
                                     'example_scene001')
    assert find_orb_scene(tmp_path / 'example_scene001') == \
        find_orb_scene(scene)
    assert find_orb_scene(tmp_path / 'no_scene') is None
    spec = orb_spec(tmp_path / 'example_scene001')
    assert spec.geometry.endswith(os.path.join('mesh_blender', 'mesh.obj'))
    assert spec.envmap.endswith(os.path.join('env_map', '0000.exr'))
    assert all(v.mask.endswith(f'{i:04d}.png') for i, v in
               enumerate(spec.views))
    # a second environment map: the first (sorted) lights the capture
    truth = tmp_path / 'ground_truth' / 'example_scene001' / 'env_map'
    os.link(truth / '0000.exr', truth / '0001.exr')
    assert 'lit by env_map/0000.exr (first of 2)' in orb_spec(scene).notes
    # a mask that leaves half of the first photograph out
    height, width = capture.images.shape[1:3]
    mask = np.full((height, width), 255, np.uint8)
    mask[: height // 2] = 0
    Image.fromarray(mask).save(scene / 'train_mask' / '0000.png')
    data = read_stanford_orb(scene, dtype=torch.float64)
    assert bool(torch.isnan(data.images[0, : height // 2]).all())
    assert torch.equal(data.images[1:], native.images[1:])
    with pytest.raises(ValueError, match='not a Stanford-ORB scene'):
        orb_spec(tmp_path)
    with pytest.raises(ValueError, match="'split' must be one of"):
        orb_spec(scene, split='novel')
