r"""Data transforms: read a :class:`~torch_geometric.data.Data`, call
:mod:`tg_intrinsic.geometry`, write attributes. Inputs are never mutated."""
from .estimate_normals import EstimateNormals
from .tangent_frames import TangentFrames
from .mls_operators import MLSOperators
from .random_rotation import RandomRotation
from .random_axis_scale import RandomAxisScale
from .random_translation import RandomTranslation
from .normalize_area import NormalizeArea
from .log_map import LogMap
from .parallel_transport import ParallelTransport
from .multiscale_supports import MultiscaleSupports
from .harmonic_precompute import HarmonicPrecompute
from .gravo_hierarchy import GravoHierarchy
from .project_views import ProjectViews
from .fit_spherical_harmonics import FitSphericalHarmonics
from .spectral_uncertainty import SpectralUncertainty
from .select_views import SelectViews, keep_views
from .clean_mesh import CleanMesh
from .decimate import Decimate
from .farthest_point_resample import FarthestPointResample
from .texture_texels import TextureTexels
from .pooling_levels import PoolingLevels

__all__ = ['EstimateNormals', 'TangentFrames', 'MLSOperators',
           'RandomRotation', 'RandomAxisScale', 'RandomTranslation',
           'NormalizeArea', 'LogMap', 'ParallelTransport',
           'MultiscaleSupports', 'HarmonicPrecompute', 'GravoHierarchy', 'ProjectViews',
           'FitSphericalHarmonics', 'SpectralUncertainty', 'SelectViews',
           'keep_views', 'CleanMesh', 'Decimate', 'FarthestPointResample',
           'TextureTexels', 'PoolingLevels']
