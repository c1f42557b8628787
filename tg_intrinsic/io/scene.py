r"""Multi-view HDR captures on disk: a *scene folder* holds the surface, the
lighting, linear HDR photographs and their calibrated cameras, which
:func:`read_scene` turns into the :class:`~torch_geometric.data.Data` that
:class:`~tg_intrinsic.transforms.ProjectViews` needs (and
:func:`write_scene` writes), for frequency-domain SVBRDF recovery
(Wiersma et al., SIGGRAPH 2025) and ``tg-intrinsic svbrdf``.

Cameras follow the OpenCV convention of
:mod:`tg_intrinsic.geometry.appearance.cameras`: :math:`x_c = R x + t` maps a
world point to camera coordinates, the camera looks along :math:`+z_c` with
:math:`x_c` right and :math:`y_c` down in the image, and
:math:`(u, v) = (f_x x_c / z_c + c_x, f_y y_c / z_c + c_y)` in pixels
where pixel (row :math:`i`, column :math:`j`) covers
:math:`u \in [j, j + 1)`, :math:`v \in [i, i + 1)`: its centre is at
:math:`(j + \frac12, i + \frac12)`. (OpenCV puts pixel centres at
integers: add 0.5 to its :math:`c_x, c_y`; COLMAP's, NeRF's and
nerfstudio's are at half-integers, as here.) The environment map is
equirectangular with world :math:`z` up, as in
:mod:`tg_intrinsic.geometry.appearance.envmap`. All radiance is linear: 8-bit
or tone-mapped photographs are not HDR.

The format (:data:`FORMAT`, also shown by ``tg-intrinsic svbrdf --help``):
"""
import json
import os
import os.path as osp
import re
import warnings
from typing import List, Optional

import numpy as np
import torch
from torch_geometric.data import Data

from tg_intrinsic.utils import atomic_write, atomic_write_file

from .capture_files import (ENVMAP_EXTENSIONS, HDR_EXTENSIONS,
                            find_single_file, is_candidate, read_json,
                            read_envmap_file, read_geometry_file,
                            read_hdr_photograph, why_not_a_file)
from .hdr import looks_clipped, write_hdr
from .mesh import MESH_EXTENSIONS, write_ply

__all__ = ['FORMAT', 'read_scene', 'write_scene', 'scene_summary',
           'scene_files']

#: The scene folder that :func:`read_scene` reads and :func:`write_scene`
#: writes, as ``tg-intrinsic svbrdf --help`` shows it.
FORMAT = r"""SCENE/
  cameras.json       the cameras, and which file is each photograph (required)
  geometry.ply       the surface: a mesh, or a point cloud (with normals
                     nx ny nz, else they are estimated); OBJ, OFF, PLY or STL;
                     a mesh's UVs (OBJ vt, PLY s t) carry the textures
  envmap.exr         the lighting: an equirectangular linear HDR image
                     [H, W, 3] (W = 2 H, row 0 looks up, +z); .hdr, .exr, .npy
  images/
    000.exr          one linear HDR photograph [H, W, 3] per camera, all of
    001.exr          one size, row 0 at the top; .exr, .hdr or .npy (float)
    ...
  ground_truth.npz   optional (synthetic scenes): base_color [N, 3],
                     metallic [N], roughness [N] per point of the geometry

cameras.json:
  {
    "geometry": "geometry.ply",               (optional, see below)
    "envmap": "envmap.exr",                   (optional, see below)
    "cameras": [
      {"image": "images/000.exr",             (path relative to SCENE)
       "K": [[fx, 0, cx], [0, fy, cy], [0, 0, 1]],          (pixels)
       "R": [[r00, r01, r02], [r10, r11, r12], [r20, r21, r22]],
       "t": [tx, ty, tz]},                   (x_cam = R x_world + t)
      ...
    ]
  }

A bare list of cameras is the same without "geometry" and "envmap"; other
keys are ignored. Without "geometry", SCENE must hold exactly one
.obj/.off/.ply/.stl file; without "envmap", exactly one .hdr/.exr/.npy
file besides the photographs. A folder of photographs must hold no
photograph that cameras.json does not list. Cameras are OpenCV's
(world-to-camera [R | t], +z forward, y down) with pixel centres at
half-integers (add 0.5 to OpenCV's cx, cy; COLMAP's are as here)."""

__doc__ += '\n::\n\n' + '\n'.join(
    '    ' + line if line else '' for line in FORMAT.split('\n')) + '\n'

CAMERAS_FILE = 'cameras.json'
GROUND_TRUTH_FILE = 'ground_truth.npz'
IMAGE_FORMATS = ('exr', 'hdr', 'npy')
# what a file of each kind is written as by write_scene
GEOMETRY_NAME = 'geometry.ply'
IMAGE_FOLDER = 'images'
# |R R^T - I| allowed in cameras.json: float32 round-off, not a shear
ROTATION_TOLERANCE = 1e-4
_NUMBERED = re.compile(r'^\d{3,}\.(exr|hdr|npy)$')


# ------------------------------------------------------------------ reading
def read_scene(folder, dtype: torch.dtype = torch.float32) -> Data:
    r"""Reads a scene folder (see :data:`FORMAT`): the geometry, the
    environment map, the linear HDR photographs and their cameras.

    Normals are the file's (PLY vertex properties ``nx ny nz``) when it has
    them; otherwise area-weighted vertex normals of a mesh
    (:func:`~tg_intrinsic.geometry.vertex_normals`) or PCA normals of a
    point cloud oriented outwards
    (:func:`~tg_intrinsic.geometry.estimate_normals` with 10 neighbours).
    Pixels may be NaN (missing; :class:`~tg_intrinsic.transforms.ProjectViews`
    masks them out). Photographs that look 8-bit or clipped
    (:func:`~tg_intrinsic.io.looks_clipped`) raise a :class:`UserWarning`
    that names them, as ``ProjectViews`` does.

    Args:
        folder (str or os.PathLike): The scene folder.
        dtype (torch.dtype, optional): Of ``pos``, ``normal``, the cameras
            and ``envmap`` (``images`` are float32).
            (default: :obj:`torch.float32`)

    Returns:
        :class:`~torch_geometric.data.Data` with ``pos`` :math:`(N, 3)`,
        ``normal`` :math:`(N, 3)` (unit), ``face`` :math:`(3, F)` (meshes
        only), ``face_uv`` :math:`(3, F, 2)` (meshes with texture
        coordinates, :func:`~tg_intrinsic.io.read_face_uv`), ``images``
        :math:`(V, H, W, 3)`, ``intrinsics`` :math:`(V, 3, 3)`,
        ``extrinsics`` :math:`(V, 3, 4)` (world to camera) and ``envmap``
        :math:`(H_e, W_e, 3)`.

    Raises:
        ValueError: Naming the file and the problem: a missing folder or
            cameras.json, malformed cameras.json (not JSON, missing keys,
            wrong shapes, non-finite numbers, a K that is not a pinhole
            matrix, an R that is not a rotation), a listed photograph that
            is missing or an unlisted one beside them, photographs of
            different sizes, without 3 channels, not floating point, or
            with infinite or negative radiance, no photograph with a pixel
            above 0, an environment map of the wrong shape (not
            [H, 2 H, 3]) or black everywhere, no geometry file or several candidates, and a
            folder where a file belongs.
    """
    if dtype not in (torch.float32, torch.float64):
        raise ValueError(f"'dtype' must be torch.float32 or torch.float64, "
                         f"got {dtype}")
    folder = os.fspath(folder)
    spec, files, geometry, envmap_file = _locate(folder)
    named_in = f'named in {CAMERAS_FILE}'
    pos, face, normal, face_uv = read_geometry_file(
        _resolve(folder, geometry), named_in)
    envmap = read_envmap_file(_resolve(folder, envmap_file), named_in)
    images = _read_images(folder, files)
    intrinsics = torch.as_tensor(np.stack([c['K'] for c in spec['cameras']]),
                                 dtype=dtype)
    extrinsics = torch.as_tensor(np.stack([
        np.concatenate([c['R'], c['t'][:, None]], 1)
        for c in spec['cameras']]), dtype=dtype)
    data = Data(pos=pos.to(dtype), normal=normal.to(dtype), images=images,
                intrinsics=intrinsics, extrinsics=extrinsics,
                envmap=envmap.to(dtype))
    if face is not None:
        data.face = face
    if face_uv is not None:
        data.face_uv = face_uv.to(dtype)
    return data


def scene_files(folder) -> List[str]:
    """The files :func:`read_scene` reads from a scene folder:
    cameras.json, the geometry, the environment map and the photographs
    (which may lie outside the folder). Raises the same errors for a
    malformed folder."""
    folder = os.fspath(folder)
    spec, files, geometry, envmap = _locate(folder)
    return [osp.join(folder, CAMERAS_FILE), _resolve(folder, geometry),
            _resolve(folder, envmap)] + [_resolve(folder, n) for n in files]


def _locate(folder: str):
    """The checked cameras.json, the listed photographs, the geometry
    file and the environment-map file of a scene folder."""
    if not osp.exists(folder):
        raise ValueError(f"the scene folder '{folder}' does not exist")
    if not osp.isdir(folder):
        raise ValueError(f"'{folder}' is a file, not a scene folder (a "
                         f"folder with {CAMERAS_FILE}, the geometry, the "
                         f"environment map and the photographs)")
    spec = _read_cameras_json(folder)
    files = [camera['image'] for camera in spec['cameras']]
    _check_image_folders(folder, files)
    geometry = spec['geometry'] or find_single_file(
        folder, MESH_EXTENSIONS, set(), 'geometry (mesh or point cloud)',
        f'as "geometry" in {CAMERAS_FILE}')
    envmap = spec['envmap'] or find_single_file(
        folder, ENVMAP_EXTENSIONS, set(files), 'environment-map',
        f'as "envmap" in {CAMERAS_FILE}')
    return spec, files, geometry, envmap


def _resolve(folder: str, name: str) -> str:
    return name if osp.isabs(name) else osp.join(folder, name)


def _read_cameras_json(folder: str) -> dict:
    """The parsed, checked cameras.json: ``{'cameras': [{'image', 'K',
    'R', 't'}], 'geometry': name or None, 'envmap': name or None}``."""
    path = osp.join(folder, CAMERAS_FILE)
    if osp.isdir(path):
        raise ValueError(f"'{path}' is a folder, not a file: a scene folder "
                         f"needs the file {CAMERAS_FILE} listing every "
                         f"photograph with its camera (K, R, t); run "
                         f"'tg-intrinsic svbrdf --write-example DIR' to see "
                         f"the format")
    if not osp.isfile(path):
        raise ValueError(f"'{folder}' has no {CAMERAS_FILE}: a scene folder "
                         f"needs one listing every photograph with its "
                         f"camera (K, R, t); run 'tg-intrinsic svbrdf "
                         f"--write-example DIR' to see the format")
    spec = read_json(path)
    if isinstance(spec, list):
        spec = {'cameras': spec}
    if not isinstance(spec, dict):
        raise ValueError(f"'{path}' must hold an object with a \"cameras\" "
                         f"list (or a list of cameras), got "
                         f"{type(spec).__name__}")
    cameras = spec.get('cameras')
    if not isinstance(cameras, list) or not cameras:
        raise ValueError(f"'{path}' must have a non-empty \"cameras\" list "
                         f"(one entry per photograph with \"image\", \"K\", "
                         f"\"R\" and \"t\")")
    for key in ('geometry', 'envmap'):
        if spec.get(key) is not None and not (
                isinstance(spec[key], str) and spec[key]):
            raise ValueError(f"'{path}': \"{key}\" must be a file name, got "
                             f"{spec[key]!r}")
    checked, seen = [], {}
    for i, camera in enumerate(cameras):
        where = f"'{path}', camera {i}"
        if not isinstance(camera, dict):
            raise ValueError(f"{where} must be an object with \"image\", "
                             f"\"K\", \"R\" and \"t\", got "
                             f"{type(camera).__name__}")
        missing = [k for k in ('image', 'K', 'R', 't') if k not in camera]
        if missing:
            raise ValueError(f"{where} has no {', '.join(map(repr, missing))}"
                             f" (each camera needs \"image\", \"K\" (3x3), "
                             f"\"R\" (3x3) and \"t\" (3))")
        image = camera['image']
        if not isinstance(image, str) or not image:
            raise ValueError(f"{where}: \"image\" must be a file name, got "
                             f"{image!r}")
        key = osp.normpath(_resolve(folder, image))
        if key in seen:
            raise ValueError(f"{where} lists the image '{image}' again "
                             f"(camera {seen[key]} has it); every camera "
                             f"needs its own photograph")
        seen[key] = i
        K = _matrix(camera['K'], (3, 3), 'K', where)
        R = _matrix(camera['R'], (3, 3), 'R', where)
        t = _matrix(camera['t'], (3, ), 't', where)
        if not (K[0, 0] > 0 and K[1, 1] > 0):
            raise ValueError(f"{where}: \"K\" must have positive focal "
                             f"lengths K[0][0] and K[1][1] (in pixels), got "
                             f"{K[0, 0]:g} and {K[1, 1]:g}")
        if not np.allclose(K[2], (0, 0, 1), atol=1e-6) or K[1, 0] != 0:
            raise ValueError(f"{where}: \"K\" must be a pinhole matrix "
                             f"[[fx, s, cx], [0, fy, cy], [0, 0, 1]], got "
                             f"{K.tolist()}")
        error = np.abs(R @ R.T - np.eye(3)).max()
        if error > ROTATION_TOLERANCE or np.linalg.det(R) <= 0:
            raise ValueError(f"{where}: \"R\" must be a rotation (orthonormal"
                             f" with determinant +1), but |R R^T - I| = "
                             f"{error:.2g} and det R = {np.linalg.det(R):.3g};"
                             f" give the world-to-camera rotation of x_cam = "
                             f"R x + t")
        checked.append({'image': image, 'K': K, 'R': R, 't': t})
    return {'cameras': checked, 'geometry': spec.get('geometry'),
            'envmap': spec.get('envmap')}


def _matrix(value, shape, name: str, where: str) -> np.ndarray:
    what = 'a 3x3 matrix' if len(shape) == 2 else 'a list of 3 numbers'
    try:
        array = np.asarray(value, dtype=np.float64)
    except (TypeError, ValueError):
        raise ValueError(f"{where}: \"{name}\" must be {what}, got "
                         f"{json.dumps(value)[:60]}") from None
    if array.shape != shape:
        raise ValueError(f"{where}: \"{name}\" must be {what}, got shape "
                         f"{list(array.shape)}")
    if not np.isfinite(array).all():
        raise ValueError(f"{where}: \"{name}\" holds NaN or infinite values")
    return array


def _check_image_folders(folder: str, files: List[str]):
    """Every listed image exists, and a folder of images (other than the
    scene folder itself, which also holds the envmap) holds no unlisted
    image."""
    listed = {}
    for i, name in enumerate(files):
        path = _resolve(folder, name)
        why = why_not_a_file(path)
        if why:
            raise ValueError(f"camera {i} of '{osp.join(folder, CAMERAS_FILE)}"
                             f"' lists the image '{name}', but '{path}' "
                             f"{why}")
        parent = osp.realpath(osp.dirname(osp.abspath(path)))
        listed.setdefault(parent, set()).add(osp.basename(path))
    top = osp.realpath(folder)
    for parent, names in listed.items():
        if parent == top:
            continue
        present = {n for n in os.listdir(parent)
                   if is_candidate(n, HDR_EXTENSIONS)}
        extra = sorted(present - names)
        if extra:
            shown = ', '.join(f"'{n}'" for n in extra[:3])
            raise ValueError(
                f"'{osp.join(folder, CAMERAS_FILE)}' lists {len(files)} "
                f"camera(s) but '{parent}' holds {len(present)} image(s): "
                f"{shown}{' ...' if len(extra) > 3 else ''} "
                f"{'has' if len(extra) == 1 else 'have'} no camera; add "
                f"{'it' if len(extra) == 1 else 'them'} to cameras.json or "
                f"move {'it' if len(extra) == 1 else 'them'} out of the "
                f"folder")


def _read_images(folder: str, files: List[str]) -> torch.Tensor:
    images, clipped, first = [], [], None
    for name in files:
        path = _resolve(folder, name)
        image = read_hdr_photograph(path)
        if first is None:
            first = (name, image.shape[:2])
        elif image.shape[:2] != first[1]:
            raise ValueError(
                f"'{path}' is {image.shape[0]} x {image.shape[1]} pixels but "
                f"'{first[0]}' is {first[1][0]} x {first[1][1]}; all "
                f"photographs must have one size (resize or crop them and "
                f"adjust K)")
        if looks_clipped(image):
            clipped.append(name)
        images.append(image)
    if not any(bool((image > 0).any()) for image in images):
        raise ValueError(f"no photograph listed in "
                         f"'{osp.join(folder, CAMERAS_FILE)}' has a pixel "
                         f"above 0 (all are 0, or NaN for missing), so there "
                         f"is no light to fit; export them as linear HDR "
                         f"radiance")
    if clipped:
        shown = ', '.join(f"'{n}'" for n in clipped[:3])
        warnings.warn(f"{len(clipped)} of {len(files)} photographs look "
                      f"low-dynamic-range (values on a 1/255 grid or piled up"
                      f" at a maximum <= 1): {shown}"
                      f"{' ...' if len(clipped) > 3 else ''}; the recovery "
                      f"assumes linear, unclipped HDR radiance, so "
                      f"highlights will be underestimated", UserWarning,
                      stacklevel=3)
    return torch.from_numpy(np.stack(images))


# ------------------------------------------------------------------ writing
def write_scene(folder, data: Data, image_format: Optional[str] = None
                ) -> List[str]:
    r"""Writes a capture as a scene folder (see :data:`FORMAT`) that
    :func:`read_scene` reads back: ``geometry.ply`` (binary, double
    positions, normals as ``nx ny nz``, the triangles of a mesh),
    ``envmap.<ext>``, ``images/000.<ext>``, ... and ``cameras.json``. Every
    file is written atomically (temporary file, then rename) and
    cameras.json last, so a folder with a cameras.json is complete.
    Numbered photographs of an earlier, larger scene in ``images/`` are
    removed.

    Args:
        folder (str or os.PathLike): Created if missing.
        data (Data): ``pos`` :math:`(N, 3)`, ``normal`` :math:`(N, 3)`
            (optional), ``face`` :math:`(3, F)` (optional), ``images``
            :math:`(V, H, W, 3)`, ``intrinsics`` :math:`(V, 3, 3)`,
            ``extrinsics`` :math:`(V, 3, 4)` and ``envmap``
            :math:`(H_e, W_e, 3)`.
        image_format (str, optional): ``'exr'`` (lossless float32, needs
            the ``OpenEXR`` package), ``'hdr'`` (Radiance RGBE: 8-bit
            mantissas, 1/256 relative precision, no NaN) or ``'npy'``
            (lossless); also used for the environment map.
            (default: :obj:`'exr'` when OpenEXR is installed, else
            :obj:`'hdr'`)

    Returns:
        The written paths (cameras.json last).
    """
    if image_format is None:
        image_format = 'exr' if _has_openexr() else 'hdr'
    if image_format not in IMAGE_FORMATS:
        raise ValueError(f"'image_format' must be one of {IMAGE_FORMATS}, "
                         f"got {image_format!r}")
    if image_format == 'exr' and not _has_openexr():
        raise ValueError("image_format='exr' needs the OpenEXR package: pip "
                         "install OpenEXR (or use 'hdr' or 'npy')")
    arrays = _scene_arrays(data)
    folder = os.fspath(folder)
    if osp.exists(folder) and not osp.isdir(folder):
        raise ValueError(f"'{folder}' is a file; write_scene needs a folder")
    os.makedirs(osp.join(folder, IMAGE_FOLDER), exist_ok=True)
    paths = []
    properties = {}
    if arrays['normal'] is not None:
        properties = {k: arrays['normal'][:, i]
                      for i, k in enumerate(('nx', 'ny', 'nz'))}
    paths.append(write_ply(osp.join(folder, GEOMETRY_NAME), arrays['pos'],
                           arrays['face'], properties))
    envmap_name = f'envmap.{image_format}'
    paths.append(_write_image(osp.join(folder, envmap_name),
                              arrays['envmap'], image_format))
    cameras, written = [], set()
    digits = max(3, len(str(len(arrays['images']) - 1)))
    for v, image in enumerate(arrays['images']):
        name = f'{v:0{digits}d}.{image_format}'
        written.add(name)
        try:
            path = _write_image(osp.join(folder, IMAGE_FOLDER, name), image,
                                image_format)
        except ValueError as error:
            raise ValueError(f"image {v}: {error}") from None
        paths.append(path)
        E = arrays['extrinsics'][v]
        cameras.append({'image': f'{IMAGE_FOLDER}/{name}',
                        'K': arrays['intrinsics'][v].tolist(),
                        'R': E[:, :3].tolist(), 't': E[:, 3].tolist()})
    cameras_path = osp.join(folder, CAMERAS_FILE)
    text = _cameras_json(GEOMETRY_NAME, envmap_name, cameras)
    atomic_write(cameras_path, lambda f: f.write(text), 'w')
    for name in os.listdir(osp.join(folder, IMAGE_FOLDER)):
        if _NUMBERED.match(name) and name not in written:
            os.remove(osp.join(folder, IMAGE_FOLDER, name))
    for other in IMAGE_FORMATS:  # an envmap of an earlier, other format
        stale = osp.join(folder, f'envmap.{other}')
        if other != image_format and osp.isfile(stale):
            os.remove(stale)
    paths.append(cameras_path)
    return paths


def _cameras_json(geometry: str, envmap: str, cameras: List[dict]) -> str:
    """cameras.json with one camera per four lines (a person reads it)."""
    dump = json.dumps
    entries = [f'    {{"image": {dump(c["image"])},\n'
               f'     "K": {dump(c["K"])},\n'
               f'     "R": {dump(c["R"])},\n'
               f'     "t": {dump(c["t"])}}}' for c in cameras]
    return (f'{{\n  "geometry": {dump(geometry)},\n'
            f'  "envmap": {dump(envmap)},\n  "cameras": [\n'
            + ',\n'.join(entries) + '\n  ]\n}\n')


def _numpy(value, name: str) -> np.ndarray:
    if value is None:
        raise ValueError(f"write_scene needs 'data.{name}'")
    if isinstance(value, torch.Tensor):
        value = value.detach().cpu().numpy()
    return np.asarray(value)


def _scene_arrays(data: Data) -> dict:
    pos = _numpy(getattr(data, 'pos', None), 'pos').astype(np.float64)
    if pos.ndim != 2 or pos.shape[1] != 3 or len(pos) == 0:
        raise ValueError(f"'data.pos' must have shape [N, 3] with N >= 1, "
                         f"got {list(pos.shape)}")
    if not np.isfinite(pos).all():
        raise ValueError("'data.pos' has NaN or infinite coordinates")
    normal = getattr(data, 'normal', None)
    if normal is None:
        normal = getattr(data, 'norm', None)
    if normal is not None:
        normal = _numpy(normal, 'normal').astype(np.float64)
        if normal.shape != pos.shape:
            raise ValueError(f"'data.normal' must have shape "
                             f"{list(pos.shape)}, got {list(normal.shape)}")
    face = getattr(data, 'face', None)
    if face is not None:
        face = _numpy(face, 'face').astype(np.int64)
        if face.ndim != 2 or face.shape[0] != 3:
            raise ValueError(f"'data.face' must have shape [3, F], got "
                             f"{list(face.shape)}")
        face = face.T
    images = _numpy(getattr(data, 'images', None), 'images')
    if images.ndim != 4 or images.shape[-1] != 3 or len(images) == 0:
        raise ValueError(f"'data.images' must have shape [V, H, W, 3] with "
                         f"V >= 1, got {list(images.shape)}")
    intrinsics = _numpy(getattr(data, 'intrinsics', None),
                        'intrinsics').astype(np.float64)
    extrinsics = _numpy(getattr(data, 'extrinsics', None),
                        'extrinsics').astype(np.float64)
    num_views = len(images)
    if intrinsics.shape != (num_views, 3, 3) or \
            extrinsics.shape != (num_views, 3, 4):
        raise ValueError(f"there are {num_views} images, so 'data.intrinsics'"
                         f" must be [{num_views}, 3, 3] and 'data.extrinsics'"
                         f" [{num_views}, 3, 4], got "
                         f"{list(intrinsics.shape)} and "
                         f"{list(extrinsics.shape)}")
    if not (np.isfinite(intrinsics).all() and np.isfinite(extrinsics).all()):
        raise ValueError("'data.intrinsics' and 'data.extrinsics' must be "
                         "finite")
    envmap = _numpy(getattr(data, 'envmap', None), 'envmap')
    if envmap.ndim != 3 or envmap.shape[-1] != 3:
        raise ValueError(f"'data.envmap' must have shape [H, W, 3], got "
                         f"{list(envmap.shape)}")
    return {'pos': pos, 'normal': normal, 'face': face, 'images': images,
            'intrinsics': intrinsics, 'extrinsics': extrinsics,
            'envmap': envmap}


def _has_openexr() -> bool:
    try:
        import OpenEXR
    except ImportError:
        return False
    return hasattr(OpenEXR, 'File')


def _write_image(path: str, image: np.ndarray, image_format: str) -> str:
    if not np.issubdtype(image.dtype, np.floating):
        raise ValueError(f"'{path}': images must hold floating-point linear "
                         f"radiance, got {image.dtype}")
    if image_format == 'hdr':
        write_hdr(path, image)
    elif image_format == 'npy':
        image = np.ascontiguousarray(image, dtype=np.float32)
        atomic_write(path, lambda f: np.save(f, image), 'wb')
    else:
        _write_exr(path, np.ascontiguousarray(image, dtype=np.float32))
    return path


def _write_exr(path: str, image: np.ndarray):
    """A float32 RGB OpenEXR file (ZIP compressed, lossless), atomically."""
    import OpenEXR
    header = {'compression': OpenEXR.ZIP_COMPRESSION,
              'type': OpenEXR.scanlineimage}

    def write_to(temporary):
        with OpenEXR.File(header, {'RGB': image}) as f:
            f.write(temporary)

    atomic_write_file(path, write_to, make_folder=False)


def scene_summary(data: Data) -> str:
    """One line describing a scene read by :func:`read_scene`: points (and
    triangles), views and image size, the environment map's size (or the
    maps' count and size)."""
    views, height, width = data.images.shape[:3]
    face = getattr(data, 'face', None)
    surface = f"{data.pos.size(0)} points" + (
        f", {face.size(1)} triangles" if face is not None else
        ' (point cloud)')
    maps = getattr(data, 'envmaps', None)
    if maps is not None:  # each view under its own map (join_lightings)
        lighting = (f"{maps.size(0)} environment maps of {maps.size(1)} x "
                    f"{maps.size(2)}")
    else:
        lighting = (f"environment map {data.envmap.size(0)} x "
                    f"{data.envmap.size(1)}")
    return f"{surface}; {views} view(s) of {height} x {width}; {lighting}"
