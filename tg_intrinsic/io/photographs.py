r"""Low-dynamic-range photographs (JPEG, PNG, BMP, TIFF, WebP) as linear
radiance, their EXIF exposure, and object masks, for SVBRDF recovery from
real captures.

An 8- or 16-bit photograph stores codes :math:`q \in \{0, \ldots, M\}`
(:math:`M = 255` or :math:`65535`) that a camera or editor encoded with a
transfer curve; :func:`read_ldr` undoes it, by default with the sRGB
decoding curve of IEC 61966-2-1 (:func:`srgb_to_linear`),

.. math::
    L = \begin{cases} c / 12.92, & c \le 0.04045, \\
    \left(\frac{c + 0.055}{1.055}\right)^{2.4}, & c > 0.04045,
    \end{cases} \qquad c = q / M,

or with a power law :math:`L = c^{\gamma}`. This assumes the camera's
response is that curve, as for most JPEGs straight from a camera or phone
(tone-mapped photographs are not radiance). Pixels at :math:`M` in some
channel are clipped: their radiance is only a lower bound, and
:func:`read_ldr` flags them with their neighbours (which JPEG compression
and demosaicing blur into).

Pixels are used as the file stores them: an EXIF Orientation tag is
ignored, as COLMAP does, so camera calibrations made on the stored pixels
match. Pillow reads 16-bit grayscale photographs with all 16 bits but
16-bit colour (RGB, RGBA, LA) only as 8 bits, so :func:`read_ldr` refuses
those rather than silently losing 8 bits.
"""
import math
import os
import re
import struct
from typing import NamedTuple, Optional

import numpy as np

__all__ = ['LDR_EXTENSIONS', 'LDRPhoto', 'srgb_to_linear', 'read_ldr',
           'exif_exposure', 'read_mask']

#: File extensions of the photographs :func:`read_ldr` reads.
LDR_EXTENSIONS = ('.png', '.jpg', '.jpeg', '.bmp', '.tif', '.tiff', '.webp')

# raw modes of 16-bit colour that Pillow reduces to 8 bits ('RGB;16B' in
# PNG, 'RGB;16N' in TIFF; not BMP's 5-6-5 'BGR;16')
_REDUCED_RAWMODE = re.compile(r';16[BLN]$')
_GRAY16_RAWMODE = re.compile(r'I;16[BLN]?')
_GRAY16_MODES = ('I;16', 'I;16B', 'I;16L', 'I;16N')
# Pillow modes turned into one of L, LA, RGB, RGBA before decoding
_CONVERT = {'1': 'L', 'La': 'LA', 'PA': 'RGBA', 'RGBa': 'RGBA',
            'RGBX': 'RGB', 'CMYK': 'RGB', 'YCbCr': 'RGB'}

_EXIF_IFD = 0x8769
_EXPOSURE_TIME, _F_NUMBER, _ISO = 0x829A, 0x829D, 0x8827


class LDRPhoto(NamedTuple):
    r"""A photograph read by :func:`read_ldr`: ``radiance``, linear values
    in :math:`[0, 1]` (float32, :math:`(H, W, 3)`); ``clipped``, bool
    :math:`(H, W)`, the pixels with a channel at the largest code and
    their 8 neighbours; ``alpha``, bool :math:`(H, W)` where the alpha
    channel is above half its maximum, or :obj:`None` when the file has
    no alpha channel."""
    radiance: np.ndarray
    clipped: np.ndarray
    alpha: Optional[np.ndarray]


def srgb_to_linear(values: np.ndarray) -> np.ndarray:
    r"""The sRGB decoding curve of IEC 61966-2-1. It is

    .. math::
        L = \begin{cases} c / 12.92, & c \le 0.04045, \\
        \left(\frac{c + 0.055}{1.055}\right)^{2.4}, & c > 0.04045,
        \end{cases}

    elementwise on encoded values :math:`c \in [0, 1]`.

    Args:
        values (numpy.ndarray): Encoded values, any shape.

    Returns:
        :class:`numpy.ndarray` of the same shape: float32 for float32 (or
        float16) input, float64 otherwise.
    """
    values = np.asarray(values)
    if values.dtype in (np.float16, np.float32):
        values = values.astype(np.float32, copy=False)
    elif values.dtype != np.float64:
        values = values.astype(np.float64)
    knee = values.dtype.type(0.04045)
    low = values / values.dtype.type(12.92)
    high = ((np.maximum(values, knee) + values.dtype.type(0.055))
            / values.dtype.type(1.055)) ** values.dtype.type(2.4)
    return np.where(values <= knee, low, high)


# ------------------------------------------------------------------ decoding
def _open(path: str):
    """Opens ``path`` with Pillow; anything but an image raises
    ValueError."""
    from PIL import Image, UnidentifiedImageError
    try:
        return Image.open(path)
    except (FileNotFoundError, IsADirectoryError, PermissionError):
        raise
    except UnidentifiedImageError:
        raise ValueError(f"'{path}' is not an image file that Pillow can "
                         f"read; it is corrupt or in another format") \
            from None
    except (OSError, SyntaxError, ValueError, EOFError) as error:
        raise ValueError(f"'{path}' could not be read as an image "
                         f"({error})") from None


def _rawmode(img) -> str:
    """The raw mode of the file's first tile (before loading), e.g.
    ``'RGB;16B'`` for a 16-bit RGB PNG that Pillow reduces to 8 bits."""
    if not img.tile:
        return ''
    args = img.tile[0][3]
    if isinstance(args, tuple):
        args = args[0] if args else ''
    return args if isinstance(args, str) else ''


def _codes(img, path: str, noun: str, allow_reduced: bool):
    """Decodes an opened image into ``(codes, maximum, has_alpha)``: codes
    (H, W, C) uint8 or uint16 with C = 1, 2 (L, LA), 3 or 4 (RGB, RGBA)
    and the largest code, 255 or 65535."""
    rawmode = _rawmode(img)
    try:
        img.load()
    except (OSError, SyntaxError, ValueError, EOFError) as error:
        raise ValueError(f"'{path}' could not be decoded ({error}); the "
                         f"file is truncated or corrupt") from None
    width, height = img.size
    if width < 1 or height < 1:
        raise ValueError(f"'{path}' has no pixels ({width} x {height})")
    mode = img.mode
    gray16 = mode in _GRAY16_MODES or (
        mode == 'I' and _GRAY16_RAWMODE.fullmatch(rawmode) is not None)
    if gray16:
        codes = np.asarray(img)
        if mode == 'I' and (codes.min() < 0 or codes.max() > 65535):
            raise ValueError(f"'{path}' has 16-bit codes outside "
                             f"[0, 65535]; the file is corrupt")
        return codes.astype(np.uint16)[..., None], 65535, False
    if _REDUCED_RAWMODE.search(rawmode) and not allow_reduced:
        raise ValueError(f"'{path}' is a 16-bit colour {noun}, which "
                         f"Pillow reads only as 8 bits; convert it to "
                         f"8 bits, or store its linear radiance as "
                         f".exr or .hdr")
    if mode == 'P':
        mode = 'RGBA' if 'transparency' in img.info else 'RGB'
    mode = _CONVERT.get(mode, mode)
    if mode not in ('L', 'LA', 'RGB', 'RGBA'):
        hint = 'linear HDR photographs go in .exr/.hdr' \
            if noun == 'photograph' else 'save masks as 8-bit images'
        raise ValueError(f"'{path}' is not an 8- or 16-bit {noun} (Pillow "
                         f"mode {img.mode!r}); {hint}")
    if mode != img.mode:
        img = img.convert(mode)
    codes = np.asarray(img)
    if codes.ndim == 2:
        codes = codes[..., None]
    return codes, 255, mode in ('LA', 'RGBA')


def _decode(path, noun: str, allow_reduced: bool):
    path = os.fspath(path)
    with _open(path) as img:
        return _codes(img, path, noun, allow_reduced)


# ------------------------------------------------------------------ public
def read_ldr(path, gamma: Optional[float] = None) -> LDRPhoto:
    r"""Reads an 8- or 16-bit photograph as linear radiance.

    A code :math:`q` of at most :math:`M` (255, or 65535 for 16-bit
    grayscale PNG and TIFF) becomes :math:`L = \mathrm{srgb}(q / M)` with
    :func:`srgb_to_linear`, or :math:`L = (q / M)^{\gamma}` when ``gamma``
    is given. Grayscale photographs become three equal channels, palette
    images their colours. The stored pixels are used: an EXIF Orientation
    tag is ignored, as COLMAP does.

    Args:
        path (str or os.PathLike): The photograph, one of
            :data:`LDR_EXTENSIONS` (any format Pillow reads).
        gamma (float, optional): Decode with this power law instead of the
            sRGB curve. (default: :obj:`None`)

    Returns:
        :class:`LDRPhoto`: ``radiance`` float32 :math:`(H, W, 3)` in
        :math:`[0, 1]`; ``clipped`` bool :math:`(H, W)`, pixels with any
        channel at :math:`M` dilated by a :math:`3 \times 3` square;
        ``alpha`` bool :math:`(H, W)` where the alpha channel exceeds
        :math:`M / 2` (RGBA, LA and transparent palette images), else
        :obj:`None`.

    Raises:
        FileNotFoundError: If there is no such file.
        ValueError: If it is not an image Pillow reads, is truncated, has
            float or 32-bit integer pixels, is 16-bit colour (which Pillow
            reduces to 8 bits) or has no pixels, or ``gamma`` is not a
            positive number.
    """
    from scipy.ndimage import binary_dilation
    if gamma is not None and (isinstance(gamma, bool) or not isinstance(
            gamma, (int, float, np.integer, np.floating))
            or not math.isfinite(gamma) or gamma <= 0):
        raise ValueError(f"'gamma' must be a positive number or None, got "
                         f"{gamma!r}")
    codes, maximum, has_alpha = _decode(path, 'photograph', False)
    colour = codes[..., :-1] if has_alpha else codes
    # every code's linear value, looked up (exact, and fast for 16 bits)
    encoded = np.arange(maximum + 1, dtype=np.float64) / maximum
    table = srgb_to_linear(encoded) if gamma is None \
        else encoded ** float(gamma)
    radiance = table.astype(np.float32)[colour]
    if radiance.shape[-1] == 1:
        radiance = np.repeat(radiance, 3, axis=-1)
    clipped = binary_dilation((colour == maximum).any(-1),
                              structure=np.ones((3, 3), bool))
    alpha = None
    if has_alpha:
        alpha = codes[..., -1].astype(np.int32) * 2 > maximum
    return LDRPhoto(radiance, clipped, alpha)


def _positive(value) -> Optional[float]:
    """An EXIF value (rational, number or tuple of them) as a positive
    finite float, else None."""
    if isinstance(value, (tuple, list)):
        value = value[0] if value else None
    try:
        value = float(value)
    except (TypeError, ValueError, ZeroDivisionError, OverflowError):
        return None
    return value if math.isfinite(value) and value > 0 else None


def exif_exposure(path) -> Optional[float]:
    r"""The relative exposure of a photograph from its EXIF tags. It is

    .. math::
        e = \frac{t\,S}{N^2},

    with :math:`t` the exposure time in seconds (ExposureTime, 0x829A),
    :math:`S` the ISO sensitivity (ISOSpeedRatings or
    PhotographicSensitivity, 0x8827; the first value of several) and
    :math:`N` the f-number (FNumber, 0x829D), read from the Exif sub-IFD
    (0x8769), or the main IFD of a TIFF. A pixel's linear value is
    proportional to radiance times :math:`e`, so dividing each
    photograph's linear values (:func:`read_ldr`) by
    ``exif_exposure(photo) / exif_exposure(first)`` makes photographs of
    different exposures comparable, in the units of the first.

    Args:
        path (str or os.PathLike): The photograph.

    Returns:
        float, or :obj:`None` if the file has no (readable) EXIF or one of
        the three tags is missing or not positive.

    Raises:
        FileNotFoundError: If there is no such file.
        ValueError: If it is not an image Pillow reads.
    """
    path = os.fspath(path)
    with _open(path) as img:
        try:
            exif = img.getexif()
            tags = dict(exif)
            tags.update(exif.get_ifd(_EXIF_IFD))
        except (OSError, SyntaxError, ValueError, KeyError, IndexError,
                TypeError, struct.error):
            return None
    time = _positive(tags.get(_EXPOSURE_TIME))
    iso = _positive(tags.get(_ISO))
    f_number = _positive(tags.get(_F_NUMBER))
    if time is None or iso is None or f_number is None:
        return None
    return time * iso / f_number ** 2


def read_mask(path, size=None) -> np.ndarray:
    r"""Reads an object mask (PNG, JPEG, BMP, ...), True on the object.

    A pixel is True where its value exceeds half the largest code. The
    value is the gray level of grayscale and 1-bit masks and the mean of
    R, G, B of colour masks; for masks with alpha (RGBA, LA) it is the
    alpha channel when the colour is the same in every pixel (a cut-out
    drawn in one colour), else the colour's mean (alpha is ignored).

    Args:
        path (str or os.PathLike): The mask.
        size (tuple, optional): The photograph's :math:`(H, W)`, which the
            mask must have. (default: :obj:`None`)

    Returns:
        :class:`numpy.ndarray` of bool, shape :math:`(H, W)`.

    Raises:
        FileNotFoundError: If there is no such file.
        ValueError: If it is not an 8- or 16-bit image Pillow reads, its
            size is not ``size``, or it masks out every pixel.
    """
    if size is not None:
        if len(size) != 2 or not all(isinstance(n, (int, np.integer))
                                     and n > 0 for n in size):
            raise ValueError(f"'size' must be (H, W), two positive "
                             f"integers, got {size!r}")
    path = os.fspath(path)
    codes, maximum, has_alpha = _decode(path, 'mask', True)
    height, width = codes.shape[:2]
    if size is not None and (height, width) != tuple(size):
        raise ValueError(f"'{path}' is {width} x {height} pixels (width x "
                         f"height) but its photograph is {size[1]} x "
                         f"{size[0]}; masks must have the photograph's "
                         f"size")
    colour = codes[..., :-1] if has_alpha else codes
    if has_alpha and (colour == colour[:1, :1]).all():
        mask = codes[..., -1].astype(np.int32) * 2 > maximum
    else:
        total = colour.sum(-1, dtype=np.int32)
        mask = total * 2 > maximum * colour.shape[-1]
    if not mask.any():
        raise ValueError(f"'{path}' masks out every pixel: none is above "
                         f"half of the largest value {maximum}")
    return mask
