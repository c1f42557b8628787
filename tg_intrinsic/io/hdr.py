r"""High-dynamic-range image files: Radiance RGBE (``.hdr``), OpenEXR
(``.exr``, optional) and NumPy (``.npy``) environment maps.

RGBE stores a pixel as three 8-bit mantissas sharing one 8-bit exponent,

.. math::
    (R, G, B) = (r, g, b)\,2^{e - 136}, \qquad e = 0 \Rightarrow
    (R, G, B) = 0,

so every channel is known to :math:`1/256` of the pixel's largest channel.
The reader decodes with exactly this formula (as OpenCV, imageio and
Bruce Walter's ``rgbe.c``; Radiance's own reader adds half a mantissa
step because its writer truncates); the writer rounds to the nearest
mantissa, so a round trip is accurate to half a step.
"""
import os
import re
import warnings
import zipfile

import numpy as np
import torch

from tg_intrinsic.geometry.appearance.dynamic_range import looks_clipped
from tg_intrinsic.geometry.jit import jit
from tg_intrinsic.utils import atomic_write

_MAGIC = (b'#?RADIANCE', b'#?RGBE')
_RESOLUTION = re.compile(rb'^([+-])([XY]) +(\d+) +([+-])([XY]) +(\d+)$')

# Decoder status codes (the kernel cannot raise with a message).
_OK, _TRUNCATED, _BAD_RUN, _BAD_WIDTH = 0, 1, 2, 3


# ------------------------------------------------------------------ kernels
@jit
def _decode_rgbe(data, pos, height, width, out):
    """Decodes ``height`` scanlines of ``width`` RGBE pixels from ``data``
    (uint8) starting at byte ``pos`` into ``out`` (height, width, 4).
    Each scanline may be new-style RLE (per channel), old-style RLE
    (``1 1 1 n`` repeats the previous pixel) or flat. Returns
    ``(status, scanline, pos)``."""
    size = data.size
    new_style = width >= 8 and width < 32768
    for y in range(height):
        if pos + 4 > size:
            return _TRUNCATED, y, pos
        if new_style and data[pos] == 2 and data[pos + 1] == 2 \
                and data[pos + 2] < 128:
            if (np.int64(data[pos + 2]) << 8) + data[pos + 3] != width:
                return _BAD_WIDTH, y, pos
            pos += 4
            for c in range(4):
                x = 0
                while x < width:
                    if pos >= size:
                        return _TRUNCATED, y, pos
                    count = np.int64(data[pos])
                    pos += 1
                    if count > 128:  # a run of one byte
                        count -= 128
                        if x + count > width:
                            return _BAD_RUN, y, pos
                        if pos >= size:
                            return _TRUNCATED, y, pos
                        value = data[pos]
                        pos += 1
                        for k in range(count):
                            out[y, x + k, c] = value
                    else:  # literal bytes
                        if count == 0 or x + count > width:
                            return _BAD_RUN, y, pos
                        if pos + count > size:
                            return _TRUNCATED, y, pos
                        for k in range(count):
                            out[y, x + k, c] = data[pos + k]
                        pos += count
                    x += count
        else:
            x = 0
            shift = 0
            while x < width:
                if pos + 4 > size:
                    return _TRUNCATED, y, pos
                if data[pos] == 1 and data[pos + 1] == 1 \
                        and data[pos + 2] == 1:
                    # old-style run: repeat the previous pixel; consecutive
                    # run markers are the higher bytes of one count
                    count = np.int64(data[pos + 3]) << shift
                    if x == 0 or x + count > width:
                        return _BAD_RUN, y, pos
                    for k in range(count):
                        for c in range(4):
                            out[y, x + k, c] = out[y, x - 1, c]
                    x += count
                    shift += 8
                else:
                    for c in range(4):
                        out[y, x, c] = data[pos + c]
                    x += 1
                    shift = 0
                pos += 4
    return _OK, height, pos


@jit
def _encode_rle(rgbe, out):
    """New-style RLE of (height, width, 4) uint8 scanlines into ``out``:
    runs of 4 or more equal bytes (at most 127) become two bytes, the rest
    literal chunks of at most 128. Returns the bytes written."""
    height, width = rgbe.shape[0], rgbe.shape[1]
    p = 0
    for y in range(height):
        out[p] = 2
        out[p + 1] = 2
        out[p + 2] = width >> 8
        out[p + 3] = width & 255
        p += 4
        for c in range(4):
            x = 0
            while x < width:
                # the next run of at least 4 at or after x
                begin = x
                run = 0
                while begin < width:
                    run = 1
                    while begin + run < width and run < 127 and \
                            rgbe[y, begin + run, c] == rgbe[y, begin, c]:
                        run += 1
                    if run >= 4:
                        break
                    begin += run
                if run < 4:
                    begin = width
                while x < begin:
                    n = min(128, begin - x)
                    out[p] = n
                    for k in range(n):
                        out[p + 1 + k] = rgbe[y, x + k, c]
                    p += n + 1
                    x += n
                if begin < width:
                    out[p] = 128 + run
                    out[p + 1] = rgbe[y, begin, c]
                    p += 2
                    x = begin + run
    return p


# ------------------------------------------------------------------ header
def _parse_header(data: bytes, path: str):
    """Returns ``(pos, divisor, orientation)``: the byte where pixels
    start, the per-channel divisor from EXPOSURE/COLORCORR and
    ``(major_sign, major_axis, major_size, minor_sign, minor_axis,
    minor_size)``."""
    if not data.startswith(b'#?'):
        start = data[:16]
        raise ValueError(f"'{path}' is not a Radiance RGBE (.hdr) file: it "
                         f"must start with '#?RADIANCE', got {start!r}; "
                         f"read other formats with the right reader "
                         f"(read_exr for .exr)")
    end = data.find(b'\n\n')
    if end < 0:
        raise ValueError(f"'{path}' has no blank line ending its RGBE "
                         f"header; the file is truncated or not RGBE")
    exposure = 1.0
    colorcorr = np.ones(3)
    for line in data[:end].split(b'\n')[1:]:
        line = line.strip()
        if line.startswith(b'FORMAT='):
            fmt = line[7:].strip()
            if fmt == b'32-bit_rle_xyze':
                raise ValueError(f"'{path}' stores CIE XYZ (FORMAT="
                                 f"32-bit_rle_xyze), which is unsupported; "
                                 f"convert it to RGB (e.g. with Radiance's "
                                 f"ra_xyze -r) first")
            if fmt != b'32-bit_rle_rgbe':
                raise ValueError(f"'{path}' has unknown FORMAT={fmt!r}; "
                                 f"only 32-bit_rle_rgbe is supported")
        elif line.startswith(b'EXPOSURE='):
            try:
                exposure *= float(line[9:])
            except ValueError:
                raise ValueError(f"'{path}' has a malformed header line "
                                 f"{line!r}") from None
        elif line.startswith(b'COLORCORR='):
            try:
                values = [float(v) for v in line[10:].split()]
            except ValueError:
                values = []
            if len(values) != 3:
                raise ValueError(f"'{path}' has a malformed header line "
                                 f"{line!r}")
            colorcorr *= values
    divisor = exposure * colorcorr
    if not (np.isfinite(divisor).all() and (divisor > 0).all()):
        raise ValueError(f"'{path}' has a non-positive EXPOSURE or "
                         f"COLORCORR ({divisor.tolist()}); fix the header")
    newline = data.find(b'\n', end + 2)
    if newline < 0:
        raise ValueError(f"'{path}' ends before the resolution line; the "
                         f"file is truncated")
    match = _RESOLUTION.match(data[end + 2:newline].strip())
    if match is None or match.group(2) == match.group(5):
        raise ValueError(f"'{path}' has an unreadable resolution line "
                         f"{data[end + 2:newline][:40]!r}; expected e.g. "
                         f"'-Y 512 +X 1024'")
    s1, a1, n1, s2, a2, n2 = match.groups()
    orientation = (s1, a1, int(n1), s2, a2, int(n2))
    if orientation[2] < 1 or orientation[5] < 1:
        raise ValueError(f"'{path}' has an empty image ({n1} x {n2})")
    return newline + 1, divisor, orientation


def _min_scanline_bytes(width: int) -> int:
    """The fewest bytes any encoding the decoder accepts needs for one
    scanline of ``width`` pixels: flat pixels take 4 bytes each, a new-style
    RLE scanline at least its 4-byte marker and 2 bytes per channel for
    every 127 pixels, and the most compact, old-style runs, one 4-byte pixel
    and 4-byte run markers whose counts are consecutive bytes of one number
    (so ``ceil(bits(width - 1) / 8)`` of them)."""
    markers = -(-(width - 1).bit_length() // 8)
    return 4 + 4 * markers


def _check_pixel_bytes(path: str, available: int, lines: int, width: int):
    """A header claiming more pixels than the data could hold in any
    encoding is rejected before memory is allocated for them."""
    needed = lines * _min_scanline_bytes(width)
    if available < needed:
        raise ValueError(f"'{path}': its header says {lines} x {width} "
                         f"pixels but the file has {available} bytes of "
                         f"pixel data, fewer than the {needed} any encoding "
                         f"needs; the file is truncated or its resolution "
                         f"line is wrong")


def _rgbe_to_float(rgbe: np.ndarray) -> np.ndarray:
    exponent = rgbe[..., 3].astype(np.int64)
    scale = np.where(exponent > 0, np.ldexp(1.0, exponent - 136), 0.0)
    return (rgbe[..., :3] * scale[..., None]).astype(np.float32)


def _float_to_rgbe(image: np.ndarray) -> np.ndarray:
    """Nearest-mantissa RGBE: the largest channel lands in [128, 255]."""
    image = image.astype(np.float64)
    largest = image.max(-1)
    mantissa, exponent = np.frexp(largest)  # largest = mantissa 2^exponent
    # rounding 255.5 and up would need a 9th bit: one exponent more
    exponent = exponent + (mantissa * 256 + 0.5 >= 256)
    scale = np.ldexp(256.0, -exponent)
    out = np.zeros(image.shape[:-1] + (4, ), np.uint8)
    stored = exponent + 128
    if (stored > 255).any():
        raise ValueError("'image' has values of 2^127 or more, beyond "
                         "RGBE's range; rescale it")
    keep = (largest > 0) & (stored >= 1)  # smaller ones underflow to 0
    mantissas = np.floor(image[keep] * scale[keep, None] + 0.5)
    out[keep, :3] = np.clip(mantissas, 0, 255)
    out[keep, 3] = stored[keep]
    return out


# ------------------------------------------------------------------ public
def read_hdr(path) -> np.ndarray:
    r"""Reads a Radiance RGBE (``.hdr``) file as linear radiance.

    Decodes new-style run-length scanlines, old-style runs and flat pixels
    with a compiled kernel, then

    .. math::
        L = \frac{(r, g, b)\,2^{e - 136}}{\prod \mathrm{EXPOSURE}\;
        \prod \mathrm{COLORCORR}},

    dividing by the header's EXPOSURE (and COLORCORR) lines as the format
    specifies, so the result is the radiance before those multipliers
    (most files have none). Any of the eight orientations of the
    resolution line is turned into the standard one, ``-Y H +X W``: row 0
    at the top, column 0 at the left.

    Args:
        path (str or os.PathLike): The file.

    Returns:
        :class:`numpy.ndarray` of float32, shape :math:`(H, W, 3)`.

    Raises:
        FileNotFoundError: If there is no such file.
        ValueError: If it is not RGBE, stores XYZ, or is truncated or
            corrupt, or its header claims more pixels than its data could
            hold in any encoding (checked before decoding, so a corrupt
            resolution line cannot make it allocate terabytes).
    """
    path = os.fspath(path)
    with open(path, 'rb') as f:
        data = f.read()
    pos, divisor, (s1, a1, n1, s2, a2, n2) = _parse_header(data, path)
    _check_pixel_bytes(path, len(data) - pos, n1, n2)
    buffer = np.frombuffer(data, np.uint8)
    try:
        rgbe = np.zeros((n1, n2, 4), np.uint8)
    except MemoryError:
        raise ValueError(f"'{path}': its header says {n1} x {n2} pixels, "
                         f"{4 * n1 * n2 / 2 ** 30:.1f} GiB to decode, more "
                         f"than this machine can allocate") from None
    status, line, _ = _decode_rgbe(buffer, pos, n1, n2, rgbe)
    if status == _TRUNCATED:
        raise ValueError(f"'{path}' is truncated: its data ends in scanline "
                         f"{line} of {n1}; the file is incomplete, "
                         f"download or export it again")
    if status == _BAD_RUN:
        raise ValueError(f"'{path}' is corrupt: a run in scanline {line} "
                         f"overruns the {n2} pixels of the scanline")
    if status == _BAD_WIDTH:
        raise ValueError(f"'{path}' is corrupt: scanline {line} declares a "
                         f"width other than {n2}")
    image = _rgbe_to_float(rgbe)
    # scanlines along the major axis; '+Y' starts at the bottom, '-X' at
    # the right
    if a1 == b'Y':
        image = image[::-1] if s1 == b'+' else image
        image = image[:, ::-1] if s2 == b'-' else image
    else:
        image = image[::-1] if s1 == b'-' else image
        image = image[:, ::-1] if s2 == b'+' else image
        image = image.transpose(1, 0, 2)
    image = np.ascontiguousarray(image)
    if (divisor != 1).any():
        image /= divisor.astype(np.float32)
    return image


def _as_numpy_image(image) -> np.ndarray:
    if isinstance(image, torch.Tensor):
        image = image.detach().cpu().numpy()
    image = np.asarray(image)
    if image.ndim != 3 or image.shape[-1] != 3 or min(image.shape[:2]) < 1:
        raise ValueError(f"'image' must have shape [H, W, 3], got "
                         f"{list(image.shape)}")
    if not np.issubdtype(image.dtype, np.floating):
        raise ValueError(f"'image' must hold floating-point linear "
                         f"radiance, got {image.dtype}")
    if not np.isfinite(image).all():
        raise ValueError("'image' has NaN or infinite values, which RGBE "
                         "cannot store; repair them first")
    if (image < 0).any():
        raise ValueError("'image' has negative values, which RGBE cannot "
                         "store; clamp them to 0 first")
    return image


def write_hdr(path, image) -> None:
    r"""Writes linear radiance as a run-length encoded Radiance RGBE
    (``.hdr``) file, orientation ``-Y H +X W``.

    Each pixel is stored with the nearest 8-bit mantissas under the
    exponent of its largest channel, so :func:`read_hdr` returns every
    channel within :math:`2^{-9}` of the pixel's largest channel
    (:math:`1/256` relative, with margin). The file is written to a
    temporary file in the same folder and moved into place with
    :func:`os.replace`, so a reader never sees half a file.

    Args:
        path (str or os.PathLike): The file.
        image (numpy.ndarray or torch.Tensor): Finite, non-negative
            :math:`(H, W, 3)` floating-point radiance.

    Raises:
        FileNotFoundError: If the folder of ``path`` does not exist (it is
            not created); the message names the folder.
        ValueError: If ``image`` is not finite, non-negative
            :math:`(H, W, 3)` floating-point radiance.
    """
    path = os.fspath(path)
    image = _as_numpy_image(image)
    height, width = image.shape[:2]
    rgbe = _float_to_rgbe(image)
    if 8 <= width < 32768:
        out = np.empty(height * (4 + 4 * (width + (width + 127) // 128)),
                       np.uint8)
        body = out[:_encode_rle(rgbe, out)].tobytes()
    else:  # new-style RLE cannot describe these widths
        body = rgbe.tobytes()
    header = (b'#?RADIANCE\n# written by tg_intrinsic\n'
              b'FORMAT=32-bit_rle_rgbe\n\n'
              + f'-Y {height} +X {width}\n'.encode())

    def write(f):
        f.write(header)
        f.write(body)

    atomic_write(path, write, 'wb', make_folder=False)


def read_exr(path) -> np.ndarray:
    r"""Reads the RGB channels of an OpenEXR file as linear radiance.

    Needs the optional ``OpenEXR`` package (``pip install OpenEXR``). A
    luminance-only image (channel ``Y``) is repeated into three channels.

    Args:
        path (str or os.PathLike): The file.

    Returns:
        :class:`numpy.ndarray` of float32, shape :math:`(H, W, 3)`.
    """
    try:
        import OpenEXR
    except ImportError:
        raise ImportError("reading .exr files needs the OpenEXR package: "
                          "pip install OpenEXR (or convert the file to "
                          ".hdr)") from None
    path = os.fspath(path)
    if not os.path.exists(path):
        raise FileNotFoundError(f"no such file: '{path}'")
    if not hasattr(OpenEXR, 'File'):
        raise ImportError("OpenEXR is too old (before 3.3): pip install "
                          "--upgrade OpenEXR")
    try:
        with OpenEXR.File(path, separate_channels=True) as f:
            channels = {name: np.asarray(channel.pixels)
                        for name, channel in f.channels().items()}
    except Exception as error:
        raise ValueError(f"'{path}' could not be read as OpenEXR: "
                         f"{error}") from None
    if all(c in channels for c in 'RGB'):
        image = np.stack([channels[c] for c in 'RGB'], -1)
    elif 'Y' in channels:
        image = np.repeat(channels['Y'][..., None], 3, -1)
    else:
        raise ValueError(f"'{path}' has no R, G, B (or Y) channels, only "
                         f"{sorted(channels)}")
    return np.ascontiguousarray(image, dtype=np.float32)


def read_npy(path) -> np.ndarray:
    """The array of numbers in a ``.npy`` file (:func:`numpy.save`).

    Raises a :class:`ValueError` that names the file and what is wrong
    with it: numpy's own message for a file that is not ``.npy`` offers to
    unpickle it, which would run code from the file.
    """
    path = os.fspath(path)
    try:
        array = np.load(path, allow_pickle=False)
    except EOFError:
        reason = 'it is empty'
    except ValueError as error:
        message = str(error)
        if 'pickled' in message:
            reason = 'it is not a NumPy .npy file'
        elif 'Object arrays' in message:
            reason = 'it holds Python objects, not numbers'
        else:  # a damaged header or data cut short
            reason = f'it is damaged ({message.rstrip(".")})'
    except zipfile.BadZipFile as error:
        reason = f'it is a damaged .npz archive ({error})'
    else:
        if not isinstance(array, np.lib.npyio.NpzFile):
            return array
        array.close()
        reason = 'it is a .npz archive (numpy.savez), not one .npy array'
    raise ValueError(f"could not read '{path}': {reason}; write it with "
                     f"numpy.save")


def read_envmap(path) -> torch.Tensor:
    r"""Reads an equirectangular environment map (``.hdr``/``.pic``,
    ``.exr`` or ``.npy``) as a float32 tensor :math:`(H, W, 3)` in the
    convention of :mod:`tg_intrinsic.geometry.appearance.envmap` (row 0 looks
    up, :math:`+z`), validated by
    :func:`~tg_intrinsic.geometry.appearance.envmap.check_envmap`.

    Warns with a :class:`UserWarning` when the map
    :func:`looks_clipped` (an LDR panorama underestimates the sun by
    orders of magnitude).

    Args:
        path (str or os.PathLike): The file.
    """
    from tg_intrinsic.geometry.appearance.envmap import check_envmap
    path = os.fspath(path)
    extension = os.path.splitext(path)[1].lower()
    if extension in ('.hdr', '.pic', '.rgbe'):
        image = read_hdr(path)
    elif extension == '.exr':
        image = read_exr(path)
    elif extension == '.npy':
        image = read_npy(path)
        if not np.issubdtype(image.dtype, np.floating):
            raise ValueError(f"'{path}' holds {image.dtype}, not "
                             f"floating-point radiance")
    else:
        raise ValueError(f"'{path}': unknown environment-map extension "
                         f"{extension!r}; use .hdr, .exr or .npy")
    envmap = check_envmap(torch.as_tensor(np.ascontiguousarray(image))
                          .float(), os.path.basename(path))
    if looks_clipped(envmap):
        warnings.warn(f"'{path}' looks low-dynamic-range (values on a "
                      f"1/255 grid or piled up at a maximum <= 1); lighting "
                      f"from it will be too dim in the highlights",
                      UserWarning, stacklevel=2)
    return envmap
