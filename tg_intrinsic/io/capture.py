"""Any capture, one reader: :func:`read_capture` recognises the format of a
folder (or file) and reads it into the
:class:`~torch_geometric.data.Data` of :func:`~tg_intrinsic.io.read_scene`;
:func:`write_capture` writes a capture in any of them (the synthetic
examples of ``tg-intrinsic svbrdf --write-example --format``).

Formats (:data:`CAPTURE_FORMATS`), looked for in this order:

* ``native``: a scene folder with ``cameras.json``
  (:mod:`~tg_intrinsic.io.scene`);
* ``orb``: a Stanford-ORB scene (:mod:`~tg_intrinsic.io.stanford_orb`);
* ``nerf`` / ``nerfstudio``: a ``transforms.json`` or
  ``transforms_train.json`` (:mod:`~tg_intrinsic.io.transforms_json`);
* ``colmap``: a COLMAP sparse model, text or binary, in the folder, in
  ``sparse/0/`` or ``sparse/``, with the photographs in ``images/``
  (:mod:`~tg_intrinsic.io.colmap`).

Pixel conventions, each format's own, become the library's (pixel
centres at half-integers, :mod:`~tg_intrinsic.geometry.appearance.cameras`):
COLMAP's principal point is taken as it is (its upper-left pixel's centre
is (0.5, 0.5)); NeRF/Blender's is the image centre (W/2, H/2); nerfstudio's
``cx, cy`` are taken as they are (its rays pass through pixel + 0.5).
OpenCV's calibrations (pixel centres at integers) need 0.5 added to
``cx, cy`` before they go into cameras.json.
"""
import os
import os.path as osp
from typing import Optional

import torch

from .capture_files import why_not_a_file
from .colmap import colmap_spec, find_colmap_model
from .capture_views import assemble_capture
from .scene import CAMERAS_FILE, read_scene
from .stanford_orb import find_orb_scene, orb_spec
from .transforms_json import convention, find_transforms, transforms_spec

__all__ = ['CAPTURE_FORMATS', 'detect_format', 'read_capture']

#: The formats :func:`read_capture` reads.
CAPTURE_FORMATS = ('native', 'colmap', 'nerf', 'nerfstudio', 'orb')
# options that the native scene folder has a place for (cameras.json)
_NATIVE_DEFAULTS = {'geometry': None, 'envmap': None, 'exposure': None,
                    'gamma': None, 'envmap_rotation': 0.0, 'up': 'z'}


def detect_format(path) -> str:
    """The format of the capture at ``path`` (see the module), or a
    :class:`ValueError` that says what was looked for."""
    path = os.fspath(path)
    if not osp.exists(path):
        if find_orb_scene(path) is not None:
            return 'orb'
        raise ValueError(f"the capture '{path}' {why_not_a_file(path)}")
    if osp.isfile(path):
        if osp.basename(path) == CAMERAS_FILE:
            return 'native'
        if path.lower().endswith('.json'):
            import json
            try:
                with open(path, encoding='utf-8-sig') as f:
                    return convention(json.load(f))
            except (ValueError, OSError, TypeError, KeyError):
                return 'nerf'  # its reader says what is wrong
        raise ValueError(f"'{path}' is a file; a capture is a folder (or a "
                         f"transforms.json)")
    if osp.lexists(osp.join(path, CAMERAS_FILE)):  # read_scene says what
        return 'native'  # is wrong with it
    if find_orb_scene(path) is not None:
        return 'orb'
    transforms = find_transforms(path)
    if transforms is not None:
        return detect_format(transforms)
    if find_colmap_model(path) is not None:
        return 'colmap'
    raise ValueError(
        f"'{path}' is no capture this library reads: it holds no "
        f"{CAMERAS_FILE} (a scene folder), no transforms.json or "
        f"transforms_train.json (NeRF, nerfstudio), no COLMAP model "
        f"(cameras, images and points3D .txt/.bin, here or in sparse/0/) "
        f"and is no Stanford-ORB scene")


def read_capture(path, format: Optional[str] = None,
                 dtype: torch.dtype = torch.float32, **options):
    r"""Reads a capture of any format (see the module) into the
    :class:`~torch_geometric.data.Data` of
    :func:`~tg_intrinsic.io.read_scene`, with ``capture_info``: the
    format, what was read from where, and how many pixels were left out
    and why (masks, clipping, undistortion).

    Args:
        path (str): The capture folder (or transforms file).
        format (str, optional): One of :data:`CAPTURE_FORMATS`; detected
            when :obj:`None`. (default: :obj:`None`)
        dtype (torch.dtype, optional): Of the geometry, cameras and
            lighting. (default: :obj:`torch.float32`)
        **options: ``geometry``, ``envmap``, ``exposure``, ``gamma``,
            ``envmap_rotation`` and ``up`` of
            :func:`~tg_intrinsic.io.capture_views.assemble_capture`; the
            native format keeps these in its cameras.json and refuses
            them.
    """
    path = os.fspath(path)
    format = format or detect_format(path)
    if format not in CAPTURE_FORMATS:
        raise ValueError(f"'format' must be one of {CAPTURE_FORMATS}, got "
                         f"{format!r}")
    if format == 'native':
        given = [k for k, v in options.items()
                 if v is not None and v != _NATIVE_DEFAULTS.get(k)]
        if given:
            raise ValueError(
                f"a scene folder ({CAMERAS_FILE}) names its geometry and "
                f"lighting and holds linear HDR photographs, so "
                f"{', '.join(given)} do not apply; edit {CAMERAS_FILE}")
        folder = osp.dirname(path) if osp.isfile(path) else path
        data = read_scene(folder, dtype=dtype)
        data.capture_info = {'format': 'native', 'folder': folder,
                             'views': int(data.images.size(0)),
                             'notes': []}
        return data
    if format == 'colmap':
        spec = colmap_spec(path)
    elif format == 'orb':
        spec = orb_spec(path)
    else:
        spec = transforms_spec(path, format)
    data = assemble_capture(spec, dtype=dtype, **options)
    data.capture_info['folder'] = spec.folder
    return data
