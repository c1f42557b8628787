"""The files every capture shares: the one file of a kind in a folder,
environment maps that are no latitude-longitude map, photographs that are
not HDR."""
import numpy as np
import pytest

from tg_intrinsic.io.capture_files import (find_single_file,
                                           read_envmap_file,
                                           read_hdr_photograph,
                                           why_not_a_file)
from tg_intrinsic.io.hdr import write_hdr


def test_find_single_file_says_how_to_name_one(tmp_path):
    how = 'with --geometry MESH'
    with pytest.raises(ValueError, match='holds no geometry file .*; add '
                       'one, or name it with --geometry MESH'):
        find_single_file(str(tmp_path), ('.obj', '.ply'), set(), 'geometry',
                         how)
    (tmp_path / 'a.obj').write_text('v 0 0 0\n')
    assert find_single_file(str(tmp_path), ('.obj', ), set(), 'geometry',
                            how) == 'a.obj'
    (tmp_path / 'b.ply').write_text('ply\n')
    with pytest.raises(ValueError, match="several geometry files: 'a.obj', "
                       "'b.ply'; name the one to use with --geometry"):
        find_single_file(str(tmp_path), ('.obj', '.ply'), set(), 'geometry',
                         how)
    assert find_single_file(str(tmp_path), ('.obj', '.ply'),
                            {str(tmp_path / 'b.ply')}, 'geometry',
                            how) == 'a.obj'


def test_envmaps_must_be_latitude_longitude_maps(tmp_path):
    path = str(tmp_path / 'sky.hdr')
    write_hdr(path, np.ones((8, 12, 3), np.float32))
    with pytest.raises(ValueError, match=r"sky.hdr' is 8 x 12 pixels; an "
                       r"equirectangular .* twice as wide"):
        read_envmap_file(path, 'given with --envmap')
    write_hdr(path, np.zeros((8, 16, 3), np.float32))
    with pytest.raises(ValueError, match='is black'):
        read_envmap_file(path, 'given with --envmap')
    with pytest.raises(ValueError, match="'.*none.exr' given with --envmap "
                       "does not exist"):
        read_envmap_file(str(tmp_path / 'none.exr'), 'given with --envmap')


def test_hdr_photographs_only(tmp_path):
    (tmp_path / 'p.png').write_bytes(b'not really')
    with pytest.raises(ValueError, match=r'not a linear HDR image \(8-bit '
                       r'.png photographs are not HDR\)'):
        read_hdr_photograph(str(tmp_path / 'p.png'))
    assert why_not_a_file(str(tmp_path)) == 'is a folder, not a file'
