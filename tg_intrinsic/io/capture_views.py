r"""One way from any capture format to the :class:`~torch_geometric.data.Data`
that :func:`~tg_intrinsic.io.read_scene` returns: a format reader
(COLMAP, transforms.json, Stanford-ORB) says where each photograph, mask,
the surface and the lighting are and what each camera is
(:class:`CaptureSpec`); :func:`assemble_capture` reads them.

Photographs are linear HDR (.exr, .hdr, .npy) or 8/16-bit LDR (PNG, JPEG,
...). LDR values are decoded with the sRGB curve (or ``value ** gamma``)
and divided by the capture's exposure :math:`S` times each photograph's
EXIF exposure :math:`e_i = t_i \cdot \mathrm{ISO}_i / N_i^2` relative to
the first's, where every photograph carries one:

.. math::
    L = \frac{\mathrm{decode}(c)}{S \, e_i / e_0}.

Pixels that carry no radiance are NaN, which
:class:`~tg_intrinsic.transforms.ProjectViews` leaves out: outside the
object's mask (a mask file, else an alpha channel), clipped (a channel at
the top code, and the pixels next to it) and, after undistortion, outside
the photograph. Distorted photographs are resampled into the pinhole
camera of the same :math:`K`
(:func:`~tg_intrinsic.geometry.appearance.distortion.undistort_image`).
"""
import os.path as osp
from dataclasses import dataclass, field
from typing import List, Optional, Tuple

import numpy as np
import torch
from torch_geometric.data import Data

from tg_intrinsic.geometry.appearance.photograph_stack import \
    PhotographStack

from .capture_files import (ENVMAP_EXTENSIONS, HDR_EXTENSIONS,
                            find_single_file, read_envmap_file,
                            read_geometry_file, read_hdr_photograph)
from .mesh import MESH_EXTENSIONS
from .photographs import exif_exposure, read_ldr, read_mask

__all__ = ['CaptureView', 'CaptureSpec', 'assemble_capture', 'UP_AXES']

#: The world's up axis a capture may have; the library's is +z.
UP_AXES = ('z', 'y')
# y up -> z up: (x, y, z) -> (x, -z, y), a rotation (det +1)
_Y_UP_TO_Z_UP = np.array([[1.0, 0.0, 0.0], [0.0, 0.0, -1.0],
                          [0.0, 1.0, 0.0]])


@dataclass
class CaptureView:
    """One photograph of a capture and its camera (OpenCV convention,
    pixel centres at half-integers, :math:`x_c = R x + t`)."""
    image: str
    K: np.ndarray
    R: np.ndarray
    t: np.ndarray
    #: (k1, k2, p1, p2), or None for a pinhole camera
    distortion: Optional[np.ndarray] = None
    #: a mask file, or None
    mask: Optional[str] = None
    #: (H, W) the format declares for the photograph, or None
    size: Optional[Tuple[int, int]] = None
    #: the environment map this photograph was lit by, where the format
    #: gives each its own (transforms.json's ``hdri_path``), or None
    envmap: Optional[str] = None


@dataclass
class CaptureSpec:
    """What a format reader found: the views, the files it names and how
    to read them."""
    #: the format's name ('colmap', 'nerf', ...)
    format: str
    #: the file or folder the cameras come from (for messages)
    source: str
    #: where files that the format does not name are looked for
    folder: str
    views: List[CaptureView]
    geometry: Optional[str] = None
    envmap: Optional[str] = None
    #: 'tg' (this library's) or 'blender' (mirrored azimuth)
    envmap_convention: str = 'tg'
    notes: List[str] = field(default_factory=list)


def assemble_capture(spec: CaptureSpec, geometry=None, envmap=None,
                     exposure: Optional[float] = None,
                     gamma: Optional[float] = None,
                     envmap_rotation: float = 0.0, up: str = 'z',
                     dtype: torch.dtype = torch.float32) -> Data:
    r"""Reads what :obj:`spec` names into the
    :class:`~torch_geometric.data.Data` of
    :func:`~tg_intrinsic.io.read_scene`, with ``capture_info`` (a dict:
    the format, the notes, the exposures used, and how many pixels were
    left out and why).

    Args:
        spec (CaptureSpec): The format reader's findings.
        geometry (str, optional): A mesh or point cloud that replaces the
            format's; otherwise the format's, else the one mesh file in
            the capture folder. (default: :obj:`None`)
        envmap (str, optional): The lighting, likewise.
            (default: :obj:`None`)
        exposure (float, optional): :math:`S`, required for LDR
            photographs (the scale from decoded values to the environment
            map's radiance). (default: :obj:`None`)
        gamma (float, optional): Decode LDR values as ``value ** gamma``
            instead of the sRGB curve. (default: :obj:`None`)
        envmap_rotation (float, optional): Degrees to turn the lighting
            about world up. (default: :obj:`0.0`)
        up (str, optional): The capture world's up axis, ``'z'`` or
            ``'y'`` (then turned to +z). (default: :obj:`'z'`)
        dtype (torch.dtype, optional): Of the geometry, cameras and
            lighting. (default: :obj:`torch.float32`)
    """
    from tg_intrinsic.geometry.appearance.envmap import (blender_envmap,
                                                         rotate_envmap)
    if up not in UP_AXES:
        raise ValueError(f"'up' must be one of {UP_AXES}, got {up!r}")
    if exposure is not None and not (np.isfinite(exposure) and
                                     exposure > 0):
        raise ValueError(f"the exposure must be a positive number, got "
                         f"{exposure!r}")
    per_view = _per_view_lighting(spec, envmap)
    geometry_path, envmap_path = _surface_and_lighting(
        spec, geometry, envmap if per_view is None else per_view[0][0])
    named = {'geometry': 'given with --geometry' if geometry else
             f'of {spec.source}',
             'envmap': 'given with --envmap' if envmap else
             f'of {spec.source}'}
    pos, face, normal, face_uv = read_geometry_file(geometry_path,
                                                    named['geometry'])

    def light(path: str, named: str):
        lighting = read_envmap_file(path, named)
        if spec.envmap_convention == 'blender':
            lighting = blender_envmap(lighting)
        if envmap_rotation:
            lighting = rotate_envmap(lighting, envmap_rotation)
        return lighting.to(dtype)
    if per_view is None:
        lighting = light(envmap_path, named['envmap'])
    else:
        paths, view_lighting = per_view
        maps = [light(path, f'named by {spec.source}') for path in paths]
        for path, lighting in zip(paths, maps):
            if lighting.shape != maps[0].shape:
                raise ValueError(
                    f"the environment maps of {spec.source} differ in size: "
                    f"'{path}' is {lighting.shape[0]} x {lighting.shape[1]}"
                    f" but '{paths[0]}' {maps[0].shape[0]} x "
                    f"{maps[0].shape[1]}; resample them to one size")
    images, info = _photographs(spec, exposure, gamma)
    rotation = np.stack([view.R for view in spec.views])
    translation = np.stack([view.t for view in spec.views])
    if up == 'y':  # turn the world, cameras with it
        pos = pos @ torch.from_numpy(_Y_UP_TO_Z_UP).to(pos).T
        normal = normal @ torch.from_numpy(_Y_UP_TO_Z_UP).to(normal).T
        rotation = rotation @ _Y_UP_TO_Z_UP.T
    intrinsics = torch.as_tensor(np.stack([v.K for v in spec.views]),
                                 dtype=dtype)
    extrinsics = torch.as_tensor(np.concatenate(
        [rotation, translation[:, :, None]], 2), dtype=dtype)
    data = Data(pos=pos.to(dtype), normal=normal.to(dtype), images=images,
                intrinsics=intrinsics, extrinsics=extrinsics)
    if per_view is None:
        data.envmap = lighting
    else:  # each photograph under its own map
        data.envmaps = torch.stack(maps)
        data.view_lighting = torch.tensor(view_lighting)
    if face is not None:
        data.face = face
    if face_uv is not None:
        data.face_uv = face_uv.to(dtype)
    _check_the_cameras_see_the_surface(spec, data)
    info.update(format=spec.format, notes=list(spec.notes),
                geometry=osp.abspath(geometry_path),
                envmap=osp.abspath(envmap_path), up=up,
                envmap_rotation=float(envmap_rotation))
    if per_view is not None:
        info['lightings'] = [osp.abspath(path) for path in per_view[0]]
        info['notes'].append(f'{len(per_view[0])} environment maps, one per '
                             f'photograph as the frames name them')
    elif any(view.envmap for view in spec.views):
        info['notes'].append('--envmap lights every photograph (the frames '
                             'name their own maps)')
    data.capture_info = info
    return data


def _per_view_lighting(spec: CaptureSpec, envmap):
    """``(maps, the map of each view)`` where the format gives each
    photograph its own environment map (and --envmap does not replace
    them), else None."""
    named = [view.envmap for view in spec.views]
    if envmap is not None or not any(named):
        return None
    if not all(named):
        missing = [v for v, path in enumerate(named) if not path]
        raise ValueError(
            f"{spec.source} names an environment map for some photographs "
            f"but not for {len(missing)} (the first: "
            f"'{spec.views[missing[0]].image}'); name one for every "
            f"photograph, or light them all with --envmap MAP")
    maps = list(dict.fromkeys(named))
    return maps, [maps.index(path) for path in named]


def _surface_and_lighting(spec: CaptureSpec, geometry, envmap):
    """The geometry and envmap paths: the options, the format's, or the
    one file of the kind in the capture folder."""
    if geometry is None:
        geometry = spec.geometry or osp.join(spec.folder, find_single_file(
            spec.folder, MESH_EXTENSIONS, set(), 'geometry (mesh or point '
            'cloud)', 'with --geometry MESH'))
    if envmap is None:
        photographs = {view.image for view in spec.views}
        envmap = spec.envmap or osp.join(spec.folder, find_single_file(
            spec.folder, ENVMAP_EXTENSIONS, photographs, 'environment-map',
            'with --envmap MAP'))
    return str(geometry), str(envmap)


def _photographs(spec: CaptureSpec, exposure, gamma):
    """The photographs as a :class:`PhotographStack` that reads each view
    from disk when asked (a capture's photographs are not held in memory
    at once), after one pass that checks their sizes and counts what is
    left out."""
    ldr = [not _is_hdr(view.image) for view in spec.views]
    if any(ldr) and exposure is None:
        first = spec.views[ldr.index(True)].image
        raise ValueError(
            f"'{first}' is an 8-bit photograph: an LDR capture needs "
            f"--exposure S, the factor from its decoded values to the "
            f"environment map's radiance (for example the ratio of a white "
            f"card's value in a photograph to the light the map gives it)")
    relative = _relative_exposures(spec, ldr)
    read = _ViewReader(spec.views, gamma, [
        None if not is_ldr else exposure * scale
        for is_ldr, scale in zip(ldr, relative or [1.0] * len(ldr))])
    size, lit = None, False
    counts = {'masked': 0, 'clipped': 0, 'outside_after_undistortion': 0}
    for v, view in enumerate(spec.views):
        image, left_out = read.with_counts(v)
        if size is None:
            size = tuple(image.shape[:2])
        _check_size(view, image, size, spec)
        for key, value in left_out.items():
            counts[key] += value
        lit = lit or bool((image > 0).any())
    if not lit:
        raise ValueError(f"no photograph of {spec.source} has a pixel above "
                         f"0 where it counts (inside the masks, unclipped)")
    images = PhotographStack(read, len(spec.views), size,
                             [view.image for view in spec.views])
    info = {'views': len(spec.views), 'ldr': bool(any(ldr)),
            'exposure': exposure, 'gamma': gamma,
            'relative_exposures': None if relative is None else
            [round(float(r), 6) for r in relative],
            'pixels_left_out': counts}
    return images, info


class _ViewReader:
    """Reads view ``v`` of a capture as radiance (a plain object, so that
    a capture read with its photographs on disk can be pickled)."""
    def __init__(self, views: List[CaptureView], gamma, scales):
        self.views, self.gamma, self.scales = views, gamma, scales

    def with_counts(self, v: int):
        return _read_view(self.views[v], self.gamma,
                          self.scales[v] is not None, self.scales[v])

    def __call__(self, v: int):
        return self.with_counts(v)[0]


def _read_view(view: CaptureView, gamma, ldr: bool, scale):
    """One photograph as radiance, float32 (H, W, 3), NaN where it carries
    none (outside its mask, clipped, outside after undistortion), and how
    many pixels were left out and why."""
    image, clipped, alpha = _read_one(view.image, gamma, ldr)
    counts = {'masked': 0, 'clipped': 0, 'outside_after_undistortion': 0}
    if scale is not None:
        image = image / np.float32(scale)
    mask = read_mask(view.mask, size=image.shape[:2]) \
        if view.mask is not None else alpha
    if mask is not None:
        counts['masked'] = int((~mask).sum())
        image[~mask] = np.nan
    if clipped is not None:
        counts['clipped'] = int((clipped & (mask if mask is not None
                                            else True)).sum())
        image[clipped] = np.nan
    image = torch.from_numpy(image)
    if view.distortion is not None and np.any(view.distortion):
        from tg_intrinsic.geometry.appearance.distortion import \
            undistort_image
        before = int(torch.isnan(image).any(-1).sum())
        image = undistort_image(image, torch.from_numpy(view.K),
                                view.distortion)
        counts['outside_after_undistortion'] = max(
            0, int(torch.isnan(image).any(-1).sum()) - before)
    return image, counts


def _is_hdr(path: str) -> bool:
    return osp.splitext(path)[1].lower() in HDR_EXTENSIONS


def _read_one(path: str, gamma, ldr: bool):
    """(radiance (H, W, 3) float32, clipped (H, W) or None, alpha mask
    (H, W) or None)."""
    if not ldr:
        return read_hdr_photograph(path).copy(), None, None
    photo = read_ldr(path, gamma=gamma)
    return np.array(photo.radiance, dtype=np.float32), photo.clipped, \
        photo.alpha


def _relative_exposures(spec: CaptureSpec, ldr: List[bool]):
    """Each LDR photograph's EXIF exposure over the first's, when every
    LDR photograph has one (else all 1)."""
    if not any(ldr):
        return None
    values = [exif_exposure(v.image) for v, is_ldr in zip(spec.views, ldr)
              if is_ldr]
    if any(value is None for value in values):
        return [1.0] * len(spec.views)
    values = iter(values)
    exposures = [next(values) if is_ldr else None for is_ldr in ldr]
    first = next(e for e in exposures if e is not None)
    return [1.0 if e is None else e / first for e in exposures]


def _check_size(view: CaptureView, image: np.ndarray, size, spec):
    height, width = image.shape[:2]
    if view.size is not None and tuple(view.size) != (height, width):
        raise ValueError(
            f"'{view.image}' is {height} x {width} pixels but {spec.source} "
            f"gives its camera {view.size[0]} x {view.size[1]}; use the "
            f"photographs the cameras were calibrated on (or scale K)")
    if (height, width) != tuple(size):
        raise ValueError(
            f"'{view.image}' is {height} x {width} pixels but the first "
            f"photograph is {size[0]} x {size[1]}; all photographs must "
            f"have one size")


def _check_the_cameras_see_the_surface(spec: CaptureSpec, data: Data):
    """The most common convention error (OpenGL cameras read as OpenCV,
    another world frame) leaves every camera looking away from the
    surface: said in words, before any work."""
    from tg_intrinsic.geometry.appearance.cameras import project
    height, width = data.images.shape[1:3]
    uv, depth = project(data.pos.double(), data.intrinsics.double(),
                        data.extrinsics.double())
    inside = (depth > 0) & (uv[..., 0] >= 0) & (uv[..., 0] < width) & \
        (uv[..., 1] >= 0) & (uv[..., 1] < height)
    if not bool(inside.any()):
        behind = float((depth <= 0).double().mean())
        raise ValueError(
            f"no camera of {spec.source} sees any of the {data.pos.size(0)} "
            f"points of the surface ({100 * behind:.0f}% of them lie behind"
            f" the cameras): the cameras and the mesh are in different "
            f"frames or conventions; check that the mesh belongs to this "
            f"capture, or force the other reading with --format (nerf vs "
            f"nerfstudio, colmap)")
