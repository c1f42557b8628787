import math
from fractions import Fraction

import numpy as np
import pytest
from PIL import Image, TiffImagePlugin

from tg_intrinsic.io.photographs import (LDR_EXTENSIONS, LDRPhoto,
                                         exif_exposure, read_ldr, read_mask,
                                         srgb_to_linear)


def srgb_curve(c):
    # IEC 61966-2-1, written out independently of the library
    return c / 12.92 if c <= 0.04045 else ((c + 0.055) / 1.055) ** 2.4


def codes_image(shape=(16, 16), seed=0):
    """Every 8-bit code once per channel, in different orders (repeated
    to fill ``shape``)."""
    rng = np.random.default_rng(seed)
    codes = np.stack([rng.permutation(256) for _ in range(3)], -1)
    count = shape[0] * shape[1]
    codes = np.tile(codes, (-(-count // 256), 1))[:count]
    return codes.reshape(shape + (3, )).astype(np.uint8)


def save(tmp_path, array, name, **kwargs):
    path = tmp_path / name
    Image.fromarray(array).save(path, **kwargs)
    return path


def exif_with(tags):
    exif = Image.Exif()
    exif[0x8769] = dict(tags)  # the Exif sub-IFD
    return exif


EXPOSURE = {0x829A: TiffImagePlugin.IFDRational(1, 100),  # ExposureTime
            0x8827: 200,  # ISOSpeedRatings
            0x829D: TiffImagePlugin.IFDRational(4, 1)}  # FNumber


# ------------------------------------------------------------ srgb curve
@pytest.mark.parametrize('c', [0.0, 0.04, 0.04045, 0.041, 0.2, 0.5, 0.9,
                               1.0])
def test_srgb_to_linear_matches_the_curve(c):
    for dtype, rtol in ((np.float64, 1e-14), (np.float32, 1e-6)):
        out = srgb_to_linear(np.array([c], dtype))
        assert out.dtype == dtype
        assert out[0] == pytest.approx(srgb_curve(c), rel=rtol, abs=1e-12)


def test_srgb_to_linear_known_values():
    out = srgb_to_linear(np.array([0.0, 0.5, 1.0], np.float32))
    np.testing.assert_allclose(out, [0.0, 0.21404114, 1.0], rtol=1e-6)
    assert srgb_to_linear(np.float64(0.04045)) == pytest.approx(
        0.04045 / 12.92, rel=1e-15)
    assert srgb_to_linear(np.zeros((2, 3, 4))).shape == (2, 3, 4)


def test_srgb_to_linear_is_monotone_and_continuous_at_the_knee():
    c = np.linspace(0, 1, 100001)
    assert (np.diff(srgb_to_linear(c)) > 0).all()
    knee = 0.04045
    left = srgb_to_linear(np.array([knee]))[0]
    right = ((knee + 1e-12 + 0.055) / 1.055) ** 2.4
    assert abs(left - right) < 1e-8


# ------------------------------------------------------------ read_ldr
def test_8bit_png_round_trips(tmp_path):
    codes = codes_image()
    photo = read_ldr(save(tmp_path, codes, 'x.png'))
    assert isinstance(photo, LDRPhoto)
    assert photo.radiance.dtype == np.float32
    assert photo.radiance.shape == (16, 16, 3)
    expected = srgb_to_linear(codes / 255.0)
    np.testing.assert_allclose(photo.radiance, expected, rtol=1e-6,
                               atol=1e-9)
    assert photo.alpha is None
    assert photo.clipped.shape == (16, 16) and photo.clipped.dtype == bool


def test_jpeg_round_trips_within_compression_error(tmp_path):
    y, x = np.mgrid[0:32, 0:48]
    codes = np.stack([4 * x + 20, 5 * y + 30, 2 * (x + y) + 40],
                     -1).astype(np.uint8)
    path = save(tmp_path, codes, 'x.jpg', quality=100, subsampling=0)
    photo = read_ldr(path)
    # exactly the curve on the codes the JPEG decodes to ...
    decoded = np.asarray(Image.open(path))
    np.testing.assert_allclose(photo.radiance,
                               srgb_to_linear(decoded / 255.0), rtol=1e-6)
    # ... which are the written codes up to compression error
    assert np.abs(decoded.astype(int) - codes).max() <= 4
    np.testing.assert_allclose(photo.radiance,
                               srgb_to_linear(codes / 255.0), atol=0.02)
    assert not photo.clipped.any()


def test_gamma_power_law(tmp_path):
    codes = codes_image()
    photo = read_ldr(save(tmp_path, codes, 'x.png'), gamma=2.2)
    np.testing.assert_allclose(photo.radiance, (codes / 255.0) ** 2.2,
                               rtol=1e-6, atol=1e-12)
    linear = read_ldr(tmp_path / 'x.png', gamma=1)
    np.testing.assert_allclose(linear.radiance, codes / 255.0, rtol=1e-6)


@pytest.mark.parametrize('gamma', [0, -1.0, float('nan'), float('inf'),
                                   True, '2.2'])
def test_bad_gamma(tmp_path, gamma):
    path = save(tmp_path, codes_image(), 'x.png')
    with pytest.raises(ValueError, match='gamma'):
        read_ldr(path, gamma=gamma)


@pytest.mark.parametrize('name', ['x.png', 'x.tif'])
def test_16bit_grayscale_keeps_16_bits(tmp_path, name):
    codes = np.array([[0, 1000, 1001], [40000, 65534, 65535]], np.uint16)
    path = save(tmp_path, codes, name)
    photo = read_ldr(path)
    expected = srgb_to_linear(codes / 65535.0)
    np.testing.assert_allclose(photo.radiance[..., 0], expected, rtol=1e-6)
    assert (photo.radiance == photo.radiance[..., :1]).all()
    # neighbouring 16-bit codes stay apart (8 bits would merge them)
    assert photo.radiance[0, 2, 0] > photo.radiance[0, 1, 0]
    # only 65535 (at row 1, column 2) is clipped, with its neighbours
    np.testing.assert_array_equal(photo.clipped, [[False, True, True],
                                                  [False, True, True]])
    assert not read_ldr(save(tmp_path, codes[:, :2] // 2,
                             'half' + name[1:])).clipped.any()


def test_16bit_grayscale_written_by_opencv(tmp_path):
    cv2 = pytest.importorskip('cv2')
    codes = np.arange(0, 65536, 4099, dtype=np.uint16).reshape(2, 8)
    assert cv2.imwrite(str(tmp_path / 'g.png'), codes)
    photo = read_ldr(tmp_path / 'g.png')
    np.testing.assert_allclose(photo.radiance[..., 1],
                               srgb_to_linear(codes / 65535.0), rtol=1e-6)


def test_16bit_colour_is_refused_not_reduced(tmp_path):
    cv2 = pytest.importorskip('cv2')
    codes = np.full((4, 5, 3), 3007, np.uint16)
    assert cv2.imwrite(str(tmp_path / 'c.png'), codes)
    with pytest.raises(ValueError, match=r"c\.png.*16-bit colour"):
        read_ldr(tmp_path / 'c.png')
    # a mask only needs its top bit, which survives the reduction
    codes[0, 0] = 60000
    assert cv2.imwrite(str(tmp_path / 'c.png'), codes)
    assert read_mask(tmp_path / 'c.png').sum() == 1


def test_clipped_marks_the_pixel_and_its_neighbours_only(tmp_path):
    codes = np.full((7, 9, 3), 100, np.uint8)
    codes[3, 4, 1] = 255
    codes[0, 8, 2] = 255  # a corner: its neighbours inside the image
    clipped = read_ldr(save(tmp_path, codes, 'x.png')).clipped
    expected = np.zeros((7, 9), bool)
    expected[2:5, 3:6] = True
    expected[0:2, 7:9] = True
    np.testing.assert_array_equal(clipped, expected)


def test_254_is_not_clipped(tmp_path):
    codes = np.full((3, 3, 3), 254, np.uint8)
    assert not read_ldr(save(tmp_path, codes, 'x.png')).clipped.any()


def test_alpha_from_rgba_and_la(tmp_path):
    rgba = np.zeros((1, 4, 4), np.uint8)
    rgba[..., :3] = 200
    rgba[0, :, 3] = [0, 127, 128, 255]
    photo = read_ldr(save(tmp_path, rgba, 'x.png'))
    np.testing.assert_array_equal(photo.alpha, [[False, False, True, True]])
    np.testing.assert_allclose(photo.radiance, srgb_curve(200 / 255),
                               rtol=1e-6)
    assert photo.radiance.shape == (1, 4, 3)
    la = Image.fromarray(rgba[..., [0, 3]], 'LA')
    la.save(tmp_path / 'la.png')
    photo = read_ldr(tmp_path / 'la.png')
    np.testing.assert_array_equal(photo.alpha, [[False, False, True, True]])
    assert photo.radiance.shape == (1, 4, 3)


def test_grayscale_and_palette_become_rgb(tmp_path):
    gray = np.arange(256, dtype=np.uint8).reshape(16, 16)
    photo = read_ldr(save(tmp_path, gray, 'g.png'))
    np.testing.assert_allclose(photo.radiance,
                               np.repeat(srgb_to_linear(gray / 255.0)
                                         [..., None], 3, -1), rtol=1e-6)
    palette = Image.fromarray(codes_image()).quantize(16)
    assert palette.mode == 'P'
    palette.save(tmp_path / 'p.png')
    photo = read_ldr(tmp_path / 'p.png')
    expected = np.asarray(palette.convert('RGB')) / 255.0
    np.testing.assert_allclose(photo.radiance, srgb_to_linear(expected),
                               rtol=1e-6)
    assert photo.alpha is None


@pytest.mark.parametrize('extension', LDR_EXTENSIONS)
def test_every_extension_reads(tmp_path, extension):
    codes = codes_image()
    path = save(tmp_path, codes, 'x' + extension)
    photo = read_ldr(path)
    assert photo.radiance.shape == (16, 16, 3)
    if extension in ('.png', '.bmp', '.tif', '.tiff'):  # lossless
        np.testing.assert_allclose(photo.radiance,
                                   srgb_to_linear(codes / 255.0), rtol=1e-6)


def test_exif_orientation_is_ignored(tmp_path):
    exif = Image.Exif()
    exif[0x0112] = 6  # rotate 90 degrees to display
    codes = codes_image((8, 32))
    path = save(tmp_path, codes, 'r.jpg', exif=exif, quality=95)
    assert Image.open(path).getexif()[0x0112] == 6
    assert read_ldr(path).radiance.shape == (8, 32, 3)


def test_not_an_image(tmp_path):
    path = tmp_path / 'notes.png'
    path.write_text('not a photograph')
    with pytest.raises(ValueError, match=r"notes\.png"):
        read_ldr(path)
    with pytest.raises(ValueError, match=r"notes\.png"):
        read_mask(path)
    with pytest.raises(ValueError, match=r"notes\.png"):
        exif_exposure(path)


def test_truncated_png(tmp_path):
    path = save(tmp_path, codes_image((64, 64)), 'x.png')
    data = path.read_bytes()
    path.write_bytes(data[:len(data) // 2])
    with pytest.raises(ValueError, match=r"x\.png.*truncated"):
        read_ldr(path)


@pytest.mark.parametrize('dtype', [np.float32, np.int32])
def test_float_or_32bit_tiff_is_refused(tmp_path, dtype):
    path = save(tmp_path, np.ones((4, 4), dtype), 'hdr.tif')
    with pytest.raises(ValueError, match=r"hdr\.tif' is not an 8- or "
                                         r"16-bit photograph.*\.exr"):
        read_ldr(path)
    with pytest.raises(ValueError, match=r"hdr\.tif' is not an 8- or "
                                         r"16-bit mask"):
        read_mask(path)


def test_missing_file(tmp_path):
    with pytest.raises(FileNotFoundError):
        read_ldr(tmp_path / 'missing.png')
    with pytest.raises(FileNotFoundError):
        read_mask(tmp_path / 'missing.png')


# ------------------------------------------------------------ exif_exposure
def test_exif_rationals_round_trip_through_a_jpeg(tmp_path):
    path = save(tmp_path, codes_image(), 'e.jpg', exif=exif_with(EXPOSURE))
    stored = Image.open(path).getexif().get_ifd(0x8769)
    time, f_number = stored[0x829A], stored[0x829D]
    assert isinstance(time, TiffImagePlugin.IFDRational)
    assert (time.numerator, time.denominator) == (1, 100)
    assert Fraction(f_number.numerator, f_number.denominator) == 4
    assert stored[0x8827] == 200
    assert exif_exposure(path) == pytest.approx(0.01 * 200 / 4 ** 2)
    assert exif_exposure(path) == pytest.approx(0.125)


def test_exif_exposure_of_a_png_and_an_iso_tuple(tmp_path):
    tags = dict(EXPOSURE)
    tags[0x8827] = (200, 400)
    path = save(tmp_path, codes_image(), 'e.png', exif=exif_with(tags))
    assert exif_exposure(path) == pytest.approx(0.125)


def test_exif_exposure_ratio_between_photographs(tmp_path):
    # twice the time, half the ISO, f/5.6 instead of f/4
    tags = {0x829A: TiffImagePlugin.IFDRational(1, 50), 0x8827: 100,
            0x829D: TiffImagePlugin.IFDRational(56, 10)}
    first = save(tmp_path, codes_image(), 'a.jpg', exif=exif_with(EXPOSURE))
    second = save(tmp_path, codes_image(), 'b.jpg', exif=exif_with(tags))
    ratio = exif_exposure(second) / exif_exposure(first)
    assert ratio == pytest.approx((0.02 * 100 / 5.6 ** 2)
                                  / (0.01 * 200 / 4 ** 2), rel=1e-12)


def test_no_exif(tmp_path):
    assert exif_exposure(save(tmp_path, codes_image(), 'x.jpg')) is None
    assert exif_exposure(save(tmp_path, codes_image(), 'x.png')) is None


@pytest.mark.parametrize('missing', sorted(EXPOSURE))
def test_exif_exposure_with_a_tag_missing(tmp_path, missing):
    tags = {k: v for k, v in EXPOSURE.items() if k != missing}
    path = save(tmp_path, codes_image(), 'x.jpg', exif=exif_with(tags))
    assert exif_exposure(path) is None


@pytest.mark.parametrize('tag, value', [
    (0x829A, TiffImagePlugin.IFDRational(0, 1)),
    (0x829D, TiffImagePlugin.IFDRational(4, 0)),
    (0x8827, 0)])
def test_exif_exposure_with_a_non_positive_tag(tmp_path, tag, value):
    tags = dict(EXPOSURE)
    tags[tag] = value
    path = save(tmp_path, codes_image(), 'x.jpg', exif=exif_with(tags))
    assert exif_exposure(path) is None


# ------------------------------------------------------------ read_mask
def disc(shape=(20, 30)):
    y, x = np.mgrid[0:shape[0], 0:shape[1]]
    return (y - 10) ** 2 + (x - 15) ** 2 < 49


def test_mask_from_gray_rgb_and_bilevel(tmp_path):
    inside = disc()
    gray = np.where(inside, 200, 30).astype(np.uint8)
    np.testing.assert_array_equal(
        read_mask(save(tmp_path, gray, 'g.png')), inside)
    np.testing.assert_array_equal(
        read_mask(save(tmp_path, gray, 'g.bmp'), size=(20, 30)), inside)
    rgb = np.zeros((20, 30, 3), np.uint8)
    rgb[inside] = [255, 255, 0]  # mean 170
    rgb[~inside] = [255, 0, 0]  # mean 85
    np.testing.assert_array_equal(
        read_mask(save(tmp_path, rgb, 'c.png')), inside)
    bilevel = Image.fromarray(inside)
    assert bilevel.mode == '1'
    bilevel.save(tmp_path / 'b.png')
    np.testing.assert_array_equal(read_mask(tmp_path / 'b.png'), inside)


def test_mask_threshold_is_half(tmp_path):
    gray = np.array([[127, 128, 0, 255]], np.uint8)
    np.testing.assert_array_equal(read_mask(save(tmp_path, gray, 'g.png')),
                                  [[False, True, False, True]])


def test_mask_from_rgba(tmp_path):
    inside = disc()
    # a cut-out: one colour everywhere, the object in alpha
    rgba = np.zeros((20, 30, 4), np.uint8)
    rgba[..., :3] = [10, 200, 30]
    rgba[..., 3] = np.where(inside, 255, 0)
    np.testing.assert_array_equal(
        read_mask(save(tmp_path, rgba, 'a.png')), inside)
    # colour varies: the colour decides, alpha is ignored
    rgba[..., :3] = np.where(inside, 255, 0)[..., None]
    rgba[..., 3] = 255
    np.testing.assert_array_equal(
        read_mask(save(tmp_path, rgba, 'b.png')), inside)


def test_mask_size_mismatch(tmp_path):
    path = save(tmp_path, np.full((80, 100), 255, np.uint8), 'cup.png')
    with pytest.raises(ValueError) as info:
        read_mask(path, size=(160, 200))
    message = str(info.value)
    assert 'cup.png' in message
    assert '100 x 80' in message and '200 x 160' in message
    assert "masks must have the photograph's size" in message
    assert read_mask(path, size=(80, 100)).all()


@pytest.mark.parametrize('size', [(80, ), (0, 100), (80.0, 100), 'ab'])
def test_mask_bad_size_argument(tmp_path, size):
    path = save(tmp_path, np.full((80, 100), 255, np.uint8), 'cup.png')
    with pytest.raises(ValueError, match="'size'"):
        read_mask(path, size=size)


def test_mask_that_masks_out_everything(tmp_path):
    path = save(tmp_path, np.full((5, 5), 127, np.uint8), 'empty.png')
    with pytest.raises(ValueError, match=r"empty\.png' masks out every "
                                         r"pixel"):
        read_mask(path)


def test_16bit_grayscale_mask(tmp_path):
    codes = np.array([[32767, 32768, 65535, 0]], np.uint16)
    np.testing.assert_array_equal(read_mask(save(tmp_path, codes, 'm.png')),
                                  [[False, True, True, False]])


def test_public_names():
    import tg_intrinsic.io.photographs as module
    assert set(module.__all__) == {'LDR_EXTENSIONS', 'LDRPhoto',
                                   'srgb_to_linear', 'read_ldr',
                                   'exif_exposure', 'read_mask'}
    assert math.isclose(srgb_curve(0.5), 0.21404114, rel_tol=1e-7)
