"""File input and output: HDR images and environment maps, meshes and
point clouds with per-vertex properties, segmentation label files,
figures of values drawn on surfaces, and captures for SVBRDF recovery in
the formats people have (the native scene folder, COLMAP, transforms.json,
Stanford-ORB; HDR or LDR photographs, masks)."""
from .hdr import read_hdr, write_hdr, read_exr, read_envmap, looks_clipped
from .mesh import (read_face_uv, read_mesh, read_surface, read_off,
                   read_signal, write_ply)
from .points import read_points, read_table
from .labels import (read_labels, read_soft_labels, meshcnn_edges,
                     label_kind, label_scores, scores_to_labels,
                     face_label_scores, edge_label_scores, check_labels,
                     to_int_labels)
from .scene import read_scene, write_scene, scene_summary
from .photographs import read_ldr, read_mask, exif_exposure, srgb_to_linear
from .colmap import (read_colmap, read_colmap_model, write_colmap_model,
                     camera_matrix)
from .transforms_json import read_transforms
from .stanford_orb import read_stanford_orb
from .capture import CAPTURE_FORMATS, detect_format, read_capture
from .capture_writer import write_capture

__all__ = [
    'read_hdr',
    'write_hdr',
    'read_exr',
    'read_envmap',
    'looks_clipped',
    'read_mesh',
    'read_surface', 'read_face_uv',
    'read_off',
    'read_signal',
    'write_ply',
    'read_points',
    'read_table',
    'read_labels',
    'read_soft_labels',
    'meshcnn_edges',
    'label_kind',
    'label_scores',
    'scores_to_labels',
    'face_label_scores',
    'edge_label_scores',
    'check_labels',
    'to_int_labels',
    'read_scene',
    'write_scene',
    'scene_summary',
    'read_ldr', 'read_mask', 'exif_exposure', 'srgb_to_linear',
    'read_colmap', 'read_colmap_model', 'write_colmap_model',
    'camera_matrix',
    'read_transforms',
    'read_stanford_orb',
    'CAPTURE_FORMATS', 'detect_format', 'read_capture',
    'write_capture',
]
