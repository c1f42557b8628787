"""Stanford-ORB captures (Kuang et al., NeurIPS 2023 Datasets and
Benchmarks), in the blender layout the dataset ships::

    ROOT/
      blender_HDR/<scene>/              (or blender_LDR: PNG photographs)
        transforms_train.json           NeRF/Blender cameras
        train/0000.exr ...              the photographs
        train_mask/0000.png ...         the object masks
        transforms_test.json, test/, test_mask/
      ground_truth/<scene>/
        mesh_blender/mesh.obj           the scanned mesh, in the cameras' world
        env_map/0000.exr ...            the captured lighting (Blender's
                                        equirectangular convention)

A capture is named by the scene's folder (``ROOT/blender_HDR/<scene>``) or
by ``ROOT/<scene>``. The environment maps are captured per test view;
the first (sorted) lights the whole capture unless ``--envmap`` names
another, and the summary says which.
"""
import os
import os.path as osp
from typing import Optional

from .capture_views import CaptureSpec, assemble_capture
from .transforms_json import transforms_spec

__all__ = ['SPLITS', 'find_orb_scene', 'orb_spec', 'read_stanford_orb']

#: The splits of a scene: a transforms_<split>.json each.
SPLITS = ('train', 'test')
_RENDERINGS = ('blender_HDR', 'blender_LDR')


def find_orb_scene(path) -> Optional[tuple]:
    """``(root, rendering, scene)`` when ``path`` is a Stanford-ORB scene
    folder or ``ROOT/<scene>``; else :obj:`None`."""
    path = osp.abspath(os.fspath(path))
    parent, scene = osp.split(path)
    grandparent, rendering = osp.split(parent)
    if rendering in _RENDERINGS and osp.isdir(path) and \
            osp.isdir(osp.join(grandparent, 'ground_truth')):
        return grandparent, rendering, scene
    if osp.isdir(osp.join(parent, 'ground_truth')) and not osp.exists(path):
        for rendering in _RENDERINGS:
            if osp.isdir(osp.join(parent, rendering, scene)):
                return parent, rendering, scene
    return None


def orb_spec(path, split: str = 'train') -> CaptureSpec:
    """The views of a Stanford-ORB scene's split, with its mesh, first
    environment map and masks."""
    found = find_orb_scene(path)
    if found is None:
        raise ValueError(f"'{path}' is not a Stanford-ORB scene: give "
                         f"ROOT/blender_HDR/<scene> or ROOT/<scene>, where "
                         f"ROOT holds blender_HDR/ and ground_truth/")
    if split not in SPLITS:
        raise ValueError(f"'split' must be one of {SPLITS}, got {split!r}")
    root, rendering, scene = found
    folder = osp.join(root, rendering, scene)
    spec = transforms_spec(osp.join(folder, f'transforms_{split}.json'),
                           'nerf')
    for view in spec.views:
        stem = osp.splitext(osp.basename(view.image))[0]
        mask = osp.join(folder, f'{split}_mask', stem + '.png')
        view.mask = mask if osp.isfile(mask) else None
    truth = osp.join(root, 'ground_truth', scene)
    mesh = osp.join(truth, 'mesh_blender', 'mesh.obj')
    envmaps = sorted(n for n in os.listdir(osp.join(truth, 'env_map'))
                     if n.lower().endswith(('.exr', '.hdr'))) \
        if osp.isdir(osp.join(truth, 'env_map')) else []
    spec.format = 'orb'
    spec.geometry = mesh if osp.isfile(mesh) else None
    spec.envmap = osp.join(truth, 'env_map', envmaps[0]) if envmaps else None
    masked = sum(view.mask is not None for view in spec.views)
    spec.notes.append(f"Stanford-ORB scene '{scene}' ({rendering}, "
                      f"{split}); masks for {masked} of {len(spec.views)} "
                      f"photographs")
    if spec.envmap is not None:
        spec.notes.append(f"lit by env_map/{envmaps[0]} (first of "
                          f"{len(envmaps)})")
    return spec


def read_stanford_orb(path, split: str = 'train', **options):
    r"""Reads a Stanford-ORB scene (see the module) into the
    :class:`~torch_geometric.data.Data` of
    :func:`~tg_intrinsic.io.read_scene`.

    Args:
        path (str): ``ROOT/blender_HDR/<scene>`` or ``ROOT/<scene>``.
        split (str, optional): ``'train'`` or ``'test'``.
            (default: :obj:`'train'`)
        **options: Of :func:`~tg_intrinsic.io.capture_views.assemble_capture`.
    """
    return assemble_capture(orb_spec(path, split), **options)
