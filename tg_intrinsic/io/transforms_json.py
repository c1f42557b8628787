r"""``transforms.json`` captures: the NeRF/Blender synthetic convention and
nerfstudio's (instant-ngp, Polycam, Record3D and ``ns-process-data``
write it).

* **NeRF/Blender**: ``camera_angle_x`` (horizontal field of view, radians)
  and per frame ``file_path`` (relative to the file, often without its
  extension) and ``transform_matrix``, the 4 x 4 camera-to-world matrix of
  an OpenGL camera (:math:`x` right, :math:`y` up, looking along
  :math:`-z`). The principal point is the image centre
  :math:`(W/2, H/2)` and :math:`f = \frac{W/2}{\tan(\mathrm{camera\_angle\_x}
  / 2)}`. The world is Blender's, :math:`z` up, and its environment maps
  follow Blender's equirectangular convention
  (:func:`~tg_intrinsic.geometry.appearance.envmap.blender_envmap`).
* **nerfstudio**: ``fl_x, fl_y, cx, cy, w, h`` in pixels at the top or
  per frame (a frame's values win), distortion ``k1 k2 p1 p2`` with
  ``camera_model`` ``OPENCV`` (or ``PINHOLE``), ``mask_path`` per frame,
  and ``applied_transform``, the 3 x 4 transform nerfstudio applied to the
  original (COLMAP) world: it is undone, so the cameras meet a mesh made in
  that world. ``cx, cy`` are continuous coordinates (nerfstudio's rays
  pass through pixel + 0.5), taken as they are.

Either may give a frame its own environment map, ``hdri_path`` (relative
to the file, as the NeRD datasets do): every photograph is then recovered
under its own lighting (``data.envmaps`` and ``data.view_lighting``).

Both turn into OpenCV cameras (:math:`R_{cv} = R_{gl}\,
\mathrm{diag}(1, -1, -1)`) with pixel centres at half-integers.
"""
import json
import math
import os
import os.path as osp
from typing import List, Optional

import numpy as np

from .capture_files import (HDR_EXTENSIONS, read_hdr_photograph,
                            read_json, why_not_a_file)
from .capture_views import CaptureSpec, CaptureView, assemble_capture
from .photographs import LDR_EXTENSIONS

__all__ = ['TRANSFORMS_FILES', 'find_transforms', 'transforms_spec',
           'read_transforms', 'write_transforms']

#: The names a transforms file goes by, in the order they are looked for.
TRANSFORMS_FILES = ('transforms.json', 'transforms_train.json')
_GL_TO_CV = np.diag([1.0, -1.0, -1.0])
_INTRINSICS = ('fl_x', 'fl_y', 'cx', 'cy', 'w', 'h')
_DISTORTION = ('k1', 'k2', 'p1', 'p2')


def find_transforms(path) -> Optional[str]:
    """The transforms file at ``path``: the file itself, or the first of
    :data:`TRANSFORMS_FILES` in the folder; :obj:`None` when there is
    none."""
    path = os.fspath(path)
    if osp.isfile(path) and path.lower().endswith('.json') and \
            osp.basename(path) != 'cameras.json':
        return path
    for name in TRANSFORMS_FILES:
        if osp.isfile(osp.join(path, name)):
            return osp.join(path, name)
    return None


def _load(path: str) -> dict:
    spec = read_json(path)
    if not isinstance(spec, dict) or not isinstance(spec.get('frames'),
                                                    list) \
            or not spec['frames']:
        raise ValueError(f"'{path}' must be an object with a non-empty "
                         f"\"frames\" list (one entry per photograph with "
                         f"\"file_path\" and \"transform_matrix\")")
    return spec


def convention(spec: dict) -> str:
    """``'nerfstudio'`` when the file gives focal lengths in pixels
    (``fl_x``, at the top or in a frame), else ``'nerf'``."""
    if 'fl_x' in spec or any(isinstance(f, dict) and 'fl_x' in f
                             for f in spec['frames']):
        return 'nerfstudio'
    return 'nerf'


def _number(value, name: str, where: str) -> float:
    try:
        number = float(value)
    except (TypeError, ValueError):
        raise ValueError(f"{where}: \"{name}\" must be a number, got "
                         f"{json.dumps(value)[:40]}") from None
    if not math.isfinite(number):
        raise ValueError(f"{where}: \"{name}\" is not finite")
    return number


def _photograph(folder: str, file_path: str, where: str) -> str:
    """The photograph of ``file_path``, which may lack its extension."""
    if not isinstance(file_path, str) or not file_path:
        raise ValueError(f"{where}: \"file_path\" must be a file name, got "
                         f"{file_path!r}")
    path = osp.normpath(osp.join(folder, file_path))
    if osp.isfile(path):
        return path
    if not osp.splitext(path)[1]:
        for extension in HDR_EXTENSIONS + LDR_EXTENSIONS:
            for candidate in (path + extension, path + extension.upper()):
                if osp.isfile(candidate):
                    return candidate
    raise ValueError(f"{where} names the photograph '{file_path}', but "
                     f"'{path}' {why_not_a_file(path)}")


def _pose(frame: dict, where: str, undo: Optional[np.ndarray]):
    """World-to-camera (R, t) of an OpenGL camera-to-world matrix."""
    try:
        matrix = np.asarray(frame['transform_matrix'], dtype=np.float64)
    except KeyError:
        raise ValueError(f"{where} has no \"transform_matrix\"") from None
    except (TypeError, ValueError):
        raise ValueError(f"{where}: \"transform_matrix\" must be a 4 x 4 "
                         f"matrix of numbers") from None
    if matrix.shape not in ((4, 4), (3, 4)) or \
            not np.isfinite(matrix).all():
        raise ValueError(f"{where}: \"transform_matrix\" must be a finite "
                         f"4 x 4 matrix, got shape {list(matrix.shape)}")
    rotation, centre = matrix[:3, :3], matrix[:3, 3]
    if undo is not None:  # back to the world before applied_transform
        rotation, centre = undo[:, :3] @ rotation, undo[:, :3] @ centre \
            + undo[:, 3]
    scale = np.linalg.norm(rotation, axis=0)
    if np.any(scale < 1e-12) or np.abs(scale - scale.mean()).max() > \
            1e-4 * scale.mean() or np.linalg.det(rotation) <= 0:
        raise ValueError(f"{where}: \"transform_matrix\" is not a rotation "
                         f"and a translation (column lengths "
                         f"{np.round(scale, 4).tolist()})")
    rotation = rotation / scale  # a uniformly scaled world keeps its shape
    R = (rotation @ _GL_TO_CV).T
    return R, -R @ centre


def _applied_transform_inverse(spec: dict, path: str):
    value = spec.get('applied_transform')
    if value is None:
        return None
    matrix = np.asarray(value, dtype=np.float64)
    if matrix.shape == (4, 4):
        matrix = matrix[:3]
    if matrix.shape != (3, 4) or not np.isfinite(matrix).all():
        raise ValueError(f"'{path}': \"applied_transform\" must be a 3 x 4 "
                         f"matrix, got shape {list(matrix.shape)}")
    inverse = np.linalg.inv(matrix[:, :3])
    return np.concatenate([inverse, -inverse @ matrix[:, 3:]], 1)


def _image_size(path: str):
    """(H, W) of a photograph; an LDR file's header is enough."""
    if osp.splitext(path)[1].lower() in HDR_EXTENSIONS:
        return read_hdr_photograph(path).shape[:2]
    from PIL import Image
    try:
        with Image.open(path) as image:
            return image.height, image.width
    except OSError as error:
        raise ValueError(f"could not read '{path}': {error}") from None


def _intrinsics(spec: dict, frame: dict, image: str, style: str,
                where: str):
    """K (3, 3), distortion (4,) or None, and the declared (H, W)."""
    merged = {**spec, **frame}
    if style == 'nerf':
        height, width = (int(merged['h']), int(merged['w'])) \
            if 'w' in merged and 'h' in merged else _image_size(image)
        if 'camera_angle_x' not in merged:
            raise ValueError(f"{where}: no \"camera_angle_x\" (NeRF/Blender"
                             f") or \"fl_x\" (nerfstudio), so the focal "
                             f"length is unknown")
        fx = 0.5 * width / math.tan(0.5 * _number(
            merged['camera_angle_x'], 'camera_angle_x', where))
        fy = fx if 'camera_angle_y' not in merged else 0.5 * height / \
            math.tan(0.5 * _number(merged['camera_angle_y'],
                                   'camera_angle_y', where))
        K = np.array([[fx, 0, width / 2], [0, fy, height / 2], [0, 0, 1]])
        return K, None, (height, width)
    missing = [k for k in _INTRINSICS if k not in merged]
    if missing:
        raise ValueError(f"{where} has no {', '.join(missing)} (nerfstudio "
                         f"cameras need fl_x, fl_y, cx, cy, w and h, at the "
                         f"top or in the frame)")
    fx, fy, cx, cy, w, h = (_number(merged[k], k, where)
                            for k in _INTRINSICS)
    model = merged.get('camera_model', 'OPENCV')
    if model not in ('OPENCV', 'PINHOLE'):
        raise ValueError(f"{where}: camera_model {model!r} is not supported"
                         f" (OPENCV and PINHOLE are); undistort the "
                         f"photographs first (ns-process-data can)")
    distortion = np.array([_number(merged.get(k, 0.0), k, where)
                           for k in _DISTORTION])
    K = np.array([[fx, 0, cx], [0, fy, cy], [0, 0, 1]])
    return K, (distortion if distortion.any() else None), (int(h), int(w))


def transforms_spec(path, style: Optional[str] = None) -> CaptureSpec:
    """The views of a transforms file (or of the folder holding one), in
    the NeRF/Blender or nerfstudio convention (``style``; by default
    detected: nerfstudio when it gives ``fl_x``)."""
    folder_or_file = os.fspath(path)
    path = find_transforms(folder_or_file)
    if path is None:
        raise ValueError(f"'{folder_or_file}' holds no "
                         f"{' or '.join(TRANSFORMS_FILES)}")
    spec = _load(path)
    style = style or convention(spec)
    folder = osp.dirname(osp.abspath(path))
    undo = _applied_transform_inverse(spec, path) \
        if style == 'nerfstudio' else None
    views: List[CaptureView] = []
    for i, frame in enumerate(spec['frames']):
        where = f"'{path}', frame {i}"
        if not isinstance(frame, dict):
            raise ValueError(f"{where} must be an object with \"file_path\""
                             f" and \"transform_matrix\"")
        image = _photograph(folder, frame.get('file_path'), where)
        K, distortion, size = _intrinsics(spec, frame, image, style, where)
        R, t = _pose(frame, where, undo)
        mask = frame.get('mask_path')
        if mask is not None:
            mask = osp.normpath(osp.join(folder, mask))
            why = why_not_a_file(mask)
            if why:
                raise ValueError(f"{where} names the mask "
                                 f"'{frame['mask_path']}', but '{mask}' "
                                 f"{why}")
        lighting = frame.get('hdri_path')
        if lighting is not None:
            lighting = osp.normpath(osp.join(folder, str(lighting)))
            why = why_not_a_file(lighting)
            if why:
                raise ValueError(f"{where} names the environment map "
                                 f"'{frame['hdri_path']}', but '{lighting}'"
                                 f" {why}")
        views.append(CaptureView(image, K, R, t, distortion, mask, size,
                                 lighting))
    notes = [] if undo is None else [
        'applied_transform undone: cameras in the original world']
    return CaptureSpec(style, path, folder, views,
                       envmap_convention='blender' if style == 'nerf'
                       else 'tg', notes=notes)


def read_transforms(path, style: Optional[str] = None, **options):
    r"""Reads a ``transforms.json`` capture (see the module) into the
    :class:`~torch_geometric.data.Data` of
    :func:`~tg_intrinsic.io.read_scene`.

    Args:
        path (str): The transforms file, or a folder holding
            ``transforms.json`` or ``transforms_train.json``.
        style (str, optional): ``'nerf'`` or ``'nerfstudio'``; detected
            when :obj:`None`. (default: :obj:`None`)
        **options: Of :func:`~tg_intrinsic.io.capture_views.assemble_capture`
            (``geometry``, ``envmap``, ``exposure``, ``gamma``,
            ``envmap_rotation``, ``up``, ``dtype``).
    """
    return assemble_capture(transforms_spec(path, style), **options)


def write_transforms(folder, views: List[dict], style: str, size,
                     name: str = TRANSFORMS_FILES[0]) -> str:
    """Writes a transforms file for ``views`` (dicts of ``image``, a path
    relative to ``folder``, ``K``, ``R``, ``t`` and optionally ``mask``) of
    photographs of ``size`` (H, W) in the ``'nerf'`` convention (all
    cameras one centred pinhole with equal focal lengths) or
    ``'nerfstudio'``'s; returns its path."""
    from tg_intrinsic.utils import atomic_write_json
    frames = []
    for view in views:
        R, t = np.asarray(view['R']), np.asarray(view['t'])
        c2w = np.eye(4)
        c2w[:3, :3] = R.T @ _GL_TO_CV
        c2w[:3, 3] = -R.T @ t
        frame = {'file_path': view['image'],
                 'transform_matrix': c2w.tolist()}
        if style == 'nerfstudio':
            K = np.asarray(view['K'])
            frame.update(fl_x=K[0, 0], fl_y=K[1, 1], cx=K[0, 2],
                         cy=K[1, 2])
            if view.get('mask'):
                frame['mask_path'] = view['mask']
        frames.append(frame)
    height, width = size
    if style == 'nerf':
        K = np.asarray(views[0]['K'])
        spec = {'camera_angle_x': 2 * math.atan(0.5 * width / K[0, 0])}
    else:
        spec = {'camera_model': 'OPENCV', 'w': int(width), 'h': int(height)}
    spec['frames'] = frames
    path = osp.join(os.fspath(folder), name)
    atomic_write_json(path, spec)
    return path
