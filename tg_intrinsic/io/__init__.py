"""File input and output: HDR images and environment maps, meshes and
point clouds with per-vertex properties, segmentation label files, and
figures of values drawn on surfaces."""
from .hdr import read_hdr, write_hdr, read_exr, read_envmap, looks_clipped
from .mesh import (read_face_uv, read_mesh, read_surface, read_off,
                   read_signal, write_ply)
from .points import read_points, read_table
from .labels import (read_labels, read_soft_labels, meshcnn_edges,
                     label_kind, label_scores, scores_to_labels,
                     face_label_scores, edge_label_scores, check_labels,
                     to_int_labels)
from .scene import read_scene, write_scene, scene_summary

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
]
