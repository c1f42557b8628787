r"""Data transforms: read a :class:`~torch_geometric.data.Data`, call
:mod:`tg_intrinsic.geometry`, write attributes. Inputs are never mutated.

On a collated :class:`~torch_geometric.data.Batch`, every transform runs on
each of its graphs alone and collates the results again: the output equals
applying the transform to every sample and collating them (``ptr``,
``batch`` and index offsets fit the new graphs, and
:meth:`~torch_geometric.data.Batch.to_data_list` works). Random
augmentations (:class:`RandomRotation`, :class:`RandomAxisScale`,
:class:`RandomTranslation`) therefore draw independent randomness for
every graph, one graph after the other, as per-sample augmentation does.
:class:`TextureTexels`, whose output PyG cannot collate, refuses a batch
with a :class:`ValueError`, as does any transform whose results differ in
their keys between the graphs (e.g. :class:`GravoHierarchy` giving them
different numbers of levels)."""
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
from .select_views import SelectViews, join_lightings, keep_views
from .clean_mesh import CleanMesh
from .decimate import Decimate
from .farthest_point_resample import FarthestPointResample
from .texture_texels import TextureTexels
from .pooling_levels import PoolingLevels

__all__ = ['EstimateNormals', 'TangentFrames', 'MLSOperators',
           'RandomRotation', 'RandomAxisScale', 'RandomTranslation',
           'NormalizeArea', 'LogMap', 'ParallelTransport',
           'MultiscaleSupports', 'HarmonicPrecompute', 'GravoHierarchy',
           'ProjectViews', 'FitSphericalHarmonics', 'SpectralUncertainty',
           'SelectViews', 'keep_views', 'join_lightings', 'CleanMesh',
           'Decimate', 'FarthestPointResample', 'TextureTexels',
           'PoolingLevels']
