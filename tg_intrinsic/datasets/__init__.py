r"""Offline, deterministic datasets of curved surfaces (no downloads).

* :class:`SyntheticSHREC`: SHREC'11-style non-rigid closed meshes for
  classification and part segmentation.
* :class:`SyntheticModelNet`: ModelNet-style rigid objects as point clouds
  with normals.
* :class:`MeshFolder`: a real dataset stored as
  ``root/<class>/<split>/*.obj|*.off|*.ply``.
"""
from .synthetic_shrec import SyntheticSHREC
from .synthetic_modelnet import SyntheticModelNet
from .mesh_folder import MeshFolder

__all__ = [
    'SyntheticSHREC',
    'SyntheticModelNet',
    'MeshFolder',
]
from .svbrdf_scene import svbrdf_scene, look_at_cameras  # noqa: E402
__all__ += ['svbrdf_scene', 'look_at_cameras']
