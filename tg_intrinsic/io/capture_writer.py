"""Writes one capture in any format :func:`~tg_intrinsic.io.read_capture`
reads (the examples of ``tg-intrinsic svbrdf --write-example --format``),
so that every reader can be checked against the native scene folder: the
same cameras, photographs, surface and lighting in each format's own
conventions."""
import os
import os.path as osp
import shutil

import numpy as np
import torch

from .scene import CAMERAS_FILE, GEOMETRY_NAME, IMAGE_FOLDER, write_scene

__all__ = ['WRITE_FORMATS', 'write_capture', 'ldr_exposure']

#: What :func:`write_capture` writes.
WRITE_FORMATS = ('native', 'colmap', 'colmap-bin', 'nerf', 'nerfstudio',
                 'orb')
#: The scene name of a written Stanford-ORB layout.
ORB_SCENE = 'example_scene001'
# the radiance percentile that an LDR example puts at 0.9 of the top code
_LDR_PERCENTILE = 0.995


def ldr_exposure(images: torch.Tensor) -> float:
    r"""An exposure :math:`S` for writing ``images`` as 8-bit photographs
    (decoded value :math:`= S L`): the 99.5th percentile of the radiance
    goes to 0.9, so few pixels clip."""
    values = images[torch.isfinite(images)].float().flatten()
    values = values[::max(1, values.numel() // 1000000)]
    level = float(torch.quantile(values, _LDR_PERCENTILE)) \
        if values.numel() else 1.0
    return float(np.float32(0.9 / max(level, 1e-12)))


def write_capture(folder, data, format: str, ldr: bool = False) -> dict:
    """Writes ``data`` (as :func:`~tg_intrinsic.io.write_scene` takes it)
    into ``folder`` in ``format`` (one of :data:`WRITE_FORMATS`): the
    photographs as EXR (or, with ``ldr``, 8-bit sRGB PNG at the exposure
    of :func:`ldr_exposure`), the surface and the lighting where the
    format keeps them. Returns ``{'capture': the path to read,
    'exposure': S or None, 'files': [...]}``."""
    if format not in WRITE_FORMATS:
        raise ValueError(f"'format' must be one of {WRITE_FORMATS}, got "
                         f"{format!r}")
    if ldr and format == 'native':
        raise ValueError("a native scene folder holds linear HDR "
                         "photographs; write LDR photographs in another "
                         "format (colmap, nerf, nerfstudio, orb)")
    folder = os.fspath(folder)
    if format == 'native':
        return {'capture': folder, 'exposure': None,
                'files': write_scene(folder, data)}
    from tg_intrinsic.geometry.appearance.envmap import blender_envmap
    blender = format in ('nerf', 'orb')
    scene = osp.join(folder, 'blender_LDR' if ldr else 'blender_HDR',
                     ORB_SCENE) if format == 'orb' else folder
    envmap = blender_envmap(data.envmap) if blender else data.envmap
    written = data.clone()
    written.envmap = envmap
    write_scene(scene, written)
    os.remove(osp.join(scene, CAMERAS_FILE))
    views = [{'image': f'{IMAGE_FOLDER}/{v:03d}.exr', 'K': K, 'R': E[:, :3],
              't': E[:, 3]} for v, (K, E) in enumerate(zip(
                  data.intrinsics.detach().cpu().double().numpy(),
                  data.extrinsics.detach().cpu().double().numpy()))]
    exposure = ldr_exposure(data.images) if ldr else None
    if ldr:
        for view, image in zip(views, data.images):
            view['image'] = _as_png(scene, view['image'], image, exposure)
    size = tuple(data.images.shape[1:3])
    if format in ('colmap', 'colmap-bin'):
        _write_colmap(folder, views, size, binary=format == 'colmap-bin')
    elif format == 'orb':
        _write_orb(folder, scene, views, size)
    else:
        from .transforms_json import write_transforms
        if format == 'nerf':  # Blender's file_path has no extension
            for view in views:
                view['image'] = osp.splitext(view['image'])[0]
        write_transforms(scene, views, format, size)
    return {'capture': scene, 'exposure': exposure,
            'files': sorted(_files(folder))}


def _as_png(folder: str, name: str, image: torch.Tensor,
            exposure: float) -> str:
    """Replaces a written EXR photograph by an 8-bit sRGB PNG."""
    from PIL import Image
    from .gltf import srgb_encode
    from tg_intrinsic.utils import atomic_write_file
    linear = np.nan_to_num(image.detach().cpu().double().numpy()) * exposure
    codes = np.round(srgb_encode(np.clip(linear, 0, 1)) * 255)
    png = osp.splitext(name)[0] + '.png'
    atomic_write_file(osp.join(folder, png), lambda path: Image.fromarray(
        codes.astype(np.uint8), 'RGB').save(path, format='PNG'),
        make_folder=False)
    os.remove(osp.join(folder, name))
    return png


def _write_colmap(folder: str, views, size, binary: bool):
    """One PINHOLE camera per distinct K, the images named as written."""
    from .colmap import write_colmap_model
    height, width = size
    cameras, images, ids = {}, [], {}
    for v, view in enumerate(views):
        K = view['K']
        key = tuple(np.round(K.ravel(), 12))
        if key not in ids:
            ids[key] = len(ids) + 1
            cameras[ids[key]] = {'model': 'PINHOLE', 'width': width,
                                 'height': height, 'params': np.array(
                                     [K[0, 0], K[1, 1], K[0, 2], K[1, 2]])}
        images.append({'image_id': v + 1, 'camera_id': ids[key],
                       'name': osp.basename(view['image']), 'R': view['R'],
                       't': view['t']})
    write_colmap_model(osp.join(folder, 'sparse', '0'), cameras, images,
                       binary=binary)


def _write_orb(root: str, scene: str, views, size):
    """The Stanford-ORB layout: train/, train_mask/ and
    transforms_train.json beside the mesh and envmap in ground_truth/."""
    from PIL import Image
    from .transforms_json import write_transforms
    from .mesh import read_surface
    os.makedirs(osp.join(scene, 'train'), exist_ok=True)
    os.makedirs(osp.join(scene, 'train_mask'), exist_ok=True)
    for v, view in enumerate(views):
        extension = osp.splitext(view['image'])[1]
        name = f'train/{v:04d}'
        os.replace(osp.join(scene, view['image']),
                   osp.join(scene, name + extension))
        view['image'] = name
        Image.fromarray(np.full(size, 255, np.uint8), 'L').save(
            osp.join(scene, 'train_mask', f'{v:04d}.png'))
    shutil.rmtree(osp.join(scene, IMAGE_FOLDER))
    write_transforms(scene, views, 'nerf', size,
                     name='transforms_train.json')
    truth = osp.join(root, 'ground_truth', ORB_SCENE)
    os.makedirs(osp.join(truth, 'mesh_blender'), exist_ok=True)
    os.makedirs(osp.join(truth, 'env_map'), exist_ok=True)
    pos, face, properties = read_surface(osp.join(scene, GEOMETRY_NAME))
    lines = [f'v {x!r} {y!r} {z!r}' for x, y, z in pos.tolist()]
    if 'nx' in properties:  # smooth shading: one normal per vertex
        lines += [f'vn {x!r} {y!r} {z!r}' for x, y, z in zip(
            *(properties[k].tolist() for k in ('nx', 'ny', 'nz')))]
        lines += [f'f {a + 1}//{a + 1} {b + 1}//{b + 1} {c + 1}//{c + 1}'
                  for a, b, c in face.tolist()]
    else:
        lines += [f'f {a + 1} {b + 1} {c + 1}' for a, b, c in face.tolist()]
    with open(osp.join(truth, 'mesh_blender', 'mesh.obj'), 'w') as f:
        f.write('\n'.join(lines) + '\n')
    os.remove(osp.join(scene, GEOMETRY_NAME))
    for name in os.listdir(scene):
        if name.startswith('envmap.'):
            os.replace(osp.join(scene, name), osp.join(
                truth, 'env_map', '0000' + osp.splitext(name)[1]))


def _files(folder: str):
    for top, _, names in os.walk(folder):
        for name in names:
            yield osp.join(top, name)
