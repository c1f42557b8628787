r"""Geodesics on meshes and point clouds: geodesic neighbourhoods by fast
marching, logarithmic maps and parallel transport (fast, vector heat and
affine heat), and the circular-harmonic terms that HSN layers consume."""
from .logmap import (geodesic_neighbourhoods, log_map, vertex_area_weights,
                     estimate_disc_edges, check_disc_memory)
from .harmonic import (ring_weights, harmonic_terms, check_harmonic_graph,
                       harmonic_layout, HarmonicOperator, transport_features)
from .distance import geodesic_distances

__all__ = ['geodesic_neighbourhoods', 'log_map', 'vertex_area_weights',
           'estimate_disc_edges', 'check_disc_memory',
           'ring_weights', 'harmonic_terms', 'check_harmonic_graph',
           'harmonic_layout', 'HarmonicOperator', 'transport_features',
           'geodesic_distances']
