"""The files every capture format shares: the surface, the environment map
and linear HDR photographs, each read and checked with messages that name
the file, and the search for the one file of a kind in a capture folder.
The formats (:mod:`~tg_intrinsic.io.scene`, COLMAP, transforms.json,
Stanford-ORB) say where the files are; this module reads them."""
import os
import os.path as osp
from typing import Optional

import numpy as np
import torch

from .hdr import read_envmap, read_exr, read_hdr, read_npy
from .mesh import read_face_uv, read_surface

__all__ = ['HDR_EXTENSIONS', 'ENVMAP_EXTENSIONS', 'why_not_a_file',
           'read_json',
           'is_candidate', 'find_single_file', 'read_geometry_file',
           'read_envmap_file', 'read_hdr_photograph']

#: Linear HDR photographs: OpenEXR, Radiance RGBE, float NumPy arrays.
HDR_EXTENSIONS = ('.exr', '.hdr', '.pic', '.npy')
#: Environment maps, the same kinds of file.
ENVMAP_EXTENSIONS = ('.hdr', '.pic', '.exr', '.npy')
LDR_SUFFIXES = ('.png', '.jpg', '.jpeg', '.bmp', '.gif', '.webp', '.tif',
                '.tiff')
# neighbours for normals of point clouds stored without them
NORMAL_NEIGHBOURS = 10


def why_not_a_file(path: str) -> Optional[str]:
    """Why ``path`` is no file to read (to end a sentence that begins
    with it), or :obj:`None` when it is one."""
    if osp.isfile(path):
        return None
    if osp.isdir(path):
        return 'is a folder, not a file'
    if osp.islink(path):
        return f"is a link to '{os.readlink(path)}', which does not exist"
    parent = osp.dirname(osp.abspath(path))
    while not osp.exists(parent) and osp.dirname(parent) != parent:
        parent = osp.dirname(parent)
    if osp.exists(parent) and not osp.isdir(parent):
        return f"does not exist: '{parent}' is a file, not a folder"
    return 'does not exist'


def read_json(path: str):
    """The parsed JSON file (a UTF-8 byte-order mark allowed), or a
    :class:`ValueError` that names the file, the line and the column of a
    syntax error."""
    import json
    try:
        with open(path, 'r', encoding='utf-8-sig') as f:
            return json.load(f)
    except json.JSONDecodeError as error:
        raise ValueError(f"'{path}' is not valid JSON: {error.msg} at line "
                         f"{error.lineno}, column {error.colno}") from None
    except (OSError, UnicodeDecodeError) as error:
        raise ValueError(f"could not read '{path}': {error}") from None


def is_candidate(name: str, extensions) -> bool:
    """Whether a file name has one of :obj:`extensions` and is not
    hidden."""
    return not name.startswith('.') and \
        osp.splitext(name)[1].lower() in extensions


def find_single_file(folder: str, extensions, exclude: set, what: str,
                     how_to_name: str) -> str:
    """The one file of ``what`` kind at the top of ``folder`` (its name);
    ``how_to_name`` says where a user names the file instead, to end the
    message when there are none or several ('as "geometry" in
    cameras.json', 'with --geometry MESH')."""
    top = osp.realpath(folder)
    excluded = {osp.realpath(name if osp.isabs(name) else osp.join(
        folder, name)) for name in exclude}
    found = sorted(n for n in os.listdir(folder)
                   if is_candidate(n, extensions)
                   and osp.isfile(osp.join(folder, n))
                   and osp.join(top, n) not in excluded)
    kinds = '/'.join(e for e in extensions if e != '.pic')
    if not found:
        folders = sorted(n for n in os.listdir(folder)
                         if is_candidate(n, extensions)
                         and osp.isdir(osp.join(folder, n)))
        also = f" ('{folders[0]}' is a folder, not a file)" if folders \
            else ''
        raise ValueError(f"'{folder}' holds no {what} file ({kinds}){also};"
                         f" add one, or name it {how_to_name}")
    if len(found) > 1:
        shown = ', '.join(f"'{n}'" for n in found[:4])
        raise ValueError(f"'{folder}' holds several {what} files: "
                         f"{shown}{' ...' if len(found) > 4 else ''}; name "
                         f"the one to use {how_to_name}")
    return found[0]


def read_geometry_file(path: str, named_in: str):
    """The surface of a capture: positions, faces (or :obj:`None`), unit
    normals and per-face UVs (or :obj:`None`) as tensors. Normals are the
    file's (PLY ``nx ny nz``) when it has them, else area-weighted vertex
    normals of a mesh or PCA normals of a point cloud (10 neighbours,
    oriented outwards). ``named_in`` says where the path came from."""
    from tg_intrinsic.geometry import estimate_normals, vertex_normals
    why = why_not_a_file(path)
    if why:
        raise ValueError(f"the geometry file '{path}' {named_in} {why}")
    try:
        pos, face, properties = read_surface(path)
    except FileNotFoundError as error:
        raise ValueError(str(error)) from None
    face_uv = None if face is None else read_face_uv(path, pos, face)
    if face_uv is not None:
        face_uv = torch.from_numpy(face_uv)
    pos = torch.from_numpy(pos)
    if face is not None:
        face = torch.from_numpy(face).t().contiguous()
    if all(k in properties for k in ('nx', 'ny', 'nz')):
        normal = torch.from_numpy(np.stack(
            [properties[k] for k in ('nx', 'ny', 'nz')], 1).astype(
                np.float64))
        length = normal.norm(dim=1)
        bad = ~torch.isfinite(length) | (length < 1e-12)
        if bool(bad.any()):
            raise ValueError(f"'{path}' has {int(bad.sum())} zero or "
                             f"non-finite normal(s) (nx ny nz); repair them "
                             f"or remove the normals to have them computed")
        # scaled to unit length; already unit ones (to float32 round-off)
        # are kept bit for bit, so a written scene reads back unchanged
        off = (length - 1).abs() > 1e-6
        normal[off] = normal[off] / length[off, None]
    elif face is not None:
        try:
            normal = vertex_normals(pos, face)
        except ValueError as error:
            raise ValueError(f"'{path}': {error}") from None
    else:
        if pos.size(0) <= 3:
            raise ValueError(f"'{path}' is a point cloud of {pos.size(0)} "
                             f"point(s) without normals; it needs more "
                             f"points, or normals as nx ny nz")
        normal = estimate_normals(pos, k=min(NORMAL_NEIGHBOURS,
                                             pos.size(0) - 1))
    return pos, face, normal, face_uv


def read_envmap_file(path: str, named_in: str) -> torch.Tensor:
    """The lighting of a capture, an equirectangular linear HDR image,
    checked: not black, and twice as wide as high. ``named_in`` says where
    the path came from."""
    why = why_not_a_file(path)
    if why:
        raise ValueError(f"the environment map '{path}' {named_in} {why}")
    try:
        envmap = read_envmap(path)
    except ImportError as error:
        raise ValueError(f"cannot read '{path}': {error}") from None
    except ValueError as error:
        if path in str(error):
            raise
        raise ValueError(f"environment map '{path}': {error}") from None
    if not bool((envmap > 0).any()):
        raise ValueError(f"the environment map '{path}' is black (every "
                         f"pixel 0): it lights nothing, so no material can "
                         f"be recovered; give the lighting the photographs "
                         f"were taken under")
    height, width = envmap.shape[:2]
    if width != 2 * height:
        raise ValueError(f"the environment map '{path}' is {height} x "
                         f"{width} pixels; an equirectangular (latitude-"
                         f"longitude) map is twice as wide as high: convert "
                         f"a cube map or mirror-ball photograph to one")
    return envmap


def read_hdr_photograph(path: str) -> np.ndarray:
    """One linear HDR photograph (.exr, .hdr or float .npy), (H, W, 3)
    float32, checked: three channels, floating point, finite and >= 0
    (NaN marks a missing pixel)."""
    extension = osp.splitext(path)[1].lower()
    try:
        if extension in ('.hdr', '.pic'):
            image = read_hdr(path)
        elif extension == '.exr':
            image = read_exr(path)
        elif extension == '.npy':
            image = read_npy(path)
        else:
            ldr = f" (8-bit {extension} photographs are not HDR)" \
                if extension in LDR_SUFFIXES else ''
            raise ValueError(f"'{path}' is not a linear HDR image{ldr}: use "
                             f".exr, .hdr or .npy")
    except ImportError as error:
        raise ValueError(f"cannot read '{path}': {error}") from None
    except (OSError, EOFError) as error:
        raise ValueError(f"could not read '{path}': {error}") from None
    except ValueError as error:
        if path in str(error):
            raise
        raise ValueError(f"could not read '{path}': {error}") from None
    if image.ndim != 3 or image.shape[-1] != 3:
        raise ValueError(f"'{path}' has shape {list(image.shape)}; a "
                         f"photograph must be [H, W, 3] (3 channels, RGB)")
    if not np.issubdtype(image.dtype, np.floating):
        raise ValueError(f"'{path}' holds {image.dtype}, not floating-point "
                         f"linear radiance; an 8-bit image is not HDR")
    image = image.astype(np.float32, copy=False)
    if np.isinf(image).any() or (image < 0).any():
        raise ValueError(f"'{path}' has infinite or negative radiance; "
                         f"linear HDR photographs must be finite and >= 0 "
                         f"(mark missing pixels as NaN)")
    return image
