r"""COLMAP sparse models: :func:`read_colmap_model` reads the cameras and
the image poses of a model that COLMAP's mapper (or
``colmap image_undistorter``, ``colmap model_converter``) wrote,
:func:`write_colmap_model` writes one, and :func:`camera_matrix` turns a
COLMAP camera into a pinhole matrix :math:`K` and OpenCV distortion
coefficients.

A model is a folder (``sparse/0`` of a COLMAP project) with three files,
each as text (``.txt``) or little-endian binary (``.bin``):

* ``cameras``: per camera ``CAMERA_ID MODEL WIDTH HEIGHT PARAMS[]``; in
  binary ``uint64`` count, then per camera ``uint32`` id, ``int32`` model
  id, ``uint64`` width and height and the model's ``float64`` parameters.
* ``images``: per image ``IMAGE_ID QW QX QY QZ TX TY TZ CAMERA_ID NAME``
  and a second line of 2D points ``X Y POINT3D_ID ...`` (possibly empty);
  in binary ``uint64`` count, then per image ``uint32`` id, ``float64``
  ``qw qx qy qz tx ty tz``, ``uint32`` camera id, the name ending in a
  null byte, ``uint64`` number of 2D points and that many
  ``(float64 x, float64 y, int64 point3D_id)``.
* ``points3D``: the 3D points, which this module neither needs nor reads
  (:func:`write_colmap_model` writes an empty one so that COLMAP opens the
  model).

Text lines starting with ``#`` are comments. COLMAP 3.12 and later also
write ``rigs`` and ``frames`` files; they are ignored here, as
``images`` holds every registered image's own pose.

The pose of an image is world-to-camera, :math:`x_c = R x + t`, with
:math:`R` the rotation of the unit Hamilton quaternion
:math:`(q_w, q_x, q_y, q_z)`: the OpenCV convention of
:mod:`tg_intrinsic.io.scene` (the camera looks along :math:`+z_c`, with
:math:`x_c` right and :math:`y_c` down in the image). COLMAP puts the
centre of the upper-left pixel at :math:`(0.5, 0.5)`, as this library
does, so its principal points :math:`c_x, c_y` are used as they are, with
no half-pixel shift.

Camera models (id, name, parameters), as COLMAP numbers them; all are
read and written, and the first five are supported by
:func:`camera_matrix`:

* 0 ``SIMPLE_PINHOLE``: f, cx, cy
* 1 ``PINHOLE``: fx, fy, cx, cy
* 2 ``SIMPLE_RADIAL``: f, cx, cy, k
* 3 ``RADIAL``: f, cx, cy, k1, k2
* 4 ``OPENCV``: fx, fy, cx, cy, k1, k2, p1, p2
* 5 ``OPENCV_FISHEYE`` (8), 6 ``FULL_OPENCV`` (12), 7 ``FOV`` (5),
  8 ``SIMPLE_RADIAL_FISHEYE`` (4), 9 ``RADIAL_FISHEYE`` (5),
  10 ``THIN_PRISM_FISHEYE`` (12)
"""
import os
import os.path as osp
import struct
from typing import List, Optional, Tuple

import numpy as np

from tg_intrinsic.utils import atomic_write

from .capture_files import HDR_EXTENSIONS, why_not_a_file
from .capture_views import CaptureSpec, CaptureView, assemble_capture
from .photographs import LDR_EXTENSIONS

__all__ = ['CAMERA_MODELS', 'SUPPORTED_MODELS', 'find_colmap_model',
           'colmap_spec', 'read_colmap',
           'read_colmap_model', 'write_colmap_model', 'camera_matrix']

#: COLMAP's camera models: model id -> (name, number of parameters).
CAMERA_MODELS = {
    0: ('SIMPLE_PINHOLE', 3),
    1: ('PINHOLE', 4),
    2: ('SIMPLE_RADIAL', 4),
    3: ('RADIAL', 5),
    4: ('OPENCV', 8),
    5: ('OPENCV_FISHEYE', 8),
    6: ('FULL_OPENCV', 12),
    7: ('FOV', 5),
    8: ('SIMPLE_RADIAL_FISHEYE', 4),
    9: ('RADIAL_FISHEYE', 5),
    10: ('THIN_PRISM_FISHEYE', 12),
}
_MODEL_IDS = {name: model_id for model_id, (name, _) in CAMERA_MODELS.items()}
_PARAMETER_NAMES = {
    'SIMPLE_PINHOLE': 'f, cx, cy',
    'PINHOLE': 'fx, fy, cx, cy',
    'SIMPLE_RADIAL': 'f, cx, cy, k',
    'RADIAL': 'f, cx, cy, k1, k2',
    'OPENCV': 'fx, fy, cx, cy, k1, k2, p1, p2',
}
#: The models that :func:`camera_matrix` turns into :math:`K` and OpenCV
#: distortion coefficients.
SUPPORTED_MODELS = tuple(_PARAMETER_NAMES)

# search order of find_colmap_model, relative to the given folder
_MODEL_PLACES = ('', osp.join('sparse', '0'), 'sparse')
_GIVE_A_MODEL = 'give the folder of a COLMAP sparse model (sparse/0)'
_EXPORT_AGAIN = ("fix the file or export the model again with 'colmap "
                 "model_converter'")
_POSE_FIELDS = ('QW', 'QX', 'QY', 'QZ', 'TX', 'TY', 'TZ')
_MAX_ID = 2 ** 32 - 1
# |R R^T - I| allowed when writing: float32 round-off, not a shear
_ROTATION_TOLERANCE = 1e-4
_CAMERA_HEADER = (
    '# COLMAP cameras, one line each:\n'
    '#   CAMERA_ID MODEL WIDTH HEIGHT PARAMS[]\n'
    '# {} cameras\n')
_IMAGE_HEADER = (
    '# COLMAP images, two lines each:\n'
    '#   IMAGE_ID QW QX QY QZ TX TY TZ CAMERA_ID NAME\n'
    '#   POINTS2D[] as X Y POINT3D_ID (none written here)\n'
    '# {} images\n')
_POINT_HEADER = (
    '# COLMAP 3D points, one line each:\n'
    '#   POINT3D_ID X Y Z R G B ERROR TRACK[] as IMAGE_ID POINT2D_IDX\n'
    '# 0 points\n')


# ------------------------------------------------------------------ finding
def find_colmap_model(folder) -> Optional[str]:
    r"""The folder of the COLMAP sparse model in ``folder``: ``folder``
    itself if it holds a ``cameras`` or ``images`` file (``.txt`` or
    ``.bin``), else ``folder/sparse/0`` (the first model COLMAP's mapper
    writes, taken when there are several), else ``folder/sparse``.

    Args:
        folder (str or os.PathLike): A model folder, or a capture folder
            with ``sparse/0/`` or ``sparse/`` in it.

    Returns:
        The model folder, or :obj:`None` where none of these holds a
        model file.
    """
    folder = os.fspath(folder)
    for place in _MODEL_PLACES:
        candidate = osp.join(folder, place) if place else folder
        if any(osp.isfile(osp.join(candidate, stem + ext))
               for stem in ('cameras', 'images') for ext in ('.bin', '.txt')):
            return candidate
    return None


def _model_file(model: str, stem: str) -> str:
    """The path of ``stem``.bin, else ``stem``.txt, in a model folder."""
    for ext in ('.bin', '.txt'):
        path = osp.join(model, stem + ext)
        if osp.isfile(path):
            return path
    raise ValueError(f"'{model}' holds no {stem}.txt or {stem}.bin: "
                     f"{_GIVE_A_MODEL}")


# ------------------------------------------------------------------ reading
def read_colmap_model(folder) -> Tuple[dict, List[dict]]:
    r"""Reads the cameras and image poses of a COLMAP sparse model, text
    or binary (where both exist, the ``.bin`` file); the 3D points are not
    read. Quaternions are normalised (COLMAP writes unit ones, up to
    round-off).

    Args:
        folder (str or os.PathLike): The model folder, or a capture folder
            holding it as ``sparse/0/`` or ``sparse/``
            (:func:`find_colmap_model`).

    Returns:
        ``(cameras, images)``: ``cameras`` a dict camera id ->
        ``dict(model=str, width=int, height=int, params=np.ndarray)``
        (float64 parameters of the model, :data:`CAMERA_MODELS`), and
        ``images`` a list, in image id order, of ``dict(image_id=int,
        name=str, camera_id=int, R=np.ndarray, t=np.ndarray)`` with the
        world-to-camera pose :math:`x_c = R x + t`, :math:`R` of shape
        :math:`(3, 3)` and :math:`t` of shape :math:`(3,)`, float64.

    Raises:
        ValueError: In one sentence naming the file (and, in text files,
            the line): a missing folder or cameras/images file, a
            truncated binary file, a field that is not a number, a wrong
            number of parameters for the camera model, an unknown model,
            a repeated id, an image whose camera is not in the cameras
            file, or a quaternion of zero length.
    """
    folder = os.fspath(folder)
    if not osp.isdir(folder):
        what = 'is a file, not a folder' if osp.exists(folder) \
            else 'does not exist'
        raise ValueError(f"'{folder}' {what}: {_GIVE_A_MODEL}")
    model = find_colmap_model(folder) or folder
    cameras_path = _model_file(model, 'cameras')
    images_path = _model_file(model, 'images')
    if cameras_path.endswith('.bin'):
        cameras = _read_cameras_binary(cameras_path)
    else:
        cameras = _read_cameras_text(cameras_path)
    if images_path.endswith('.bin'):
        rows = _read_images_binary(images_path)
    else:
        rows = _read_images_text(images_path)
    cameras_name = osp.basename(cameras_path)
    for row in rows:
        if row['camera_id'] not in cameras:
            raise ValueError(
                f"{row['where']}: image {row['image_id']} ('{row['name']}') "
                f"uses camera {row['camera_id']}, which {cameras_name} does "
                f"not hold: give the cameras and images files of one model")
    rows.sort(key=lambda row: row['image_id'])
    rotations = _quaternion_to_rotation(
        np.array([row['q'] for row in rows]).reshape(-1, 4))
    images = [dict(image_id=row['image_id'], name=row['name'],
                   camera_id=row['camera_id'], R=R, t=row['t'])
              for row, R in zip(rows, rotations)]
    return cameras, images


def _camera(where: str, camera_id: int, model: str, width: int,
            height: int, params, fix: str = _EXPORT_AGAIN) -> dict:
    """A checked camera dict; ``where`` names the file (and line) and
    ``fix`` says what to do."""
    name, count = CAMERA_MODELS[_MODEL_IDS[model]]
    params = np.asarray(params, dtype=np.float64)
    if params.shape != (count,):
        names = _PARAMETER_NAMES.get(model)
        names = f' ({names})' if names else ''
        raise ValueError(
            f"{where}: camera {camera_id} of model {model} needs {count} "
            f"parameters{names} but has {params.size}: {fix}")
    if width <= 0 or height <= 0:
        raise ValueError(f"{where}: camera {camera_id} is {width} x {height} "
                         f"pixels; width and height must be positive: "
                         f"{fix}")
    if not np.all(np.isfinite(params)):
        raise ValueError(f"{where}: camera {camera_id} has a parameter that "
                         f"is not a finite number: {fix}")
    return dict(model=name, width=int(width), height=int(height),
                params=params)


def _image(where: str, image_id: int, q, t, camera_id: int,
           name: str) -> dict:
    """A checked image row (quaternion normalised) of a reader."""
    q = np.asarray(q, dtype=np.float64)
    t = np.asarray(t, dtype=np.float64)
    if not (np.all(np.isfinite(q)) and np.all(np.isfinite(t))):
        raise ValueError(f"{where}: image {image_id} ('{name}') has a pose "
                         f"that is not finite: {_EXPORT_AGAIN}")
    norm = np.sqrt(np.sum(q * q))
    if norm < 1e-12:
        raise ValueError(f"{where}: image {image_id} ('{name}') has a "
                         f"quaternion of zero length; COLMAP writes unit "
                         f"quaternions QW QX QY QZ: {_EXPORT_AGAIN}")
    return dict(where=where, image_id=image_id, q=q / norm, t=t,
                camera_id=camera_id, name=name)


def _text_lines(path: str):
    """``(line number, stripped line)`` of a text model file."""
    with open(path, encoding='utf-8', errors='surrogateescape') as f:
        for number, line in enumerate(f, 1):
            yield number, line.strip()


def _number(where: str, text: str, field: str, kind=float):
    try:
        return kind(text)
    except ValueError:
        kind_name = 'an integer' if kind is int else 'a number'
        raise ValueError(f"{where}: {field} '{text}' is not {kind_name}: "
                         f"{_EXPORT_AGAIN}") from None


def _read_cameras_text(path: str) -> dict:
    cameras = {}
    for number, line in _text_lines(path):
        if not line or line.startswith('#'):
            continue
        where = f"'{path}' line {number}"
        fields = line.split()
        if len(fields) < 4:
            raise ValueError(f"{where}: a camera line needs CAMERA_ID MODEL "
                             f"WIDTH HEIGHT PARAMS[], got {len(fields)} "
                             f"fields: {_EXPORT_AGAIN}")
        camera_id = _number(where, fields[0], 'CAMERA_ID', int)
        model = fields[1]
        if model not in _MODEL_IDS:
            raise ValueError(f"{where}: unknown camera model '{model}'; "
                             f"COLMAP's are {', '.join(_MODEL_IDS)}: "
                             f"{_EXPORT_AGAIN}")
        width = _number(where, fields[2], 'WIDTH', int)
        height = _number(where, fields[3], 'HEIGHT', int)
        params = [_number(where, text, 'a parameter') for text in fields[4:]]
        _add(cameras, camera_id, where, 'camera',
             _camera(where, camera_id, model, width, height, params))
    return cameras


def _add(table: dict, key: int, where: str, what: str, value,
         fix: str = _EXPORT_AGAIN):
    if key in table:
        raise ValueError(f"{where}: {what} {key} appears twice; ids must be "
                         f"unique: {fix}")
    table[key] = value


def _read_images_text(path: str) -> List[dict]:
    rows, ids = [], {}
    lines = _text_lines(path)
    for number, line in lines:
        if not line or line.startswith('#'):
            continue
        where = f"'{path}' line {number}"
        fields = line.split(None, 9)
        if len(fields) < 10:
            raise ValueError(
                f"{where}: an image line needs IMAGE_ID QW QX QY QZ TX TY TZ "
                f"CAMERA_ID NAME, got {len(fields)} fields: {_EXPORT_AGAIN}")
        image_id = _number(where, fields[0], 'IMAGE_ID', int)
        numbers = [_number(where, text, field) for text, field in
                   zip(fields[1:8], _POSE_FIELDS)]
        camera_id = _number(where, fields[8], 'CAMERA_ID', int)
        _add(ids, image_id, where, 'image', None)
        rows.append(_image(where, image_id, numbers[:4], numbers[4:],
                           camera_id, fields[9]))
        # the next line holds the image's 2D points, and may be empty or
        # missing at the end of the file
        points = next(lines, None)
        if points is not None and len(points[1].split()) % 3:
            raise ValueError(
                f"'{path}' line {points[0]}: the line after image {image_id} "
                f"must hold its 2D points as X Y POINT3D_ID triples (or be "
                f"empty), but has {len(points[1].split())} fields: each "
                f"image takes two lines; {_EXPORT_AGAIN}")
    return rows


class _Bytes:
    """A cursor over a binary model file that names the file when it
    ends too early."""

    def __init__(self, path: str):
        self.path = path
        with open(path, 'rb') as f:
            self.data = f.read()
        self.offset = 0

    def take(self, size: int, what: str) -> bytes:
        if self.offset + size > len(self.data):
            raise ValueError(
                f"'{self.path}' ends after {len(self.data)} bytes, inside "
                f"{what}: the file is truncated; {_EXPORT_AGAIN}")
        start, self.offset = self.offset, self.offset + size
        return self.data[start:self.offset]

    def unpack(self, fmt: str, what: str) -> tuple:
        return struct.unpack(fmt, self.take(struct.calcsize(fmt), what))

    def string(self, what: str) -> str:
        end = self.data.find(b'\0', self.offset)
        if end < 0:  # no null byte: the name runs to the end of the file
            end = len(self.data)
        return os.fsdecode(self.take(end - self.offset + 1, what)[:-1])


def _read_cameras_binary(path: str) -> dict:
    reader = _Bytes(path)
    count, = reader.unpack('<Q', 'the number of cameras')
    cameras = {}
    for index in range(count):
        what = f'camera {index + 1} of {count}'
        camera_id, model_id, width, height = reader.unpack('<IiQQ', what)
        where = f"'{path}' ({what})"
        if model_id not in CAMERA_MODELS:
            raise ValueError(f"{where}: unknown camera model id {model_id}; "
                             f"COLMAP's are 0 to {len(CAMERA_MODELS) - 1}: "
                             f"{_EXPORT_AGAIN}")
        model, num_params = CAMERA_MODELS[model_id]
        params = reader.unpack(f'<{num_params}d', what)
        _add(cameras, camera_id, where, 'camera',
             _camera(where, camera_id, model, width, height, params))
    return cameras


def _read_images_binary(path: str) -> List[dict]:
    reader = _Bytes(path)
    count, = reader.unpack('<Q', 'the number of images')
    rows, ids = [], {}
    for index in range(count):
        what = f'image {index + 1} of {count}'
        image_id, *pose, camera_id = reader.unpack('<I7dI', what)
        name = reader.string(what)
        num_points, = reader.unpack('<Q', what)
        reader.take(24 * num_points, what)
        where = f"'{path}' ({what})"
        _add(ids, image_id, where, 'image', None)
        rows.append(_image(where, image_id, pose[:4], pose[4:], camera_id,
                           name))
    return rows


# ------------------------------------------------------------------ rotations
def _quaternion_to_rotation(q: np.ndarray) -> np.ndarray:
    """Rotation matrices :math:`(N, 3, 3)` of unit Hamilton quaternions
    :math:`(N, 4)` ordered ``w, x, y, z``."""
    w, x, y, z = q.T
    return np.stack([
        1 - 2 * (y * y + z * z), 2 * (x * y - w * z), 2 * (x * z + w * y),
        2 * (x * y + w * z), 1 - 2 * (x * x + z * z), 2 * (y * z - w * x),
        2 * (x * z - w * y), 2 * (y * z + w * x), 1 - 2 * (x * x + y * y),
    ], -1).reshape(-1, 3, 3)


def _rotation_to_quaternion(R: np.ndarray) -> np.ndarray:
    r"""Unit Hamilton quaternions :math:`(N, 4)` (``w, x, y, z``,
    :math:`w \ge 0`) of rotation matrices :math:`(N, 3, 3)`; each is
    computed from the largest of :math:`4 w^2, 4 x^2, 4 y^2, 4 z^2`
    (Shepperd's method), which keeps it accurate for every rotation."""
    r = R.reshape(-1, 9).T
    r00, r01, r02, r10, r11, r12, r20, r21, r22 = r
    # row i is 4 q_i (w, x, y, z) with q_i the i-th component
    candidates = np.stack([
        np.stack([1 + r00 + r11 + r22, r21 - r12, r02 - r20, r10 - r01], -1),
        np.stack([r21 - r12, 1 + r00 - r11 - r22, r01 + r10, r02 + r20], -1),
        np.stack([r02 - r20, r01 + r10, 1 - r00 + r11 - r22, r12 + r21], -1),
        np.stack([r10 - r01, r02 + r20, r12 + r21, 1 - r00 - r11 + r22], -1),
    ], 1)
    best = np.argmax(np.diagonal(candidates, axis1=1, axis2=2), axis=1)
    q = candidates[np.arange(len(best)), best]
    q = q / np.linalg.norm(q, axis=1, keepdims=True)
    return np.where(q[:, :1] < 0, -q, q)


# ------------------------------------------------------------------ cameras
def camera_matrix(camera: dict) -> Tuple[np.ndarray, np.ndarray]:
    r"""The pinhole matrix and OpenCV distortion coefficients of a COLMAP
    camera (a value of the ``cameras`` dict of :func:`read_colmap_model`).

    COLMAP puts the centre of the upper-left pixel at :math:`(0.5, 0.5)`,
    as this library does, so :math:`c_x, c_y` are taken as they are: no
    half-pixel shift. (OpenCV's own calibration puts it at :math:`(0, 0)`;
    these :math:`K` are not meant for it without adding 0.5.) The
    distortion is Brown-Conrady's: a normalised point :math:`(x, y)`,
    :math:`r^2 = x^2 + y^2`, goes to
    :math:`x (1 + k_1 r^2 + k_2 r^4) + 2 p_1 x y + p_2 (r^2 + 2 x^2)`,
    :math:`y (1 + k_1 r^2 + k_2 r^4) + p_1 (r^2 + 2 y^2) + 2 p_2 x y`,
    then :math:`K` maps it to pixels.

    Args:
        camera (dict): With ``model`` (one of :data:`SUPPORTED_MODELS`) and
            ``params``.

    Returns:
        ``(K, distortion)``: :math:`K` the :math:`(3, 3)` float64 matrix
        :math:`[[f_x, 0, c_x], [0, f_y, c_y], [0, 0, 1]]` and distortion
        the float64 :math:`(k_1, k_2, p_1, p_2)`: zeros for
        ``SIMPLE_PINHOLE`` and ``PINHOLE``, :math:`(k, 0, 0, 0)` for
        ``SIMPLE_RADIAL``, :math:`(k_1, k_2, 0, 0)` for ``RADIAL``.

    Raises:
        ValueError: For another model, or the wrong number of parameters.
    """
    model = camera['model']
    if model not in SUPPORTED_MODELS:
        raise ValueError(
            f"camera model '{model}' is not supported; the supported ones "
            f"are {', '.join(SUPPORTED_MODELS)}: undistort the capture with "
            f"'colmap image_undistorter', which writes PINHOLE cameras")
    p = np.asarray(camera['params'], dtype=np.float64).ravel()
    count = CAMERA_MODELS[_MODEL_IDS[model]][1]
    if p.size != count:
        raise ValueError(f"camera model {model} needs {count} parameters "
                         f"({_PARAMETER_NAMES[model]}), got {p.size}")
    if model in ('PINHOLE', 'OPENCV'):
        fx, fy, cx, cy = p[:4]
        distortion = np.zeros(4)
        distortion[:len(p) - 4] = p[4:]
    else:
        fx = fy = p[0]
        cx, cy = p[1:3]
        distortion = np.zeros(4)
        distortion[:len(p) - 3] = p[3:]
    K = np.array([[fx, 0, cx], [0, fy, cy], [0, 0, 1]], dtype=np.float64)
    return K, distortion


# ------------------------------------------------------------------ writing
def write_colmap_model(folder, cameras: dict, images: List[dict],
                       binary: bool = False) -> List[str]:
    r"""Writes a COLMAP sparse model: ``cameras``, ``images`` and an empty
    ``points3D``, as ``.txt`` files (with ``#`` header comments, numbers
    written so that they read back to the same float64) or ``.bin`` files.
    Each file is written atomically; the folder is created if missing.

    Args:
        folder (str or os.PathLike): The model folder.
        cameras (dict): Camera id -> ``dict(model, width, height,
            params)``, as :func:`read_colmap_model` returns them (any of
            :data:`CAMERA_MODELS`).
        images (list of dict): ``dict(image_id, name, camera_id, R, t)``,
            the world-to-camera pose :math:`x_c = R x + t`; written in
            image id order, as quaternions with :math:`q_w \ge 0`, and no
            2D points.
        binary (bool, optional): Write ``.bin`` files instead of ``.txt``.
            (default: :obj:`False`)

    Returns:
        The paths written: cameras, images, points3D.

    Raises:
        ValueError: For an unknown model, a wrong number of parameters, a
            repeated or out-of-range id, an image whose camera is not in
            ``cameras``, an ``R`` that is not a rotation, or a name that
            the format cannot hold (with whitespace in a text model, a
            null byte in a binary one).
    """
    folder = os.fspath(folder)
    cameras = {int(camera_id): _camera(
        'write_colmap_model', int(camera_id), camera['model'],
        int(camera['width']), int(camera['height']), camera['params'],
        'correct the camera')
        for camera_id, camera in _checked_cameras(cameras)}
    images = _checked_images(images, cameras, binary)
    rotations = np.stack([image['R'] for image in images]).reshape(-1, 3, 3) \
        if images else np.zeros((0, 3, 3))
    quaternions = _rotation_to_quaternion(rotations)
    ext = '.bin' if binary else '.txt'
    paths = [osp.join(folder, stem + ext)
             for stem in ('cameras', 'images', 'points3D')]
    if binary:
        contents = [_cameras_binary(cameras),
                    _images_binary(images, quaternions), struct.pack('<Q', 0)]
    else:
        contents = [_cameras_text(cameras), _images_text(images, quaternions),
                    _POINT_HEADER]
    mode = 'wb' if binary else 'w'
    for path, content in zip(paths, contents):
        atomic_write(path, lambda f, content=content: f.write(content), mode)
    return paths


def _checked_cameras(cameras: dict):
    for camera_id, camera in sorted(cameras.items()):
        if not 0 <= int(camera_id) <= _MAX_ID:
            raise ValueError(f"camera id {camera_id} is out of COLMAP's "
                             f"range 0 to {_MAX_ID}: renumber the cameras")
        if camera['model'] not in _MODEL_IDS:
            raise ValueError(f"camera {camera_id} has unknown model "
                             f"'{camera['model']}'; COLMAP's are "
                             f"{', '.join(_MODEL_IDS)}")
        yield camera_id, camera


def _checked_images(images: List[dict], cameras: dict,
                    binary: bool) -> List[dict]:
    checked, ids = [], {}
    for image in images:
        image_id, name = int(image['image_id']), str(image['name'])
        where = f"image {image_id} ('{name}')"
        _add(ids, image_id, where, 'image', None, 'renumber the images')
        if not 0 <= image_id <= _MAX_ID:
            raise ValueError(f"{where}: the id is out of COLMAP's range 0 "
                             f"to {_MAX_ID}: renumber the images")
        if int(image['camera_id']) not in cameras:
            raise ValueError(f"{where} uses camera {image['camera_id']}, "
                             f"which is not in 'cameras': add it")
        if (not binary and (not name or len(name.split()) != 1)) or \
                (binary and (not name or '\0' in name)):
            raise ValueError(
                f"{where}: a {'binary' if binary else 'text'} COLMAP model "
                f"cannot hold this name (empty, or with "
                f"{'a null byte' if binary else 'whitespace'})"
                f"{'' if binary else ': write it with binary=True'}")
        R = np.asarray(image['R'], dtype=np.float64)
        t = np.asarray(image['t'], dtype=np.float64).reshape(3)
        if R.shape != (3, 3) or not np.all(np.isfinite(R)) or \
                not np.all(np.isfinite(t)) or np.linalg.det(R) <= 0 or \
                np.abs(R @ R.T - np.eye(3)).max() > _ROTATION_TOLERANCE:
            raise ValueError(f"{where}: R must be a (3, 3) rotation and t "
                             f"(3,), finite: give a world-to-camera pose")
        checked.append(dict(image_id=image_id, name=name,
                            camera_id=int(image['camera_id']), R=R, t=t))
    return sorted(checked, key=lambda image: image['image_id'])


def _numbers(values) -> str:
    return ' '.join(repr(float(value)) for value in values)


def _cameras_text(cameras: dict) -> str:
    lines = [_CAMERA_HEADER.format(len(cameras))]
    for camera_id, camera in cameras.items():
        lines.append(f"{camera_id} {camera['model']} {camera['width']} "
                     f"{camera['height']} {_numbers(camera['params'])}\n")
    return ''.join(lines)


def _images_text(images: List[dict], quaternions: np.ndarray) -> str:
    lines = [_IMAGE_HEADER.format(len(images))]
    for image, q in zip(images, quaternions):
        lines.append(f"{image['image_id']} {_numbers(q)} "
                     f"{_numbers(image['t'])} {image['camera_id']} "
                     f"{image['name']}\n\n")
    return ''.join(lines)


def _cameras_binary(cameras: dict) -> bytes:
    parts = [struct.pack('<Q', len(cameras))]
    for camera_id, camera in cameras.items():
        parts.append(struct.pack(
            f"<IiQQ{len(camera['params'])}d", camera_id,
            _MODEL_IDS[camera['model']], camera['width'], camera['height'],
            *camera['params']))
    return b''.join(parts)


def _images_binary(images: List[dict], quaternions: np.ndarray) -> bytes:
    parts = [struct.pack('<Q', len(images))]
    for image, q in zip(images, quaternions):
        parts += [struct.pack('<I7dI', image['image_id'], *q, *image['t'],
                              image['camera_id']),
                  os.fsencode(image['name']) + b'\0', struct.pack('<Q', 0)]
    return b''.join(parts)


def _mask_of(masks: str, name: str) -> Optional[str]:
    """The mask of photograph ``name`` in ``masks/``: COLMAP's
    ``<name>.png``, or the same name, or ``<stem>.png``."""
    for candidate in (name + '.png', name,
                      osp.splitext(name)[0] + '.png'):
        path = osp.join(masks, candidate)
        if osp.isfile(path):
            return path
    return None


def colmap_spec(path) -> CaptureSpec:
    """The views of a COLMAP capture: the model (in ``path``,
    ``path/sparse/0`` or ``path/sparse``), the photographs in
    ``path/images/`` (or beside the model) and masks in ``path/masks/``
    where present. Photographs the model lists but that are missing raise
    a :class:`ValueError` naming them; photographs it does not list (not
    registered) are named in the notes."""
    folder = os.fspath(path)
    model = find_colmap_model(folder)
    if model is None:
        raise ValueError(f"'{folder}' holds no COLMAP model (cameras, "
                         f"images and points3D as .txt or .bin, here or in "
                         f"sparse/0/)")
    cameras, images = read_colmap_model(model)
    photographs = osp.join(folder, 'images')
    if not osp.isdir(photographs):
        photographs = folder
    masks = osp.join(folder, 'masks')
    views, missing = [], []
    for image in images:
        K, distortion = camera_matrix(cameras[image['camera_id']])
        camera = cameras[image['camera_id']]
        file = osp.join(photographs, image['name'])
        if why_not_a_file(file):
            missing.append(image['name'])
            continue
        views.append(CaptureView(
            file, K, image['R'], image['t'],
            distortion if distortion.any() else None,
            _mask_of(masks, image['name']) if osp.isdir(masks) else None,
            (camera['height'], camera['width'])))
    if missing:
        shown = ', '.join(f"'{n}'" for n in missing[:3])
        raise ValueError(
            f"the COLMAP model '{model}' lists {len(missing)} photograph(s) "
            f"that '{photographs}' does not hold: {shown}"
            f"{' ...' if len(missing) > 3 else ''}; put them there (the "
            f"folder COLMAP read them from) or give the capture folder "
            f"that holds images/")
    listed = {osp.normpath(image['name']) for image in images}
    unlisted = sorted(
        osp.relpath(osp.join(top, n), photographs)
        for top, _, names in os.walk(photographs) for n in names
        if osp.splitext(n)[1].lower() in LDR_EXTENSIONS + HDR_EXTENSIONS
        and osp.normpath(osp.relpath(osp.join(top, n), photographs))
        not in listed and top.startswith(photographs)) \
        if photographs != folder else []
    notes = []
    if unlisted:
        shown = ', '.join(unlisted[:3])
        notes.append(f"{len(unlisted)} photograph(s) in images/ are not in "
                     f"the model (not registered), left out: {shown}"
                     f"{' ...' if len(unlisted) > 3 else ''}")
    return CaptureSpec('colmap', model, folder, views, notes=notes)


def read_colmap(path, **options):
    r"""Reads a COLMAP capture (:func:`colmap_spec`) into the
    :class:`~torch_geometric.data.Data` of
    :func:`~tg_intrinsic.io.read_scene`; distorted photographs (SIMPLE_RADIAL,
    RADIAL, OPENCV) are undistorted into pinhole ones of the same K.

    Args:
        path (str): The capture folder.
        **options: Of :func:`~tg_intrinsic.io.capture_views.assemble_capture`
            (``geometry``, ``envmap``, ``exposure``, ``gamma``,
            ``envmap_rotation``, ``up``, ``dtype``).
    """
    return assemble_capture(colmap_spec(path), **options)
