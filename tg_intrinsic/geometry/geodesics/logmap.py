r"""Geodesic neighbourhoods, log maps and parallel transport on surfaces, the
precomputation of Harmonic Surface Networks (Wiersma et al., "CNNs on
surfaces using rotation-equivariant features", SIGGRAPH 2020).

Edges follow PyG's ``source_to_target`` flow: ``edge_index[0]`` is the
neighbour :math:`j`, ``edge_index[1]`` the centre :math:`i`, and an edge
:math:`(j \to i)` carries quantities *at i about j*, in the tangent frame
:math:`(e_u(i), e_v(i), n_i)` of the centre (``frame[i]``, rows
:math:`e_u, e_v, n`):

* the log map of :math:`p_j` in the tangent plane of :math:`i` in polar form
  :math:`(r_{ij}, \theta_{ij})`: :math:`r_{ij}` is the geodesic distance and
  :math:`\theta_{ij}` the angle of :math:`\log_i(p_j)` from :math:`e_u(i)`
  towards :math:`e_v(i)`;
* the transport angle :math:`\phi_{ji}`: parallel transport along the
  shortest geodesic from :math:`j` to :math:`i` turns the vector at angle
  :math:`a` in :math:`j`'s frame into the vector at angle
  :math:`a + \phi_{ji}` in :math:`i`'s frame, so an order-:math:`M` complex
  feature transports as :math:`z \mapsto z \, e^{\mathrm{i} M \phi_{ji}}`.

Self-loops :math:`(i \to i)` get :math:`r = \theta = \phi = 0`. All angles
are wrapped to :math:`(-\pi, \pi]`.
"""
import importlib.util
import math
import warnings
from typing import Optional, Tuple

import numpy as np
import torch
from numba import get_num_threads, prange
from torch import Tensor

from . import vector_heat as _vector_heat
from .fast_marching import march_from, march_many, surface_index
from ..checks import (check_edge_index, check_faces, check_frames,
                      check_points, check_positive_float, check_positive_int,
                      check_referenced, check_tensor, check_vectors,
                      same_device)
from ..jit import jit
from ..mesh import (edge_face_counts, face_areas, lumped_mass,
                    triangle_cross, vertex_normals)
from ..pointcloud.frames import tangent_frames
from ..pointcloud.neighbors import knn, radius

__all__ = ['geodesic_neighbourhoods', 'log_map', 'vertex_area_weights',
           'estimate_disc_edges', 'check_disc_memory', 'hsn_bytes_per_edge',
           'graph_bytes_per_edge', 'MAX_DISC_MEMORY']

METHODS = ('fast', 'vector_heat')


# ----------------------------------------------------------------------------
# validation
# ----------------------------------------------------------------------------
def _check_mesh(pos: Tensor, face, strict: bool = False) -> Tensor:
    """Faces that the geodesic code can march on (and, with ``strict``,
    that geometry-central accepts)."""
    face = check_faces(face, pos.size(0), pos)
    if face.size(1) == 0:
        raise ValueError("'face' has no triangles; pass face=None to treat "
                         "the points as a point cloud")
    check_referenced(face, pos.size(0), 'triangle',
                     "no geodesic reaches them; drop them with CleanMesh() "
                     "or remove_unreferenced_vertices(pos, face)")
    triangle_cross(pos.double(), face)
    if strict:
        edges, count = edge_face_counts(face, pos.size(0))
        if bool((count > 2).any()):
            bad = edges[:, count > 2]
            raise ValueError(f"the mesh has {bad.size(1)} edge(s) shared by "
                             f"more than two triangles (first: "
                             f"{bad[:, 0].tolist()}); the vector heat method "
                             f"needs a manifold mesh, use method='fast' or "
                             f"repair the mesh")
        a = torch.cat([face[0], face[1], face[2]])
        b = torch.cat([face[1], face[2], face[0]])
        n = pos.size(0)
        _, directed = torch.unique(a * n + b, return_counts=True)
        if bool((directed > 1).any()):
            raise ValueError("the triangles are not consistently oriented "
                             "(a directed edge occurs twice); the vector heat "
                             "method needs an oriented manifold mesh, e.g. "
                             "fix it with trimesh's fix_winding()")
    return face


def _check_welded(pos: Tensor):
    """Mesh vertices at the same position are separate to the marching, so
    discs would stop at them: a triangle soup (STL files, some exporters)
    would give discs of one triangle, without any error."""
    p = pos.detach().cpu().numpy() + 0.0  # -0.0 equals 0.0
    order = np.lexsort(p.T[::-1])
    repeated = int((p[order[1:]] == p[order[:-1]]).all(1).sum())
    if repeated:
        raise ValueError(f"{repeated} mesh vertex/vertices "
                         f"repeat the position of another vertex (a "
                         f"triangle soup, or seams split for texture "
                         f"coordinates); geodesics cannot cross between "
                         f"such copies, so the discs would stop there. Weld "
                         f"them first: CleanMesh() before this transform, "
                         f"or weld_vertices(pos, face)")


def _check_centers(centers, pos: Tensor) -> Tensor:
    centers = check_tensor(centers, 'centers')
    if centers.dim() != 1 or centers.dtype != torch.long:
        raise ValueError(f"'centers' must be a 1-D torch.long tensor of "
                         f"point indices, got shape {list(centers.shape)} "
                         f"and dtype {centers.dtype}")
    same_device(centers, 'centers', pos)
    if centers.numel() > 0 and (int(centers.min()) < 0
                                or int(centers.max()) >= pos.size(0)):
        raise ValueError(f"'centers' must index the {pos.size(0)} points")
    if centers.unique().numel() != centers.numel():
        raise ValueError("'centers' holds repeated indices; pass each "
                         "centre once")
    return centers


def _frames_for(pos: Tensor, frame, face: Optional[Tensor]) -> Tensor:
    if frame is not None:
        frame = check_frames(frame, pos.size(0), pos)
        if frame.dtype != pos.dtype:
            raise ValueError(f"'frame' is {frame.dtype} but 'pos' is "
                             f"{pos.dtype}; convert one of them")
        return frame
    if face is None:
        raise ValueError("log maps of a point cloud need tangent frames: "
                         "estimate normals first and pass "
                         "frame=tangent_frames(estimate_normals(pos))")
    return tangent_frames(vertex_normals(pos, face))


# ----------------------------------------------------------------------------
# the 'fast' method
# ----------------------------------------------------------------------------
def _arc_factor(angle: Tensor) -> Tensor:
    r""":math:`a / (2 \sin(a / 2))`: arc length over chord on a circle whose
    tangents turn by :math:`a` between the two ends."""
    small = angle < 1e-3
    safe = torch.where(small, torch.ones_like(angle), angle)
    exact = safe / (2.0 * torch.sin(0.5 * safe))
    return torch.where(small, 1.0 + angle * angle / 24.0, exact)


# The per-edge maths below works on coordinate-major [3, E] tensors: dot and
# cross products of rows are plain elementwise operations, several times
# faster than reductions over a trailing dimension of size 3.
def _dot(a: Tensor, b: Tensor) -> Tensor:
    return a[0] * b[0] + a[1] * b[1] + a[2] * b[2]


def _cross(a: Tensor, b: Tensor) -> Tensor:
    return torch.stack([a[1] * b[2] - a[2] * b[1], a[2] * b[0] - a[0] * b[2],
                        a[0] * b[1] - a[1] * b[0]])


def _turn(n_i: Tensor, n_j: Tensor) -> Tuple[Tensor, Tensor, Tensor]:
    """Cosine, rotation axis (not normalised) and angle of the smallest
    rotation taking ``n_j`` to ``n_i`` (rows of [3, E] tensors)."""
    cos = _dot(n_i, n_j).clamp(-1.0, 1.0)
    axis = _cross(n_j, n_i)
    angle = torch.atan2(torch.sqrt(_dot(axis, axis)), cos)
    return cos, axis, angle


def _arc_distance(pos: Tensor, normal: Tensor, j: Tensor, i: Tensor
                  ) -> Tensor:
    p, n = pos.t(), normal.t()
    d = p[:, j] - p[:, i]
    _, _, angle = _turn(n[:, i], n[:, j])
    return torch.sqrt(_dot(d, d)) * _arc_factor(angle)


def _fast(pos: Tensor, frame: Tensor, edge_index: Tensor
          ) -> Tuple[Tensor, Tensor, Tensor]:
    if pos.device.type == 'cpu':
        return _fast_numba(pos, frame, edge_index)
    return _fast_torch(pos, frame, edge_index)


def _fast_numba(pos: Tensor, frame: Tensor, edge_index: Tensor
                ) -> Tuple[Tensor, Tensor, Tensor]:
    """One compiled pass over the edges (CPU, float64 inside)."""
    num = edge_index.size(1)
    out = np.empty((3, num))
    j, i = edge_index.numpy()
    _fast_kernel(pos.detach().double().numpy(),
                 frame.detach().double().contiguous().numpy(), j, i, out)
    out = torch.from_numpy(out).to(pos.dtype)
    return out[0], out[1], out[2]


@jit(parallel=True)
def _fast_kernel(pos, frame, nbr, ctr, out):  # pragma: no cover (numba)
    """:func:`_fast_torch`, edge by edge."""
    for e in prange(nbr.shape[0]):
        a = ctr[e]
        b = nbr[e]
        if a == b:
            out[0, e] = 0.0
            out[1, e] = 0.0
            out[2, e] = 0.0
            continue
        d = pos[b] - pos[a]
        u_i = frame[a, 0]
        v_i = frame[a, 1]
        n_i = frame[a, 2]
        n_j = frame[b, 2]
        cos = min(1.0, max(-1.0, n_i[0] * n_j[0] + n_i[1] * n_j[1]
                           + n_i[2] * n_j[2]))
        k0 = n_j[1] * n_i[2] - n_j[2] * n_i[1]
        k1 = n_j[2] * n_i[0] - n_j[0] * n_i[2]
        k2 = n_j[0] * n_i[1] - n_j[1] * n_i[0]
        angle = np.arctan2(np.sqrt(k0 * k0 + k1 * k1 + k2 * k2), cos)
        if angle < 1e-3:
            factor = 1.0 + angle * angle / 24.0
        else:
            factor = angle / (2.0 * np.sin(0.5 * angle))
        out[0, e] = np.sqrt(d[0] * d[0] + d[1] * d[1] + d[2] * d[2]) * factor
        out[1, e] = np.arctan2(d[0] * v_i[0] + d[1] * v_i[1] + d[2] * v_i[2],
                               d[0] * u_i[0] + d[1] * u_i[1] + d[2] * u_i[2])
        v = frame[b, 0]
        if 1.0 + cos > 1e-6:
            kv = (k0 * v[0] + k1 * v[1] + k2 * v[2]) / max(1.0 + cos, 1e-300)
            m0 = cos * v[0] + k1 * v[2] - k2 * v[1] + kv * k0
            m1 = cos * v[1] + k2 * v[0] - k0 * v[2] + kv * k1
            m2 = cos * v[2] + k0 * v[1] - k1 * v[0] + kv * k2
        else:
            uv = u_i[0] * v[0] + u_i[1] * v[1] + u_i[2] * v[2]
            m0 = 2.0 * uv * u_i[0] - v[0]
            m1 = 2.0 * uv * u_i[1] - v[1]
            m2 = 2.0 * uv * u_i[2] - v[2]
        out[2, e] = np.arctan2(m0 * v_i[0] + m1 * v_i[1] + m2 * v_i[2],
                               m0 * u_i[0] + m1 * u_i[1] + m2 * u_i[2])


def _fast_torch(pos: Tensor, frame: Tensor, edge_index: Tensor
                ) -> Tuple[Tensor, Tensor, Tensor]:
    """Vectorised over edges (any device); the reference for the numba
    kernel."""
    j, i = edge_index
    p = pos.t()
    e_u, e_v, n = (frame[:, k].t() for k in range(3))
    d = p[:, j] - p[:, i]
    u_i, v_i, n_i = e_u[:, i], e_v[:, i], n[:, i]
    cos, axis, angle = _turn(n_i, n[:, j])
    r = torch.sqrt(_dot(d, d)) * _arc_factor(angle)
    # Direction: the chord projected onto the tangent plane of i (exact on
    # spheres and planes, where the geodesic lies in the plane of the chord
    # and the normal); the normal component drops out of both dot products.
    theta = torch.atan2(_dot(d, v_i), _dot(d, u_i))
    # Transport: the smallest rotation taking n_j to n_i, applied to e_u(j):
    # R v = cos v + k x v + (k . v) k / (1 + cos), with k = n_j x n_i.
    v = e_u[:, j]
    denom = (1.0 + cos).clamp_min(torch.finfo(pos.dtype).eps)
    moved = cos * v + _cross(axis, v) + (_dot(axis, v) / denom) * axis
    # Opposite normals (a fold): no smallest rotation; turn by pi about e_u.
    flip = 1.0 + cos <= 1e-6
    if bool(flip.any()):
        half = u_i[:, flip]
        moved[:, flip] = 2.0 * _dot(half, v[:, flip]) * half - v[:, flip]
    phi = torch.atan2(_dot(moved, v_i), _dot(moved, u_i))
    loop = i == j
    zero = torch.zeros_like(r)
    return (torch.where(loop, zero, r), torch.where(loop, zero, theta),
            torch.where(loop, zero, phi))


# ----------------------------------------------------------------------------
# size of the disc graph, before building it
# ----------------------------------------------------------------------------
#: Default ``max_memory`` (bytes) of :func:`geodesic_neighbourhoods`,
#: :class:`~tg_intrinsic.transforms.LogMap` and
#: :class:`~tg_intrinsic.transforms.MultiscaleSupports`: 2 GiB. Above it they
#: raise a :class:`ValueError` before any heavy work; ``max_memory=None``
#: turns the check off.
MAX_DISC_MEMORY = 2 * 1024 ** 3
#: A warning is issued above this fraction of ``max_memory``.
DISC_MEMORY_WARN_FRACTION = 0.25
# Bytes per edge that building the graph itself holds at its peak: the
# marching's neighbour and distance arrays (int64, float64) and their
# concatenated copies, the centre index and the final [2, E] edge_index.
_GRAPH_TRANSIENT_BYTES = 56
# Vertex visits the sampled count may march in all (bounds its time to
# about half a second).
_SAMPLE_BUDGET = 100_000


def hsn_bytes_per_edge(dtype: torch.dtype = torch.float32, rings: int = 6,
                       max_order: int = 1, coarse_fraction: float = 0.25
                       ) -> float:
    r"""Bytes that the Harmonic Surface Network precomputation
    (:func:`tg_intrinsic.train.hsn_pipeline`) keeps per edge of the
    level-0 disc graph. They are

    .. math::
        b = \Big(\underbrace{16}_{\texttt{edge\_index}}
        + \underbrace{3 s}_{\texttt{logmap},\ \texttt{transport}}
        + \underbrace{2 s\, Q\, (P + 1)}_{\texttt{harmonic}}\Big)
        (1 + f),

    with :math:`s` the size of one real number of :obj:`dtype`, :math:`Q`
    rings, orders :math:`0, \dots, P` and :math:`f` the number of level-1
    edges per level-0 edge (a quarter of the points with twice the radius
    gives the same number of neighbours per point, so :math:`f \approx
    1/4`). For float32 and the paper's settings this is 155 bytes
    (measured on an icosphere: 151); for float64 290 (measured: 283).

    Args:
        dtype (torch.dtype, optional): Dtype of the positions.
            (default: :obj:`torch.float32`)
        rings (int, optional): Rings :math:`Q`. (default: :obj:`6`)
        max_order (int, optional): Highest order :math:`P`.
            (default: :obj:`1`)
        coarse_fraction (float, optional): :math:`f`.
            (default: :obj:`0.25`)
    """
    size = torch.empty(0, dtype=dtype).element_size()
    per_level = 16 + 3 * size + 2 * size * rings * (max_order + 1)
    return float(per_level * (1.0 + coarse_fraction))


def graph_bytes_per_edge(dtype: torch.dtype = torch.float32) -> float:
    """Bytes per edge that :func:`geodesic_neighbourhoods` holds at its
    peak: the marching's int64 neighbours and float64 distances (and their
    concatenated copies), the centre index, the returned ``edge_index``
    and distances in :obj:`dtype` (56 + 4 bytes for float32)."""
    return float(_GRAPH_TRANSIENT_BYTES
                 + torch.empty(0, dtype=dtype).element_size())


def _sample_size(num_centres: int, per_centre: float, num_samples: int
                 ) -> int:
    by_budget = int(_SAMPLE_BUDGET // max(per_centre, 1.0))
    return int(min(num_centres, max(8, min(num_samples, by_budget))))


def _disc_counts(pos: Tensor, eps: float, face: Optional[Tensor],
                 sample: np.ndarray, cap: int, index=None) -> np.ndarray:
    """Number of disc members (self included, at most ``cap``) of every
    sampled centre: fast marching on meshes, a Euclidean ball count on
    point clouds (the candidates the point-cloud path holds)."""
    if face is None:
        from scipy.spatial import cKDTree
        p = pos.detach().double().cpu().numpy()
        count = cKDTree(p).query_ball_point(p[sample], eps,
                                            return_length=True)
        return np.minimum(np.asarray(count, dtype=np.int64), cap)
    f = face.t().contiguous().cpu().numpy()
    if index is None:
        index = surface_index(pos.detach().double().cpu().numpy(), f)
    vf_ptr, vf_face, vf_corner, length = index
    n = pos.size(0)
    count = np.zeros(sample.size, dtype=np.int64)
    # The same marching as geodesic_neighbourhoods (slack and relaxation
    # sweeps matter on obtuse triangles), counting only (no output slots).
    spacing = float(length.mean())
    march_many(f, length, vf_ptr, vf_face, vf_corner, n,
               sample.astype(np.int64), eps + spacing, eps, min(cap, n),
               1e-6 * spacing, 0, np.empty((sample.size, 0), np.int64),
               np.empty((sample.size, 0)), count, 8 * get_num_threads())
    return count


def estimate_disc_edges(pos: Tensor, eps: float,
                        face: Optional[Tensor] = None,
                        centers: Optional[Tensor] = None,
                        max_neighbors: Optional[int] = None,
                        num_samples: int = 64, seed: int = 0) -> int:
    r"""Estimates the number of edges :math:`E` of the disc graph of
    :func:`geodesic_neighbourhoods` without building it. It uses the disc
    sizes of a random sample :math:`S` of the centres :math:`C`:

    .. math::
        E \approx \frac{|C|}{|S|} \sum_{i \in S}
        \min\big(|\mathcal{N}(i)|, K\big),

    where :math:`|\mathcal{N}(i)|` is counted by the same truncated fast
    marching on meshes (so boundaries, thin parts and uneven vertex density
    are accounted for, unlike in :math:`\pi \varepsilon^2 N / A`) and by a
    Euclidean ball count on point clouds (the candidates the point-cloud
    path holds; a few percent above the arc-corrected count). The sample
    has :obj:`num_samples` centres, fewer where the discs are so large that
    marching them would take long (at most about 100,000 vertex visits in
    all, well under a second; at least 8 centres), and every centre when
    there are no more. Within 10 % of the real count on spheres, tori,
    stretched and flattened shapes and point clouds (tested); a 50k-vertex
    scan of unit area at :math:`\varepsilon = 0.2` (300 million edges) is
    estimated in under a second.

    Args:
        pos (torch.Tensor): Points (mesh vertices).
        eps (float): Disc radius :math:`\varepsilon`.
        face (torch.Tensor, optional): Triangles in PyG layout.
            (default: :obj:`None`, a point cloud)
        centers (torch.Tensor, optional): Indices of the centres.
            (default: :obj:`None`, every point)
        max_neighbors (int, optional): The cap :math:`K` per disc.
            (default: :obj:`None`)
        num_samples (int, optional): Sampled centres. (default: :obj:`64`)
        seed (int, optional): Seed of the sample. (default: :obj:`0`)

    Shapes:
        - **input:** pos :math:`(N, 3)`, face :math:`(3, F)`,
          centers :math:`(M)`
        - **output:** an :class:`int`
    """
    pos = check_points(pos, min_points=1)
    eps = check_positive_float(eps, 'eps')
    num_samples = check_positive_int(num_samples, 'num_samples')
    n = pos.size(0)
    cap = n if max_neighbors is None else check_positive_int(max_neighbors,
                                                            'max_neighbors')
    centre_idx = (torch.arange(n) if centers is None
                  else _check_centers(centers, pos))
    if face is not None:
        face = _check_mesh(pos, face)
    return _estimate(pos, eps, face, centre_idx, cap, num_samples, seed)


def _estimate(pos, eps, face, centre_idx, cap, num_samples=64, seed=0,
              index=None) -> int:
    centre_idx = centre_idx.cpu().numpy()
    m = centre_idx.size
    if m == 0:
        return 0
    n = pos.size(0)
    if face is not None:
        area = float(face_areas(pos.detach().double().cpu(),
                                face.cpu()).sum())
        guess = min(n, math.pi * eps * eps * n / max(area, 1e-300))
    else:
        guess = float(num_samples)  # ball counts do not march
    size = _sample_size(m, min(guess, cap), num_samples)
    rng = np.random.default_rng(seed)
    sample = centre_idx if size >= m else \
        centre_idx[rng.choice(m, size=size, replace=False)]
    count = _disc_counts(pos, eps, face, sample, cap, index)
    return int(round(float(count.mean()) * m))


def _gib(num_bytes: float) -> str:
    if num_bytes >= 2 ** 30:
        return f"{num_bytes / 2 ** 30:.3g} GiB"
    return f"{num_bytes / 2 ** 20:.3g} MiB"


def check_disc_memory(num_edges: int, bytes_per_edge: float,
                      max_memory: Optional[float], eps: float,
                      num_points: int, num_centres: int,
                      what: str = 'the disc graph'):
    r"""Raises a :class:`ValueError` if ``num_edges * bytes_per_edge``
    exceeds :obj:`max_memory` (and warns above
    :data:`DISC_MEMORY_WARN_FRACTION` of it), naming the expected edges and
    memory and what would fit: a smaller radius, fewer vertices (with
    :class:`~tg_intrinsic.transforms.Decimate` or
    :class:`~tg_intrinsic.transforms.FarthestPointResample`), or a cap on
    the neighbours. The edge count grows like :math:`\varepsilon^2` and
    like :math:`N^2` (points times neighbours per point), which is what the
    suggestions use, with a 10 % margin."""
    if max_memory is None:
        return
    memory = float(num_edges) * float(bytes_per_edge)
    mean = num_edges / max(num_centres, 1)
    head = (f"{what} of radius {eps:g} would hold about {num_edges:,} edges "
            f"({mean:,.0f} neighbours per point over {num_centres:,} "
            f"centres among {num_points:,} points), and the per-edge data "
            f"kept for them about {_gib(memory)} ({bytes_per_edge:.0f} bytes "
            f"per edge)")
    if memory > max_memory:
        shrink = math.sqrt(max_memory / memory) * 0.9
        fit_eps = eps * shrink
        fit_points = max(1, int(num_points * shrink))
        fit_cap = max(1, int(max_memory / (bytes_per_edge
                                           * max(num_centres, 1)) * 0.9))
        raise ValueError(
            f"{head}, above max_memory={_gib(max_memory)}. Use a smaller "
            f"radius (about {fit_eps:.3g} fits), or fewer points (about "
            f"{fit_points:,} fit: add Decimate({fit_points}) or "
            f"FarthestPointResample({fit_points}) before this step; Harmonic "
            f"Surface Networks resample scans to 1024 points), or cap every "
            f"disc with max_neighbors={fit_cap}; or pass a larger max_memory "
            f"(max_memory=None builds it anyway)")
    if memory > DISC_MEMORY_WARN_FRACTION * max_memory:
        warnings.warn(f"{head}; this takes long and uses much memory (the "
                      f"limit is max_memory={_gib(max_memory)}). Consider "
                      f"a smaller radius or fewer points (Decimate, "
                      f"FarthestPointResample)", stacklevel=3)


def _guard_disc_size(pos, eps, face, centre_idx, cap, max_memory,
                     bytes_per_edge, index=None):
    """The check of :func:`geodesic_neighbourhoods`: skipped where even
    full discs stay below the warning threshold."""
    if max_memory is None:
        return
    max_memory = check_positive_float(max_memory, 'max_memory')
    m = centre_idx.numel()
    bound = float(m) * min(cap, pos.size(0)) * bytes_per_edge
    if bound <= DISC_MEMORY_WARN_FRACTION * max_memory:
        return
    edges = _estimate(pos, eps, face, centre_idx, cap, index=index)
    check_disc_memory(edges, bytes_per_edge, max_memory, eps, pos.size(0),
                      m)


# ----------------------------------------------------------------------------
# public API
# ----------------------------------------------------------------------------
def geodesic_neighbourhoods(pos: Tensor, eps: float,
                            face: Optional[Tensor] = None,
                            normal: Optional[Tensor] = None,
                            max_neighbors: Optional[int] = None,
                            centers: Optional[Tensor] = None,
                            max_memory: Optional[float] = MAX_DISC_MEMORY,
                            bytes_per_edge: Optional[float] = None
                            ) -> Tuple[Tensor, Tensor]:
    r"""Builds the geodesic disc graph, self-loops included. It holds every
    pair :math:`(j \to i)` whose geodesic distance is below
    :math:`\varepsilon`,

    .. math::
        \mathcal{N}(i) = \{ j : d(p_i, p_j) < \varepsilon \}.

    On a mesh, :math:`d` is computed by fast marching (Kimmel and Sethian,
    1998), truncated at :math:`\varepsilon`, from every centre in parallel
    (numba on the CPU): Dijkstra's order over vertices with distances
    updated through triangles unfolded into the plane, and relaxation
    sweeps that repair paths through obtuse triangles. It is exact on flat
    meshes up to rare pairs behind several obtuse triangles (at most 2 %
    too long on a strongly jittered grid), first-order accurate on curved
    ones (below 0.3 % relative error on a 2.5k-vertex unit icosphere), never
    leaves the surface (two sheets that nearly touch stay apart), and is
    much cheaper than any geodesic solve.

    On a point cloud, the candidates are the Euclidean ball of radius
    :math:`\varepsilon` (a superset, since geodesic distances are at least
    Euclidean) from :func:`radius`, and :math:`d` is the chord corrected for
    the angle :math:`a` between the normals, as on a circle arc,
    :math:`d = \|p_j - p_i\| \, a / (2 \sin(a / 2))`; without normals,
    :math:`d` is the Euclidean distance.

    Mesh vertices at the same position (a triangle soup) raise a
    :class:`ValueError`: the marching could not cross between them; weld
    them first (:class:`~tg_intrinsic.transforms.CleanMesh`).

    Centres whose disc holds no other point keep only their self-loop; if
    that happens to every centre, :math:`\varepsilon` is below the sampling
    spacing and a :class:`ValueError` says so.

    The graph grows like :math:`N^2 \varepsilon^2 / A` (a 50k-vertex scan
    of unit area at :math:`\varepsilon = 0.2` has about 300 million
    edges), so before building it the number of edges is estimated
    (:func:`estimate_disc_edges`, about a second at worst) and multiplied
    by :obj:`bytes_per_edge`; above :obj:`max_memory` a
    :class:`ValueError` names the expected edges and memory and what
    would fit (a smaller radius, fewer points, a cap on the neighbours),
    and above a quarter of it a warning is issued
    (:func:`check_disc_memory`). Graphs that stay small even with full
    discs skip the estimate.

    Args:
        pos (torch.Tensor): Points (mesh vertices).
        eps (float): Disc radius :math:`\varepsilon`, in the units of
            :obj:`pos`.
        face (torch.Tensor, optional): Triangles in PyG layout; without
            them :obj:`pos` is a point cloud. (default: :obj:`None`)
        normal (torch.Tensor, optional): Point-cloud normals for the arc
            correction (ignored for meshes). (default: :obj:`None`)
        max_neighbors (int, optional): Keep at most this many nearest
            neighbours per centre (the self-loop included).
            (default: :obj:`None`, no cap)
        centers (torch.Tensor, optional): Indices of the centres to build
            discs for. (default: :obj:`None`, every point)
        max_memory (float, optional): Most bytes the graph (times
            :obj:`bytes_per_edge`) may take; :obj:`None` disables the
            check. (default: :data:`MAX_DISC_MEMORY`, 2 GiB)
        bytes_per_edge (float, optional): Bytes that the caller keeps per
            edge, e.g. :func:`hsn_bytes_per_edge` for the whole HSN
            precomputation. (default: :obj:`None`: what this function holds
            at its peak, :func:`graph_bytes_per_edge`)

    Shapes:
        - **input:** pos :math:`(N, 3)`, face :math:`(3, F)`,
          normal :math:`(N, 3)`, centers :math:`(M)`
        - **output:** ``(edge_index, dist)``: :math:`(2, E)` sorted by centre
          and then by distance, and the distances :math:`(E)` in
          :obj:`pos`'s dtype
    """
    pos = check_points(pos, min_points=1)
    eps = check_positive_float(eps, 'eps')
    cap = (pos.size(0) if max_neighbors is None
           else check_positive_int(max_neighbors, 'max_neighbors'))
    if centers is None:
        centre_idx = torch.arange(pos.size(0), device=pos.device)
    else:
        centre_idx = _check_centers(centers, pos)
    if bytes_per_edge is None:
        bytes_per_edge = graph_bytes_per_edge(pos.dtype)
    else:
        bytes_per_edge = check_positive_float(bytes_per_edge,
                                              'bytes_per_edge')
    if face is not None:
        face = _check_mesh(pos, face)
        _check_welded(pos)
        p = pos.detach().double().cpu().numpy()
        f = face.t().contiguous().cpu().numpy()
        index = surface_index(p, f)
        _guard_disc_size(pos, eps, face, centre_idx, cap, max_memory,
                         bytes_per_edge, index)
        # March one mean edge length past eps, so that the relaxation sweeps
        # can repair distances up to eps; gains far below an edge length
        # (first-order noise on curved meshes) do not trigger more sweeps.
        spacing = float(index[3].mean())
        ptr, nbr, dist = march_from(f, index, centre_idx.cpu().numpy(), eps,
                                    cap, slack=spacing, tol=1e-6 * spacing)
        i = torch.from_numpy(np.repeat(centre_idx.cpu().numpy(),
                                       np.diff(ptr)))
        edge_index = torch.stack([torch.from_numpy(nbr), i]).to(pos.device)
        dist = torch.from_numpy(dist).to(pos.dtype).to(pos.device)
    else:
        if normal is not None:
            normal = check_vectors(normal, 'normal', pos.size(0), pos)
        _guard_disc_size(pos, eps, None, centre_idx, cap, max_memory,
                         bytes_per_edge)
        j, q = radius(pos, eps, max_num_neighbors=pos.size(0), loop=True,
                      query=pos[centre_idx])
        # Self-loops are added here, so that every centre has one.
        other = centre_idx[q] != j
        slot = torch.arange(centre_idx.numel(), device=pos.device)
        j = torch.cat([centre_idx, j[other]])
        q = torch.cat([slot, q[other]])
        i = centre_idx[q]
        if normal is not None:
            unit = normal / normal.norm(dim=-1, keepdim=True).clamp_min(
                torch.finfo(pos.dtype).tiny)
            dist = _arc_distance(pos, unit, j, i)
        else:
            dist = (pos[j] - pos[i]).norm(dim=-1)
        dist = torch.where(i == j, torch.zeros_like(dist), dist)
        keep = dist < eps
        i, j, dist = i[keep], j[keep], dist[keep]
        # Sort by centre slot, then distance; then cap every row.
        slot = q[keep]
        order = torch.argsort(dist, stable=True)
        order = order[torch.argsort(slot[order], stable=True)]
        i, j, dist, slot = i[order], j[order], dist[order], slot[order]
        count = torch.bincount(slot, minlength=centre_idx.numel())
        start = torch.cumsum(count, 0) - count
        rank = torch.arange(slot.numel(), device=pos.device) - start[slot]
        keep = rank < cap
        edge_index = torch.stack([j[keep], i[keep]])
        dist = dist[keep]
    if centre_idx.numel() > 0 and edge_index.size(1) == centre_idx.numel():
        raise ValueError(f"eps={eps:g} is smaller than the spacing of the "
                         f"points: every disc holds only its centre; "
                         f"increase eps (e.g. to a few mean edge lengths), "
                         f"or use a finer mesh (FarthestPointResample("
                         f"num_vertices) subdivides a coarse one)")
    return edge_index, dist


def log_map(pos: Tensor, edge_index: Tensor, frame: Optional[Tensor] = None,
            face: Optional[Tensor] = None, method: str = 'fast',
            margin: float = 8.0, workers: Optional[int] = None
            ) -> Tuple[Tensor, Tensor, Tensor]:
    r"""Log map in polar form and parallel-transport angle for every edge
    :math:`(j \to i)`, in the tangent frame of the centre :math:`i`. They
    satisfy

    .. math::
        \log_i(p_j) = r_{ij} \left(\cos\theta_{ij} \, e_u(i)
        + \sin\theta_{ij} \, e_v(i)\right), \qquad
        P_{j \to i}\, e_u(j) = \cos\phi_{ji} \, e_u(i)
        + \sin\phi_{ji} \, e_v(i),

    with :math:`P_{j \to i}` the parallel transport along the shortest
    geodesic. A vector at angle :math:`a` in :math:`j`'s frame arrives at
    angle :math:`a + \phi_{ji}`; rotating frame :math:`i` by :math:`\alpha`
    shifts :math:`\theta_{ij}` and :math:`\phi_{ji}` by :math:`-\alpha`, and
    rotating frame :math:`j` by :math:`\beta` shifts :math:`\phi_{ji}` by
    :math:`+\beta`.

    ``method='fast'`` (any device, float32/float64; a compiled loop over
    the edges on the CPU, vectorised torch elsewhere): the chord
    :math:`d = p_j - p_i` projected onto the tangent plane of :math:`i`
    gives :math:`\theta_{ij}`; its length corrected for the angle :math:`a`
    between the normals, :math:`r_{ij} = \|d\| \, a / (2 \sin(a/2))` (exact
    on a circle arc), gives :math:`r_{ij}`; and the smallest rotation taking
    :math:`n_j` to :math:`n_i`, applied to :math:`e_u(j)`, gives
    :math:`\phi_{ji}`. Exact on planes and spheres (with exact normals);
    elsewhere the error grows with the disc radius and the variation of the
    curvature across it (median 0.06 rad from the vector heat result on a
    unit-area scan at :math:`\varepsilon = 0.2`, see the benchmark).

    ``method='vector_heat'`` (CPU): the ``'AffineLocal'`` log map and the
    vector transport of the Vector Heat Method (Sharp, Soliman and Crane,
    2019), the quantities the original HSN code gets from geometry-central
    with one global solve each per vertex. On meshes they are computed by
    our own solver (:mod:`tg_intrinsic.geometry.geodesics.affine_heat`): on the
    intrinsic Delaunay triangulation (as potpourri3d does by default; the
    obtuse triangles of real meshes otherwise make heat flows change sign
    and directions flip), with the affine heat system split into its
    scalar and connection parts, one factorisation of each serving every
    centre, and the centres solved in blocks of right-hand sides with
    compiled triangular solves in ``workers`` threads. Its radii match
    potpourri3d's global solves to round-off; its angles differ by the
    direction each vertex's tangent space calls 0 (we align it with all the
    vertex's edges, geometry-central with one), and both are as close to
    the analytic answer on a jittered sphere (tested). :math:`\phi_{ji}` is
    minus the angle by which the transport of a vector from :math:`i` to
    :math:`j` turns it, since transport back along the same geodesic is the
    inverse. Mesh boundary vertices keep their true fan of triangles
    (geometry-central stretches it to a half plane, which makes corners
    cone points), so directions at corners are exact on flat meshes.

    The heat flows run for the time :math:`t = h^2` (:math:`h` the mean
    edge length of the intrinsic triangulation) and the influence of far
    parts of the surface decays like :math:`e^{-2 b / h}` with their
    distance :math:`b`. Where the discs are small against the surface,
    centres are grouped around seeds (farthest point sampling) and every
    group is solved on a patch: the triangles within ``margin`` mean edge
    lengths (fast-marching distance) of one of its discs (the benchmark
    measures what that changes); a cost model picks patches or whole
    components. A centre whose neighbours are not all
    connected to it inside its patch is redone on its whole connected
    component, as in the original. Meshes must be oriented manifolds.

    On point clouds the solver is potpourri3d's point-cloud heat solver
    (install ``potpourri3d``) on Euclidean balls around the groups, in
    ``workers`` processes, converted from its tangent bases to
    :obj:`frame`; it is markedly less accurate than the mesh one (on a
    3k-point unit sphere with :math:`\varepsilon = 0.4`: log-map angles
    0.03 rad median, 0.26 rad worst; radii up to 5 % of
    :math:`\varepsilon`; transport 1e-3 rad median, 0.16 rad worst).

    Args:
        pos (torch.Tensor): Points (mesh vertices).
        edge_index (torch.Tensor): Edges :math:`(j \to i)`, e.g. from
            :func:`geodesic_neighbourhoods`.
        frame (torch.Tensor, optional): Tangent frames, rows
            :math:`(e_u, e_v, n)`. (default: :obj:`None`: for meshes
            ``tangent_frames(vertex_normals(pos, face))``; point clouds must
            pass frames)
        face (torch.Tensor, optional): Triangles in PyG layout. Needed by
            ``'vector_heat'`` on meshes; ``'fast'`` only uses it for the
            default frames. (default: :obj:`None`)
        method (str, optional): ``'fast'`` or ``'vector_heat'``.
            (default: :obj:`'fast'`)
        margin (float, optional): ``'vector_heat'`` patch margin around the
            discs, in mean edge lengths (mean point spacings for clouds).
            (default: :obj:`8.0`)
        workers (int, optional): ``'vector_heat'`` threads (meshes) or
            worker processes (point clouds; large jobs only, where starting
            them pays). (default: :obj:`None`, one per CPU)

    Shapes:
        - **input:** pos :math:`(N, 3)`, edge_index :math:`(2, E)`,
          frame :math:`(N, 3, 3)`, face :math:`(3, F)`
        - **output:** ``(r, theta, phi)``, each :math:`(E)` in :obj:`pos`'s
          dtype and device
    """
    pos = check_points(pos, min_points=1)
    edge_index = check_edge_index(edge_index, pos.size(0), pos)
    if method not in METHODS:
        raise ValueError(f"'method' must be one of {METHODS}, got "
                         f"{method!r}")
    if face is not None:
        face = _check_mesh(pos, face, strict=method == 'vector_heat')
    frame = _frames_for(pos, frame, face)
    if method == 'fast':
        return _fast(pos, frame, edge_index)
    margin = check_positive_float(margin, 'margin', allow_zero=True)
    if face is None and importlib.util.find_spec('potpourri3d') is None:
        raise ImportError("method='vector_heat' on point clouds needs "
                          "potpourri3d: pip install potpourri3d (or "
                          "tg_intrinsic[heat])")
    workers = (_vector_heat.default_workers() if workers is None
               else check_positive_int(workers, 'workers'))
    r, theta, phi = _vector_heat_log_map(pos, edge_index, frame, face,
                                         margin, workers)
    return (r.to(pos.dtype).to(pos.device),
            theta.to(pos.dtype).to(pos.device),
            phi.to(pos.dtype).to(pos.device))


def _vector_heat_log_map(pos, edge_index, frame, face, margin, workers):
    vh = _vector_heat
    num = edge_index.size(1)
    if num == 0:
        empty = torch.zeros(0, dtype=torch.float64)
        return empty, empty, empty
    kind = 'mesh' if face is not None else 'cloud'
    p = pos.detach().double().cpu().numpy()
    fr = frame.detach().double().cpu().numpy()
    f = face.t().contiguous().cpu().numpy() if face is not None else None
    j, i = edge_index.cpu().numpy()
    label = vh.vertex_components(kind, p, f)
    across = label[i] != label[j]
    if across.any():
        e = int(np.flatnonzero(across)[0])
        raise ValueError(f"{int(across.sum())} edge(s) join different "
                         f"connected components of the mesh (first: "
                         f"{j[e]} -> {i[e]}), so no geodesic exists; build "
                         f"the graph with geodesic_neighbourhoods(), which "
                         f"never does that")
    # The 'fast' answer sizes the patches (reach of every disc) and picks
    # the branch of transported angles at point-cloud boundary vertices.
    est = [t.cpu().numpy() for t in _fast(
        pos.detach().double(), frame.detach().double(), edge_index)]
    spacing = vh.mean_spacing(kind, p, f)
    if kind == 'mesh':
        area = float(face_areas(pos.detach().double().cpu(),
                                face.cpu()).sum())
        out = vh.mesh_log_map(p, f, fr, label, j, i, est[0], spacing, area,
                              margin, workers)
        return tuple(torch.from_numpy(o) for o in out)
    area = p.shape[0] * spacing ** 2
    order = np.argsort(i, kind='stable')
    centres, start = np.unique(i[order], return_index=True)
    ptr = np.append(start, num).astype(np.int64)
    results = vh.solve_all(kind, p, f, fr, label, centres, ptr, j[order],
                           order, np.maximum.reduceat(est[0][order], start),
                           est[2][order], spacing, area, margin, workers)
    r = np.empty(num)
    theta = np.empty(num)
    phi = np.empty(num)
    for eid, rr, tt, pp, _ in results:  # a loop over patches
        r[eid], theta[eid], phi[eid] = rr, tt, pp
    return (torch.from_numpy(r), torch.from_numpy(theta),
            torch.from_numpy(phi))


def vertex_area_weights(pos: Tensor, face: Optional[Tensor] = None,
                        normal: Optional[Tensor] = None, k: int = 8
                        ) -> Tensor:
    r"""Area :math:`A_j` of the surface around every point, the integration
    weight of a neighbour in a discretised surface integral. That is,

    .. math::
        \int_{B_\varepsilon(i)} f \, dA \approx \sum_{j \in \mathcal{N}(i)}
        A_j f(p_j)

    (Harmonic Surface Networks normalise :math:`A_j` over each
    neighbourhood; that is left to the caller).

    On a mesh, :math:`A_j` is the barycentric vertex area, one third of the
    area of the incident triangles (:func:`lumped_mass`). On a point cloud,
    it is the area of the Voronoi cell of :math:`p_j` among its :obj:`k`
    nearest neighbours projected onto its tangent plane (an exact half-plane
    intersection per point, numba), clipped to the regular octagon around
    the circle of radius 0.6 times their mean distance, which holds the
    cells of interior points (about 0.58 to 0.71 times the spacing) and
    keeps cells on an open boundary bounded (there they overestimate, up to
    about twice at the corner of a grid). On a uniform grid of spacing
    :math:`h` the interior weights are exactly :math:`h^2`.

    Args:
        pos (torch.Tensor): Points (mesh vertices).
        face (torch.Tensor, optional): Triangles in PyG layout.
            (default: :obj:`None`)
        normal (torch.Tensor, optional): Point-cloud normals (required
            without :obj:`face`). (default: :obj:`None`)
        k (int, optional): Neighbours of the point-cloud Voronoi cells (at
            least 3). (default: :obj:`8`)

    Shapes:
        - **input:** pos :math:`(N, 3)`, face :math:`(3, F)`,
          normal :math:`(N, 3)`
        - **output:** :math:`(N)`, positive
    """
    pos = check_points(pos, min_points=1)
    if face is not None:
        return lumped_mass(pos, face)
    if normal is None:
        raise ValueError("point-cloud area weights need normals: estimate "
                         "them first, e.g. vertex_area_weights(pos, "
                         "normal=estimate_normals(pos))")
    normal = check_vectors(normal, 'normal', pos.size(0), pos)
    k = check_positive_int(k, 'k', minimum=3)
    if pos.size(0) <= k:
        raise ValueError(f"'pos' has {pos.size(0)} points but k={k} "
                         f"neighbours are needed per point; lower k")
    frame = tangent_frames(normal)
    nbr = knn(pos, k, loop=False)[0].view(-1, k)
    area = _voronoi_areas(pos.detach().double().cpu().numpy(),
                          frame.detach().double().cpu().numpy(),
                          nbr.cpu().numpy())
    if not bool(np.all(area > 0)):
        bad = np.flatnonzero(~(area > 0))
        raise ValueError(f"{bad.size} point(s) (first: {bad[:5].tolist()}) "
                         f"have an empty Voronoi cell: their {k} nearest "
                         f"neighbours project onto them in the tangent plane "
                         f"(duplicate points, or normals along the offsets "
                         f"to the neighbours); remove duplicate points or "
                         f"check the normals")
    return torch.from_numpy(area).to(pos.dtype).to(pos.device)


@jit(parallel=True)
def _voronoi_areas(pos, frame, nbr):  # pragma: no cover (numba)
    """Tangent-plane Voronoi cell area of every point among its neighbours:
    an octagon clipped by the bisector half-planes (Sutherland-Hodgman)."""
    n, k = nbr.shape
    area = np.zeros(n)
    for i in prange(n):
        qx = np.empty(k)
        qy = np.empty(k)
        mean = 0.0
        for m in range(k):
            d = pos[nbr[i, m]] - pos[i]
            qx[m] = d[0] * frame[i, 0, 0] + d[1] * frame[i, 0, 1] \
                + d[2] * frame[i, 0, 2]
            qy[m] = d[0] * frame[i, 1, 0] + d[1] * frame[i, 1, 1] \
                + d[2] * frame[i, 1, 2]
            mean += np.sqrt(qx[m] ** 2 + qy[m] ** 2) / k
        # Octagon circumscribing the circle of radius 0.6 * mean.
        corner = 0.6 * mean / np.cos(np.pi / 8)
        px = np.empty(k + 8)
        py = np.empty(k + 8)
        cx = np.empty(k + 8)
        cy = np.empty(k + 8)
        for t in range(8):
            px[t] = corner * np.cos(np.pi / 8 + t * np.pi / 4)
            py[t] = corner * np.sin(np.pi / 8 + t * np.pi / 4)
        size = 8
        for m in range(k):
            c = 0.5 * (qx[m] ** 2 + qy[m] ** 2)
            if c <= 0.0:
                continue  # a duplicate point bounds nothing
            out = 0
            for t in range(size):
                s = (t + 1) % size
                fa = px[t] * qx[m] + py[t] * qy[m] - c
                fb = px[s] * qx[m] + py[s] * qy[m] - c
                if fa <= 0.0:
                    cx[out] = px[t]
                    cy[out] = py[t]
                    out += 1
                if (fa <= 0.0) != (fb <= 0.0):
                    w = fa / (fa - fb)
                    cx[out] = px[t] + w * (px[s] - px[t])
                    cy[out] = py[t] + w * (py[s] - py[t])
                    out += 1
            size = out
            for t in range(size):
                px[t] = cx[t]
                py[t] = cy[t]
            if size < 3:
                break
        acc = 0.0
        for t in range(size):
            s = (t + 1) % size
            acc += px[t] * py[s] - px[s] * py[t]
        area[i] = 0.5 * abs(acc) if size >= 3 else 0.0
    return area
