r"""Data transforms: read a :class:`~torch_geometric.data.Data`, call
:mod:`tg_intrinsic.geometry`, write attributes. Inputs are never mutated."""
from .estimate_normals import EstimateNormals
from .tangent_frames import TangentFrames
from .mls_operators import MLSOperators
from .random_rotation import RandomRotation
from .normalize_area import NormalizeArea
from .log_map import LogMap
from .parallel_transport import ParallelTransport
from .multiscale_supports import MultiscaleSupports
from .harmonic_precompute import HarmonicPrecompute
from .gravo_hierarchy import GravoHierarchy

__all__ = ['EstimateNormals', 'TangentFrames', 'MLSOperators',
           'RandomRotation', 'NormalizeArea', 'LogMap', 'ParallelTransport',
           'MultiscaleSupports', 'HarmonicPrecompute', 'GravoHierarchy']
