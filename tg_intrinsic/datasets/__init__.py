r"""Offline, deterministic datasets of curved surfaces (no downloads).

* :class:`SyntheticSHREC`: SHREC'11-style non-rigid closed meshes for
  classification and part segmentation.
* :class:`SyntheticModelNet`: ModelNet-style rigid objects as point clouds
  with normals.
* :class:`MeshFolder`: a real dataset stored as
  ``root/<class>/<split>/*.obj|*.off|*.ply``.
* :func:`svbrdf_scene`: a multi-view capture of a sphere or mesh with a
  spatially varying principled BRDF under an environment map, rendered by
  an independent estimator of the reflection integral (ground truth for
  SVBRDF recovery); :func:`look_at_cameras` builds its pinhole cameras.
* :func:`bumpy_torus`: a closed bumpy torus of any size, for solvers.
"""
from .synthetic_shrec import SyntheticSHREC
from .synthetic_modelnet import SyntheticModelNet
from .mesh_folder import MeshFolder
from .svbrdf_scene import svbrdf_scene, look_at_cameras
from .surfaces import bumpy_torus

__all__ = [
    'SyntheticSHREC',
    'SyntheticModelNet',
    'MeshFolder',
    'svbrdf_scene',
    'look_at_cameras',
    'bumpy_torus',
]
