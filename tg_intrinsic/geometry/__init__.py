r"""Pure tensor geometry: no :class:`~torch_geometric.data.Data`, no
:class:`torch.nn.Module`.

Edge convention (PyG's ``source_to_target`` flow): ``edge_index[0]`` is the
neighbour :math:`j`, ``edge_index[1]`` the centre :math:`i`. Triangles are
``[3, F]`` long tensors.
"""
from .neighbors import knn, radius, fps
from .frames import estimate_normals, tangent_frames
from .mesh import (face_areas, face_normals, vertex_normals, lumped_mass,
                   cotan_weights, cotan_laplacian, mesh_edges,
                   edge_face_counts, is_closed_manifold,
                   remove_unreferenced_vertices, normalize_area,
                   laplacian_spectrum, weld_vertices)
from .sparse import to_scipy, from_scipy
from .mls import mls_grad_div, build_mls_operators
from .operators import SurfaceOperators
from .logmap import geodesic_neighbourhoods, log_map, vertex_area_weights

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
    'mls_grad_div',
    'build_mls_operators',
    'SurfaceOperators',
    'geodesic_neighbourhoods',
    'log_map',
    'vertex_area_weights',
]
