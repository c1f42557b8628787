"""read_capture and detect_format: every format recognised from its
folder, forced with ``format``, and what is not a capture said in words."""
import os

import pytest
import torch

from tg_intrinsic.io.capture import CAPTURE_FORMATS, detect_format, \
    read_capture
from tg_intrinsic.io.capture_writer import write_capture


@pytest.mark.parametrize('form,detected', [
    ('native', 'native'), ('colmap', 'colmap'), ('colmap-bin', 'colmap'),
    ('nerf', 'nerf'), ('nerfstudio', 'nerfstudio'), ('orb', 'orb')])
def test_every_format_is_recognised(capture, tmp_path, form, detected):
    written = write_capture(tmp_path / 'c', capture, form)
    assert detected in CAPTURE_FORMATS
    assert detect_format(written['capture']) == detected
    data = read_capture(written['capture'], format=detected)
    assert data.capture_info['format'] == detected
    if form == 'orb':  # ROOT/<scene> names the scene too
        root = tmp_path / 'c' / 'example_scene001'
        assert detect_format(root) == 'orb'
    if form in ('nerf', 'nerfstudio'):  # the file itself
        path = os.path.join(written['capture'], 'transforms.json')
        assert detect_format(path) == detected


def test_a_forced_format_reads_the_other_convention(capture, tmp_path):
    """The cameras of a NeRF file read as nerfstudio's need fl_x: said."""
    written = write_capture(tmp_path / 'c', capture, 'nerf')
    with pytest.raises(ValueError, match='has no fl_x, fl_y, cx, cy'):
        read_capture(written['capture'], format='nerfstudio')
    with pytest.raises(ValueError, match="'format' must be one of"):
        read_capture(written['capture'], format='blender')


def test_not_a_capture(capture, tmp_path):
    with pytest.raises(ValueError, match='no capture this library reads'):
        detect_format(tmp_path)
    with pytest.raises(ValueError, match='does not exist'):
        detect_format(tmp_path / 'nothing')
    (tmp_path / 'mesh.obj').write_text('v 0 0 0\n')
    with pytest.raises(ValueError, match='is a file; a capture is a folder'):
        detect_format(tmp_path / 'mesh.obj')


def test_the_native_folder_keeps_its_options_in_cameras_json(capture,
                                                            tmp_path):
    written = write_capture(tmp_path / 'c', capture, 'native')
    data = read_capture(written['capture'], dtype=torch.float64)
    assert data.capture_info['format'] == 'native'
    with pytest.raises(ValueError, match='exposure, up do not apply; edit '
                       'cameras.json'):
        read_capture(written['capture'], exposure=2.0, up='y')
