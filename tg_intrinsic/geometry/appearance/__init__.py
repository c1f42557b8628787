r"""Appearance: spherical harmonics, BRDF terms and their spectra,
environment maps, pinhole cameras, the reference lighting integral and its
torch tables over roughness, the rasteriser with point visibility, and the
greedy choice of views by expected entropy reduction, the observations
held per point, and photographs read from disk a view at a time."""
from .sh import (real_sh, fit_sh, power_spectrum, fibonacci_sphere,
                 light_directions, light_fit_matrix, schlick_fresnel,
                 smith_g1, principled_to_torrance_sparrow,
                 torrance_sparrow_to_principled)
from .envmap import (check_envmap, equirect_lookup, envmap_to_sh,
                     sh_to_envmap, irradiance, sun_sky_envmap)
from .cameras import camera_centers, project, look_at_cameras
from .lighting import render_radiance
from .raster import rasterize, point_visibility
from .view_selection import select_views
from .direct_lighting import reflection_tables, direction_visibility
from .observations import compact_observations, observed_slots
from .photograph_stack import PhotographStack

__all__ = ['real_sh', 'fit_sh', 'power_spectrum', 'fibonacci_sphere',
           'light_directions', 'light_fit_matrix',
           'schlick_fresnel', 'smith_g1', 'principled_to_torrance_sparrow',
           'torrance_sparrow_to_principled', 'check_envmap',
           'equirect_lookup', 'envmap_to_sh', 'sh_to_envmap', 'irradiance',
           'sun_sky_envmap', 'camera_centers', 'project', 'look_at_cameras',
           'render_radiance', 'rasterize', 'point_visibility',
           'select_views', 'reflection_tables', 'direction_visibility',
           'compact_observations', 'observed_slots', 'PhotographStack']
