import os
import sys
from pathlib import Path

import numpy as np
import pytest
import torch

from tg_intrinsic.geometry.appearance.envmap import sun_sky_envmap
from tg_intrinsic.io import (looks_clipped, read_envmap, read_exr, read_hdr,
                             write_hdr)

ENVMAPS = Path(__file__).resolve().parents[2].parent / 'shared' / 'data' \
    / 'envmaps'
REAL_FILES = sorted(ENVMAPS.glob('*.hdr')) if ENVMAPS.is_dir() else []


def header(resolution=b'-Y 2 +X 3', extra=b''):
    return (b'#?RADIANCE\n# hand made\n' + extra
            + b'FORMAT=32-bit_rle_rgbe\n\n' + resolution + b'\n')


def save(tmp_path, data, name='x.hdr'):
    path = tmp_path / name
    path.write_bytes(data)
    return path


def hdr_image(seed=0, shape=(9, 37)):
    rng = np.random.default_rng(seed)
    # five decades of radiance with colour, some exact zeros
    image = np.exp(rng.normal(0, 2.5, shape + (3, ))).astype(np.float32)
    image[0, :3] = 0
    return image


# ------------------------------------------------------- hand-built streams
def test_flat_stream_decodes_to_hand_computed_values(tmp_path):
    # width 3 < 8: flat pixels only; value = mantissa * 2^(e - 136)
    pixels = [[128, 64, 0, 129], [200, 100, 50, 136], [0, 0, 0, 0],
              [255, 1, 128, 140], [128, 128, 128, 128], [16, 32, 64, 137]]
    data = header() + bytes(sum(pixels, []))
    image = read_hdr(save(tmp_path, data))
    expected = np.array([[[1.0, 0.5, 0.0], [200, 100, 50], [0, 0, 0]],
                         [[4080, 16, 2048], [0.5, 0.5, 0.5], [32, 64, 128]]],
                        np.float32)
    assert image.dtype == np.float32 and image.shape == (2, 3, 3)
    np.testing.assert_array_equal(image, expected)


def test_old_style_run_repeats_previous_pixel(tmp_path):
    # (1, 1, 1, n) repeats the previous pixel n times
    data = header(b'-Y 1 +X 4') + bytes([64, 32, 16, 137, 1, 1, 1, 2,
                                         128, 0, 0, 136])
    image = read_hdr(save(tmp_path, data))
    np.testing.assert_array_equal(image[0], [[128, 64, 32]] * 3
                                  + [[128, 0, 0]])


def test_rle_stream_decodes_to_hand_computed_values(tmp_path):
    width = 10
    line = bytes([2, 2, 0, width])
    line += bytes([128 + 10, 128])                       # R: run of 10
    line += bytes([10] + [16 * i for i in range(10)])    # G: 10 literals
    line += bytes([128 + 6, 64, 4, 1, 2, 3, 255])        # B: run 6, 4 lit.
    line += bytes([128 + 10, 130])                       # E: run of 10
    image = read_hdr(save(tmp_path, header(b'-Y 1 +X 10') + line))
    scale = 2.0 ** (130 - 136)
    np.testing.assert_array_equal(image[0, :, 0], 128 * scale)
    np.testing.assert_array_equal(image[0, :, 1], 16 * np.arange(10) * scale)
    np.testing.assert_array_equal(image[0, :, 2],
                                  np.array([64] * 6 + [1, 2, 3, 255]) * scale)


def test_orientation_and_exposure(tmp_path):
    pixels = bytes([128, 0, 0, 129, 0, 128, 0, 129,
                    0, 0, 128, 129, 128, 128, 128, 129])
    standard = read_hdr(save(tmp_path, header(b'-Y 2 +X 2') + pixels))
    # +Y: the first scanline is the bottom row
    flipped = read_hdr(save(tmp_path, header(b'+Y 2 +X 2') + pixels, 'f.hdr'))
    np.testing.assert_array_equal(flipped, standard[::-1])
    # +X major: scanlines are columns, left to right, each top to bottom
    columns = read_hdr(save(tmp_path, header(b'+X 2 -Y 2') + pixels,
                            'c.hdr'))
    np.testing.assert_array_equal(columns, standard.transpose(1, 0, 2))
    # EXPOSURE multiplied the stored values: divide by their product
    exposed = read_hdr(save(tmp_path, header(b'-Y 2 +X 2',
                                             b'EXPOSURE=2\nEXPOSURE= 4\n')
                            + pixels, 'e.hdr'))
    np.testing.assert_allclose(exposed, standard / 8)


# ----------------------------------------------------------------- errors
def test_bad_files_raise_clear_errors(tmp_path):
    pixels = bytes(24)
    with pytest.raises(FileNotFoundError):
        read_hdr(tmp_path / 'missing.hdr')
    with pytest.raises(ValueError, match='not a Radiance RGBE'):
        read_hdr(save(tmp_path, b'P6\n2 3\n255\n' + pixels))
    xyze = header().replace(b'rgbe', b'xyze') + pixels
    with pytest.raises(ValueError, match='XYZ.*unsupported'):
        read_hdr(save(tmp_path, xyze))
    with pytest.raises(ValueError, match='truncated'):
        read_hdr(save(tmp_path, header() + pixels[:-5]))
    with pytest.raises(ValueError, match='no blank line'):
        read_hdr(save(tmp_path, b'#?RADIANCE\nFORMAT=32-bit_rle_rgbe\n'))
    with pytest.raises(ValueError, match='resolution line'):
        read_hdr(save(tmp_path, header(b'-Y 2 +Z 3') + pixels))
    with pytest.raises(ValueError, match='resolution line'):
        read_hdr(save(tmp_path, header(b'-Y 2 -Y 3') + pixels))
    # an RLE run that overruns its scanline
    bad_run = bytes([2, 2, 0, 8, 128 + 9, 1]) + bytes(40)
    with pytest.raises(ValueError, match='corrupt'):
        read_hdr(save(tmp_path, header(b'-Y 1 +X 8') + bad_run))
    bad_width = bytes([2, 2, 0, 9]) + bytes(40)
    with pytest.raises(ValueError, match='width'):
        read_hdr(save(tmp_path, header(b'-Y 1 +X 8') + bad_width))


def test_truncated_rle_file(tmp_path):
    path = tmp_path / 'a.hdr'
    write_hdr(path, hdr_image(shape=(16, 40)))
    data = path.read_bytes()
    with pytest.raises(ValueError, match='truncated.*scanline'):
        read_hdr(save(tmp_path, data[:len(data) * 2 // 3], 'cut.hdr'))


def test_write_rejects_bad_images(tmp_path):
    path = tmp_path / 'x.hdr'
    with pytest.raises(ValueError, match=r'\[H, W, 3\]'):
        write_hdr(path, np.ones((4, 8)))
    with pytest.raises(ValueError, match=r'\[H, W, 3\]'):
        write_hdr(path, np.ones((4, 8, 4)))
    with pytest.raises(ValueError, match='negative'):
        write_hdr(path, -np.ones((4, 8, 3)))
    with pytest.raises(ValueError, match='NaN'):
        write_hdr(path, np.full((4, 8, 3), np.nan))
    with pytest.raises(ValueError, match='floating'):
        write_hdr(path, np.ones((4, 8, 3), np.uint8))
    assert not path.exists()


# ------------------------------------------------------------- round trip
@pytest.mark.parametrize('shape', [(9, 37), (3, 5), (1, 300)])
def test_round_trip_to_rgbe_precision(tmp_path, shape):
    image = hdr_image(1, shape)
    path = tmp_path / 'x.hdr'
    write_hdr(path, torch.from_numpy(image))  # tensors are accepted too
    back = read_hdr(path)
    assert back.shape == image.shape and back.dtype == np.float32
    # each channel within half a mantissa step of the pixel's largest
    bound = image.max(-1, keepdims=True) / 256
    assert (np.abs(back - image) <= bound * (1 + 1e-6)).all()
    assert (back[image == 0] == 0).all()
    # RGBE values are written back exactly
    write_hdr(path, back)
    np.testing.assert_array_equal(read_hdr(path), back)
    assert [p.name for p in tmp_path.iterdir()] == ['x.hdr']  # no temp file


def test_runs_and_literals_across_chunk_limits(tmp_path):
    # runs longer than 127 and literal stretches longer than 128
    rng = np.random.default_rng(2)
    row = np.concatenate([np.full(300, 3.0), rng.uniform(1, 2, 200),
                          np.full(5, 7.0), rng.uniform(1, 2, 3),
                          np.full(4, 0.25)])
    image = np.stack([row, row[::-1], np.roll(row, 50)], -1)[None]
    image = np.repeat(image, 3, 0).astype(np.float32)
    path = tmp_path / 'x.hdr'
    write_hdr(path, image)
    first = read_hdr(path)
    write_hdr(path, first)
    np.testing.assert_array_equal(read_hdr(path), first)
    constant = tmp_path / 'c.hdr'
    write_hdr(constant, np.ones((64, 256, 3), np.float32))
    assert constant.stat().st_size < 64 * 256  # run-length encoded
    np.testing.assert_array_equal(read_hdr(constant), 1.0)


def test_write_into_missing_folder_leaves_nothing(tmp_path):
    # the error names the missing folder and what to do, not the
    # temporary file write_hdr would have written first
    with pytest.raises(FileNotFoundError, match=r"cannot write '.*x\.hdr': "
                       r"the folder '.*no' does not exist; create it first"
                       ) as info:
        write_hdr(tmp_path / 'no' / 'x.hdr', hdr_image())
    assert '.tmp' not in str(info.value)
    assert list(tmp_path.iterdir()) == []
    (tmp_path / 'file').write_text('')
    with pytest.raises(FileNotFoundError, match=r"folder '.*file' is not a "
                       r"folder"):
        write_hdr(tmp_path / 'file' / 'x.hdr', hdr_image())


def test_written_files_get_the_usual_permissions(tmp_path):
    # written through a temporary file, which must not stay private
    path = tmp_path / 'x.hdr'
    write_hdr(path, hdr_image())
    umask = os.umask(0)
    os.umask(umask)
    assert path.stat().st_mode & 0o777 == 0o666 & ~umask


def test_header_larger_than_the_data_is_rejected_before_allocating(
        tmp_path):
    # 1e8 x 1e8 pixels would be 35 PiB to decode (a MemoryError before):
    # no encoding fits them in 24 bytes
    path = save(tmp_path, header(b'-Y 100000000 +X 100000000') + bytes(24))
    with pytest.raises(ValueError, match=r"header says 100000000 x 100000000 "
                       r"pixels but the file has 24 bytes of pixel data, "
                       r"fewer than the 2000000000 any encoding needs"):
        read_hdr(path)
    # also a plausible header over too short a flat stream
    path = save(tmp_path, header(b'-Y 20 +X 3') + bytes(24), 'short.hdr')
    with pytest.raises(ValueError, match=r"20 x 3 pixels but the file has 24 "
                       r"bytes"):
        read_hdr(path)


def test_shortest_old_style_runs_pass_the_size_check(tmp_path):
    # the bound is the most compact encoding: per scanline one pixel and
    # old-style run markers whose counts are the bytes of one number
    # (69999 = 0x01116f: three markers)
    line = bytes([64, 32, 16, 137, 1, 1, 1, 0x6f, 1, 1, 1, 0x11,
                  1, 1, 1, 0x01])
    image = read_hdr(save(tmp_path, header(b'-Y 2 +X 70000') + 2 * line))
    assert image.shape == (2, 70000, 3)
    np.testing.assert_array_equal(image, np.broadcast_to([128, 64, 32],
                                                         image.shape))
    with pytest.raises(ValueError, match='fewer than the 32 any encoding'):
        read_hdr(save(tmp_path, header(b'-Y 2 +X 70000') + 2 * line[:-1],
                      'cut.hdr'))


# ---------------------------------------------------------------- oracles
def test_opencv_reads_what_we_write(tmp_path):
    cv2 = pytest.importorskip('cv2')
    image = hdr_image(3, (12, 40))
    path = tmp_path / 'x.hdr'
    write_hdr(path, image)
    theirs = cv2.imread(str(path), cv2.IMREAD_UNCHANGED)[..., ::-1]
    np.testing.assert_array_equal(theirs, read_hdr(path))


@pytest.mark.skipif(not REAL_FILES, reason='no real environment maps at '
                    f'{ENVMAPS}')
@pytest.mark.parametrize('path', REAL_FILES, ids=lambda p: p.name)
def test_real_files_against_opencv(path):
    cv2 = pytest.importorskip('cv2')
    ours = read_hdr(path)
    theirs = cv2.imread(str(path), cv2.IMREAD_UNCHANGED)[..., ::-1]
    assert ours.shape == theirs.shape
    np.testing.assert_array_equal(ours, theirs)


@pytest.mark.skipif(not REAL_FILES, reason='no real environment maps')
def test_real_files_are_hdr():
    for path in REAL_FILES:
        with_warnings = read_envmap(path)
        assert with_warnings.dtype == torch.float32
        assert not looks_clipped(with_warnings)


# ----------------------------------------------------------- read_envmap
def test_read_envmap_dispatches_and_validates(tmp_path):
    sky = sun_sky_envmap(32, 64)
    write_hdr(tmp_path / 'sky.hdr', sky)
    from_hdr = read_envmap(tmp_path / 'sky.hdr')
    assert from_hdr.dtype == torch.float32 and from_hdr.shape == (32, 64, 3)
    assert bool(((from_hdr - sky).abs() <= sky.amax(-1, keepdim=True) / 256
                 ).all())
    np.save(tmp_path / 'sky.npy', sky.double().numpy())
    assert torch.equal(read_envmap(str(tmp_path / 'sky.npy')), sky)

    with pytest.raises(ValueError, match='extension'):
        read_envmap(tmp_path / 'sky.png')
    np.save(tmp_path / 'int.npy', np.ones((4, 8, 3), np.int64))
    with pytest.raises(ValueError, match='floating'):
        read_envmap(tmp_path / 'int.npy')
    np.save(tmp_path / 'rgba.npy', np.ones((4, 8, 4)))
    with pytest.raises(ValueError, match=r'\[H, W, 3\]'):
        read_envmap(tmp_path / 'rgba.npy')
    np.save(tmp_path / 'nan.npy', np.full((4, 8, 3), np.nan))
    with pytest.raises(ValueError, match='NaN'):
        read_envmap(tmp_path / 'nan.npy')


def test_read_envmap_warns_on_ldr(tmp_path):
    rng = np.random.default_rng(7)
    np.save(tmp_path / 'ldr.npy', rng.integers(0, 256, (16, 32, 3)) / 255.0)
    with pytest.warns(UserWarning, match='low-dynamic-range'):
        read_envmap(tmp_path / 'ldr.npy')


def test_read_exr_without_openexr(tmp_path, monkeypatch):
    monkeypatch.setitem(sys.modules, 'OpenEXR', None)
    with pytest.raises(ImportError, match='pip install OpenEXR'):
        read_exr(tmp_path / 'x.exr')


def test_read_exr(tmp_path):
    OpenEXR = pytest.importorskip('OpenEXR')
    if not hasattr(OpenEXR, 'File'):
        pytest.skip('OpenEXR before 3.3')
    image = hdr_image(8, (8, 16))
    header = {'compression': OpenEXR.ZIP_COMPRESSION,
              'type': OpenEXR.scanlineimage}
    path = str(tmp_path / 'x.exr')
    with OpenEXR.File(header, {'RGB': image}) as f:
        f.write(path)
    np.testing.assert_array_equal(read_exr(path), image)
    envmap = read_envmap(path)
    assert torch.equal(envmap, torch.from_numpy(image))
    with pytest.raises(FileNotFoundError):
        read_exr(tmp_path / 'missing.exr')
    os.remove(path)
