"""File input and output: HDR images and environment maps, meshes and
point clouds with per-vertex properties, and figures of values drawn on
surfaces."""
from .hdr import read_hdr, write_hdr, read_exr, read_envmap, looks_clipped
from .mesh import read_mesh, read_surface, read_off, read_signal, write_ply
from .scene import read_scene, write_scene, scene_summary

__all__ = [
    'read_hdr',
    'write_hdr',
    'read_exr',
    'read_envmap',
    'looks_clipped',
    'read_mesh',
    'read_surface',
    'read_off',
    'read_signal',
    'write_ply',
    'read_scene',
    'write_scene',
    'scene_summary',
]
