"""PBR textures and glTF 2.0 binaries (``.glb``) of recovered material
maps: what Blender, three.js or any glTF viewer opens with the material on.

glTF's metallic-roughness material is the principled model the SVBRDF
recovery fits: its ``baseColorTexture`` holds the base colour sRGB-encoded,
its ``metallicRoughnessTexture`` the roughness in the green channel and the
metallic in the blue one (both linear), with the same perceptual roughness
(:math:`\\alpha = r^2`). The file is written by trimesh."""
from typing import Optional

import numpy as np

from tg_intrinsic.nn.svbrdf_result import MAP_INFO, scaled_to_range
from tg_intrinsic.utils import atomic_write

__all__ = ['srgb_encode', 'to_bytes', 'write_png', 'write_glb',
           'write_textured_model', 'TEXTURE_FILES', 'GLB_FILE']


def srgb_encode(linear: np.ndarray) -> np.ndarray:
    """Linear values in [0, 1] sRGB-encoded (IEC 61966-2-1), as a display
    (and glTF's base colour) expects them."""
    linear = np.clip(linear, 0, 1)
    return np.where(linear <= 0.0031308, 12.92 * linear,
                    1.055 * linear ** (1 / 2.4) - 0.055)


def to_bytes(image: np.ndarray) -> np.ndarray:
    """Values in [0, 1] as 8-bit integers, rounded."""
    return np.round(np.clip(image, 0, 1) * 255).astype(np.uint8)


def write_png(path: str, image: np.ndarray) -> str:
    """Writes an 8-bit PNG (grey ``(H, W)`` or RGB ``(H, W, 3)`` of values
    in [0, 1], stored as they are: encode colours first) atomically;
    returns ``path``."""
    from PIL import Image
    pixels = Image.fromarray(to_bytes(image))
    atomic_write(path, lambda f: pixels.save(f, format='PNG'), 'wb')
    return path


def write_glb(path: str, pos: np.ndarray, face: np.ndarray,
              face_uv: np.ndarray, base_color: np.ndarray,
              metallic: np.ndarray, roughness: np.ndarray,
              normal: Optional[np.ndarray] = None, name: str = 'svbrdf'
              ) -> str:
    r"""Writes a mesh with its PBR material as a glTF 2.0 binary,
    atomically; returns ``path``.

    Args:
        path (str): The ``.glb`` file.
        pos (numpy.ndarray): Vertices :math:`(V, 3)`.
        face (numpy.ndarray): Triangles :math:`(F, 3)`.
        face_uv (numpy.ndarray): UVs per corner :math:`(3, F, 2)` in
            :math:`[0, 1]` with :math:`v` up (OBJ's convention; glTF's
            flipped :math:`v` is written). A vertex with several UVs (a
            seam) is split.
        base_color (numpy.ndarray): Linear base-colour texture
            :math:`(H, W, 3)` in [0, 1], row 0 at the top.
        metallic (numpy.ndarray): :math:`(H, W)` in [0, 1].
        roughness (numpy.ndarray): :math:`(H, W)` in [0, 1].
        normal (numpy.ndarray, optional): Vertex normals :math:`(V, 3)`
            for smooth shading. (default: :obj:`None`)
        name (str, optional): The material's name. (default: ``'svbrdf'``)
    """
    import trimesh
    from PIL import Image
    face = np.asarray(face, dtype=np.int64)
    face_uv = np.asarray(face_uv, dtype=np.float64)
    if face_uv.shape != (3, len(face), 2):
        raise ValueError(f"'face_uv' must have shape [3, {len(face)}, 2], "
                         f"got {list(face_uv.shape)}")
    # one glTF vertex per (vertex, UV) pair
    corner_vertex = face.reshape(-1)
    corner_uv = face_uv.transpose(1, 0, 2).reshape(-1, 2)
    keys = np.concatenate([corner_vertex[:, None].astype(np.float64),
                           corner_uv], 1)
    unique, inverse = np.unique(keys, axis=0, return_inverse=True)
    vertex = unique[:, 0].astype(np.int64)
    packed = np.stack([np.ones_like(roughness), roughness, metallic], -1)
    material = trimesh.visual.material.PBRMaterial(
        name=name, baseColorFactor=[1.0, 1.0, 1.0, 1.0], metallicFactor=1.0,
        roughnessFactor=1.0, doubleSided=False,
        baseColorTexture=Image.fromarray(to_bytes(srgb_encode(base_color))),
        metallicRoughnessTexture=Image.fromarray(to_bytes(packed)))
    mesh = trimesh.Trimesh(
        vertices=np.asarray(pos, dtype=np.float64)[vertex],
        faces=inverse.reshape(-1, 3),
        vertex_normals=None if normal is None else np.asarray(
            normal, dtype=np.float64)[vertex],
        visual=trimesh.visual.TextureVisuals(uv=unique[:, 1:],
                                             material=material),
        process=False)
    data = trimesh.exchange.gltf.export_glb(trimesh.Scene(mesh),
                                            include_normals=normal is not None)
    atomic_write(path, lambda f: f.write(data), 'wb')
    return path


#: Texture files of :func:`write_textured_model`, by map (every map of
#: :data:`~tg_intrinsic.nn.svbrdf_result.MAP_INFO`).
TEXTURE_FILES = {name: f'{name}_texture.png' for name in MAP_INFO}
#: The glTF binary of :func:`write_textured_model`.
GLB_FILE = 'svbrdf.glb'


def write_textured_model(folder: str, pos, face, maps: dict, size: int,
                         face_uv=None, normal=None) -> dict:
    r"""Writes per-vertex material maps as textures and a glTF binary.

    The maps become :math:`N \times N` textures on the mesh's UVs
    (:func:`~tg_intrinsic.geometry.uv_atlas` makes an atlas when there are
    none), written with a textured glTF binary: the files of
    :data:`TEXTURE_FILES` (base colour sRGB-encoded; the other maps as
    linear grey values over their range in
    :data:`~tg_intrinsic.nn.svbrdf_result.MAP_INFO`: [0, 1], and [0, 0.1]
    for ``roughness_std``) and :data:`GLB_FILE`, each
    written atomically into ``folder``. Baking
    (:func:`~tg_intrinsic.geometry.bake_texture`) runs on the CPU.

    Args:
        folder (str): An existing folder.
        pos (torch.Tensor): Vertices :math:`(V, 3)`.
        face (torch.Tensor): Triangles :math:`(3, F)`.
        maps (dict): ``base_color`` :math:`(V, 3)`, ``metallic``,
            ``roughness`` and optionally ``entropy`` and ``roughness_std``
            :math:`(V)` (numpy or torch).
        size (int): Texture side :math:`N`.
        face_uv (torch.Tensor, optional): UVs per corner :math:`(3, F, 2)`.
            (default: :obj:`None`, an atlas is made)
        normal (torch.Tensor, optional): Vertex normals :math:`(V, 3)`.
            (default: :obj:`None`)

    Returns:
        dict: ``files`` (the written paths), ``uv`` (``'mesh'``,
        ``'xatlas'`` or ``'grid'``), ``size`` (:math:`N`) and ``coverage`` (the fraction
        of texels a triangle covers).
    """
    import os
    import torch
    from tg_intrinsic.geometry import bake_texture
    pos = torch.as_tensor(pos).detach().cpu().double()
    face = torch.as_tensor(face).detach().cpu()
    uv = 'mesh'
    if face_uv is None:
        face_uv, uv = _atlas(pos, face)
    else:
        face_uv = torch.as_tensor(face_uv).detach().cpu().double()
    # every map's columns side by side: one rasterisation for all of them
    keys = [key for key in TEXTURE_FILES if key in maps]
    columns = [np.asarray(maps[key], dtype=np.float64).reshape(
        len(pos), -1) for key in keys]
    texture, coverage = bake_texture(
        torch.from_numpy(np.concatenate(columns, 1)), face, face_uv,
        (size, size))
    widths = np.cumsum([0] + [c.shape[1] for c in columns])
    textures, files = {}, []
    for key, start, stop in zip(keys, widths[:-1], widths[1:]):
        textures[key] = texture[..., start:stop].squeeze(-1).numpy()
        image = srgb_encode(textures[key]) if key == 'base_color' \
            else scaled_to_range(key, textures[key])
        files.append(write_png(os.path.join(folder, TEXTURE_FILES[key]),
                               image))
    files.append(write_glb(
        os.path.join(folder, GLB_FILE), pos.numpy(), face.t().numpy(),
        face_uv.numpy(), textures['base_color'], textures['metallic'],
        textures['roughness'],
        None if normal is None else torch.as_tensor(normal).detach().cpu()
        .double().numpy()))
    return {'files': files, 'uv': uv,
            'size': size, 'coverage': float(coverage.double().mean())}


#: Meshes with more triangles get the grid atlas: xatlas takes minutes
#: and more (3.4 s for 20k triangles on 2 cores, and its charts are merged
#: super-linearly) and crashed on an 82k-triangle icosphere.
XATLAS_MAX_FACES = 40000


def _atlas(pos, face):
    """UVs for a mesh without them: xatlas' charts up to
    :data:`XATLAS_MAX_FACES` triangles, else (or when xatlas fails) the
    grid atlas, with a warning that says why."""
    import warnings
    from tg_intrinsic.geometry import uv_atlas
    if face.size(1) <= XATLAS_MAX_FACES:
        try:
            return uv_atlas(pos, face), 'xatlas'
        except RuntimeError as error:
            why = f'{error}; '
    else:
        why = f'the mesh has {face.size(1)} triangles (xatlas is used up ' \
              f'to {XATLAS_MAX_FACES}); '
    warnings.warn(f"{why}the textures use a grid atlas (every pair of "
                  f"triangles its own square), which needs more texels than "
                  f"xatlas' charts", UserWarning, stacklevel=3)
    return uv_atlas(pos, face, method='grid'), 'grid'
