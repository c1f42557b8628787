"""File input and output: HDR images and environment maps."""
from .hdr import read_hdr, write_hdr, read_exr, read_envmap, looks_clipped

__all__ = [
    'read_hdr',
    'write_hdr',
    'read_exr',
    'read_envmap',
    'looks_clipped',
]
