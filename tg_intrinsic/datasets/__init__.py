r"""Offline, deterministic datasets of curved surfaces (no downloads).

* :class:`SyntheticSHREC`: SHREC'11-style non-rigid closed meshes for
  classification and part segmentation.
* :class:`SyntheticModelNet`: ModelNet-style rigid objects as point clouds
  with normals.
* :class:`MeshFolder`: meshes stored as
  ``root/<class>/<split>/*.obj|*.off|*.ply`` (classification; ModelNet's
  ``.off`` release, MeshCNN's SHREC'11) or ``root/<split>/*`` with label
  files (segmentation; MeshCNN's human_seg / coseg with ``.eseg`` files).
* :class:`PointCloudFolder`: the same layouts for point clouds
  (``.ply|.txt|.xyz|.npy|.pts``).
* :class:`ModelNetResampled`, :class:`ShapeNetPartNormal`,
  :class:`ScanObjectNN`: standard point cloud benchmarks read from the
  user's local copy (PointNet++'s ModelNet and ShapeNet-Part releases,
  ScanObjectNN's HDF5 files); nothing is downloaded. :func:`open_folder`
  picks the reader from the files a folder holds.
* :func:`svbrdf_scene`: a multi-view capture of a sphere or mesh with a
  spatially varying principled BRDF under an environment map, rendered by
  an independent estimator of the reflection integral (ground truth for
  SVBRDF recovery); :func:`look_at_cameras` builds its pinhole cameras.
* :func:`bumpy_torus`: a closed bumpy torus of any size, for solvers.
* :class:`SyntheticShapeParts`: ShapeNet-Part-style part segmentation of
  objects composed from primitives (5 categories, 16 parts).
* :class:`SyntheticCorrespondence`: one template mesh in many
  near-isometric poses (dense correspondence, FAUST-style), with
  :func:`correspondence_accuracy`.
* :class:`SphereDigits`: scikit-learn's 8 x 8 digits on an icosphere,
  upright or rotated (HSN's rotated MNIST on a sphere).
* :class:`PrecomputedOnDisk`: precomputed examples (operators, log maps,
  hierarchies) in an on-disk database, written by parallel workers.
"""
from .synthetic_shrec import SyntheticSHREC
from .synthetic_modelnet import SyntheticModelNet
from .mesh_folder import MeshFolder
from .point_cloud_folder import PointCloudFolder
from .modelnet_resampled import ModelNetResampled
from .shapenet_part_normal import ShapeNetPartNormal
from .scanobjectnn import ScanObjectNN
from .folder import open_folder
from .svbrdf_scene import svbrdf_scene, look_at_cameras
from .surfaces import bumpy_torus
from .synthetic_parts import SyntheticShapeParts
from .synthetic_correspondence import (SyntheticCorrespondence,
                                       correspondence_accuracy)
from .sphere_digits import SphereDigits
from .precomputed_on_disk import PrecomputedOnDisk

__all__ = [
    'SyntheticSHREC',
    'SyntheticModelNet',
    'MeshFolder',
    'PointCloudFolder',
    'ModelNetResampled',
    'ShapeNetPartNormal',
    'ScanObjectNN',
    'open_folder',
    'svbrdf_scene',
    'look_at_cameras',
    'bumpy_torus',
    'SyntheticShapeParts',
    'SyntheticCorrespondence',
    'correspondence_accuracy',
    'SphereDigits',
    'PrecomputedOnDisk',
]
