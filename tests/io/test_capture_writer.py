"""write_capture: one capture in every format, each read back as the
native scene folder reads (the readers against the native format), and
8-bit photographs within their quantisation."""
import numpy as np
import pytest
import torch

from tg_intrinsic.io.capture import detect_format, read_capture
from tg_intrinsic.io.capture_writer import write_capture

FORMATS = ['colmap', 'colmap-bin', 'nerf', 'nerfstudio', 'orb']

READ_AS = {'colmap-bin': 'colmap'}


def same_capture(data, native, images_atol=0.0):
    assert torch.allclose(data.pos, native.pos, atol=1e-6)
    assert torch.equal(data.face, native.face)
    assert torch.allclose(data.normal, native.normal, atol=1e-6)
    assert torch.allclose(data.intrinsics, native.intrinsics, rtol=1e-12,
                          atol=1e-9)
    # float32 rotations re-orthonormalised by a quaternion (COLMAP)
    assert torch.allclose(data.extrinsics, native.extrinsics, atol=1e-6)
    assert torch.equal(data.envmap, native.envmap)
    # read_capture's photographs are a PhotographStack: [:] reads them all
    images = data.images[:]
    both = ~torch.isnan(native.images)
    assert torch.equal(torch.isnan(images), ~both)
    assert (images[both] - native.images[both]).abs().max() <= \
        images_atol

@pytest.mark.parametrize('form', FORMATS)
def test_every_format_reads_as_the_native_folder(capture, native, tmp_path,
                                                 form):
    written = write_capture(tmp_path / 'c', capture, form)
    assert detect_format(written['capture']) == READ_AS.get(form, form)
    data = read_capture(written['capture'], dtype=torch.float64)
    same_capture(data, native)
    assert data.capture_info['format'] == READ_AS.get(form, form)
    # the photographs stay on disk, and the capture pickles (torch.save)
    import pickle
    again = pickle.loads(pickle.dumps(data))
    assert torch.equal(again.images[-1], data.images[-1])

@pytest.mark.parametrize('form', ['colmap', 'nerfstudio', 'orb'])
def test_ldr_photographs_within_the_quantisation(capture, native, tmp_path,
                                                 form):
    from tg_intrinsic.io.gltf import srgb_encode
    written = write_capture(tmp_path / 'c', capture, form, ldr=True)
    exposure = written['exposure']
    with pytest.raises(ValueError, match='needs --exposure S'):
        read_capture(written['capture'])
    data = read_capture(written['capture'], dtype=torch.float64,
                        exposure=exposure)
    assert data.capture_info['ldr'] and \
        data.capture_info['exposure'] == exposure
    images = data.images[:]
    kept = ~torch.isnan(images)
    # clipped pixels (and their neighbours) are left out, nothing else
    assert kept.float().mean() > 0.9
    ours = srgb_encode(np.clip(images[kept].numpy() * exposure, 0, 1))
    truth = srgb_encode(np.clip(native.images[kept].numpy() * exposure, 0,
                                1))
    assert np.abs(ours - truth).max() <= 0.5 / 255 + 1e-6
    assert data.capture_info['pixels_left_out']['clipped'] == \
        int((~kept).any(-1).sum())


def test_write_capture_refuses_what_it_cannot_write(capture, tmp_path):
    with pytest.raises(ValueError, match="'format' must be one of"):
        write_capture(tmp_path, capture, 'blender')
    with pytest.raises(ValueError, match='linear HDR photographs'):
        write_capture(tmp_path, capture, 'native', ldr=True)
