r"""Pure tensor geometry: no :class:`~torch_geometric.data.Data`, no
:class:`torch.nn.Module`. Tensors in, tensors out (numpy and numba inside),
split by domain:

- :mod:`~tg_intrinsic.geometry.pointcloud`: neighbours, normals and frames,
  moving least squares, surface operators;
- :mod:`~tg_intrinsic.geometry.geodesics`: fast marching, log maps, vector
  and affine heat, circular-harmonic terms;
- :mod:`~tg_intrinsic.geometry.multigrid`: Gravo MG sampling, Voronoi cells,
  prolongation;
- :mod:`~tg_intrinsic.geometry.appearance`: spherical harmonics, BRDF terms,
  environment maps, cameras, the lighting integral, rasterisation;

with the triangle-mesh basics every domain uses (:mod:`.mesh`), the
texture space of UV-mapped meshes (:mod:`.texture`), sparse conversions
(:mod:`.sparse`) and the input checks of the whole library
(:mod:`.checks`).

Edge convention (PyG's ``source_to_target`` flow): ``edge_index[0]`` is the
neighbour :math:`j`, ``edge_index[1]`` the centre :math:`i`. Triangles are
``[3, F]`` long tensors.
"""
import importlib
import importlib.abc
import importlib.util
import sys
import types
import warnings

from .pointcloud import (knn, radius, fps, estimate_normals, tangent_frames,
                         mls_grad_div, build_mls_operators, SurfaceOperators)
from .mesh import (face_areas, face_normals, vertex_normals, lumped_mass,
                   cotan_weights, cotan_laplacian, mesh_edges,
                   edge_face_counts, is_closed_manifold,
                   remove_unreferenced_vertices, normalize_area,
                   laplacian_spectrum, weld_vertices)
from .sparse import to_scipy, from_scipy
from .texture import (bake_texture, rasterize_uv, texture_grid_edges,
                      uv_atlas, grid_atlas, uv_sphere)
from .geodesics import geodesic_neighbourhoods, log_map, vertex_area_weights

__all__ = [
    'knn',
    'radius',
    'fps',
    'estimate_normals',
    'tangent_frames',
    'face_areas',
    'face_normals',
    'vertex_normals',
    'lumped_mass',
    'cotan_weights',
    'cotan_laplacian',
    'mesh_edges',
    'edge_face_counts',
    'is_closed_manifold',
    'remove_unreferenced_vertices',
    'normalize_area',
    'laplacian_spectrum',
    'weld_vertices',
    'to_scipy',
    'from_scipy',
    'rasterize_uv',
    'texture_grid_edges', 'uv_atlas', 'grid_atlas', 'bake_texture',
    'uv_sphere',
    'mls_grad_div',
    'build_mls_operators',
    'SurfaceOperators',
    'geodesic_neighbourhoods',
    'log_map',
    'vertex_area_weights',
]

# The module paths before the split by domain (version 0.1), kept importable
# with a DeprecationWarning so that user code does not break.
MOVED_MODULES = {
    'neighbors': 'pointcloud.neighbors',
    'frames': 'pointcloud.frames',
    'mls': 'pointcloud.mls',
    'operators': 'pointcloud.operators',
    'sampling': 'pointcloud.sampling',
    'logmap': 'geodesics.logmap',
    'harmonic': 'geodesics.harmonic',
    'gravo': 'multigrid.gravo',
    'voronoi': 'multigrid.voronoi',
    'sh': 'appearance.sh',
    'brdf': 'appearance.brdf',
    'envmap': 'appearance.envmap',
    'cameras': 'appearance.cameras',
    # render.py was split by job; its public names live on in these.
    'render': ('appearance.lighting', 'appearance.raster',
               'appearance.cameras', '..datasets.capture'),
}


class _MovedModuleFinder(importlib.abc.MetaPathFinder, importlib.abc.Loader):
    """Imports ``tg_intrinsic.geometry.<old name>`` as its new module."""

    def find_spec(self, fullname, path=None, target=None):
        package, _, short = fullname.rpartition('.')
        if package == __name__ and short in MOVED_MODULES:
            return importlib.util.spec_from_loader(fullname, self)
        return None

    def create_module(self, spec):
        short = spec.name.rpartition('.')[2]
        target = MOVED_MODULES[short]
        if isinstance(target, str):
            new = f'{__name__}.{target}'
            warnings.warn(f"'{spec.name}' moved to '{new}'; import it from "
                          f"there", DeprecationWarning, stacklevel=2)
            module = importlib.import_module(new)
            spec.loader_state = module.__spec__  # see exec_module
            return module
        parts = [importlib.import_module(name, __name__) if name[0] == '.'
                 else importlib.import_module(f'{__name__}.{name}')
                 for name in target]
        warnings.warn(f"'{spec.name}' was split into " + ', '.join(
            f"'{part.__name__}'" for part in parts) + "; import from those",
            DeprecationWarning, stacklevel=2)
        module = types.ModuleType(spec.name)
        for part in parts:
            for name in getattr(part, '__all__', ()):
                setattr(module, name, getattr(part, name))
        return module

    def exec_module(self, module):
        # The import system has just set the moved module's __spec__ to
        # the old name's; put its own back, or its relative imports would
        # resolve against the old package (Python 3.12 warns "__package__
        # != __spec__.parent" at each) and importlib.reload would miss it.
        if module.__spec__.loader_state is not None:
            module.__spec__ = module.__spec__.loader_state


if not any(isinstance(finder, _MovedModuleFinder) for finder in sys.meta_path):
    sys.meta_path.append(_MovedModuleFinder())
