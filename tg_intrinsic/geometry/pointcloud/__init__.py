r"""Point clouds: neighbourhoods, normals and tangent frames, moving least
squares, and the surface operators (gradient, divergence, curl, Laplacians)
built from them; Perona-Malik diffusion with those operators."""
from .neighbors import knn, radius, fps
from .frames import estimate_normals, tangent_frames
from .mls import mls_grad_div, build_mls_operators
from .operators import SurfaceOperators, VectorCalculus
from .sampling import sample_surface
from .diffusion import perona_malik

__all__ = ['knn', 'radius', 'fps', 'estimate_normals', 'tangent_frames',
           'mls_grad_div', 'build_mls_operators',
           'SurfaceOperators', 'VectorCalculus', 'sample_surface', 'perona_malik']
