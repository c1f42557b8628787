r"""Mesh bookkeeping shared by :class:`CleanMesh`, :class:`Decimate` and
:class:`FarthestPointResample`: which attributes of a
:class:`~torch_geometric.data.Data` are per vertex or per face, carrying
them through index changes, polygon fans, degenerate and duplicate faces,
connected components, midpoint subdivision and a greedy edge-manifold
filter (numba). Vectorised throughout; no loops over vertices or faces in
Python."""
from typing import Dict, List, Optional, Tuple

import numpy as np
import torch
from scipy.sparse import coo_matrix
from scipy.sparse.csgraph import connected_components
from torch import Tensor
from torch_geometric.data import Data

from tg_intrinsic.geometry.jit import jit

# Triangles with area at most this times their longest edge squared are
# degenerate (heights below 2e-5 of the longest edge): above the float32
# threshold of the geometry checks (16 eps = 1.9e-6), so that what is kept
# passes them in either precision.
DEGENERATE_TOLERANCE = 1e-5
# Attributes that number vertices or edges of the input: stale after the
# vertices change.
_GRAPH_KEYS = ('edge_index', 'edge_attr', 'edge_weight')


def check_mesh_data(data: Data, name: str, allow_cloud: bool = False):
    """What the mesh transforms need: ``pos`` [N, 3], ``face`` [k, F] with
    k >= 3 (or no face with :obj:`allow_cloud`) and no graph built yet."""
    pos = getattr(data, 'pos', None)
    if not isinstance(pos, Tensor) or pos.dim() != 2 or pos.size(1) != 3 \
            or pos.size(0) == 0:
        raise ValueError(f"{name} needs vertex positions 'data.pos' of shape "
                         f"[N, 3]")
    if not pos.is_floating_point():
        raise ValueError(f"{name}: 'data.pos' must be float32 or float64, "
                         f"got {pos.dtype}")
    face = getattr(data, 'face', None)
    if face is None and not allow_cloud:
        raise ValueError(f"{name} needs a triangle mesh ('data.face'); for a "
                         f"point cloud use FarthestPointResample(num_vertices)"
                         f" (farthest point sampling of the points) or "
                         f"torch_geometric.transforms.FixedPoints")
    if face is not None:
        if not isinstance(face, Tensor) or face.dim() != 2 \
                or face.size(0) < 3 or face.dtype != torch.long:
            shape = list(face.shape) if isinstance(face, Tensor) else face
            raise ValueError(f"{name}: 'data.face' must be a torch.long "
                             f"tensor [3, F] (or [k, F] polygons, k >= 3) in "
                             f"PyG layout, got {shape}")
        lowest = -1 if face.size(0) > 3 else 0  # -1 pads short polygons
        if face.numel() and (int(face.min()) < lowest
                             or int(face.max()) >= pos.size(0)
                             or bool((face[:3] < 0).any())):
            raise ValueError(f"{name}: 'data.face' indexes vertices outside "
                             f"[0, {pos.size(0) - 1}] (only rows after the "
                             f"third may hold -1, to pad short polygons)")
    for key in _GRAPH_KEYS:
        if getattr(data, key, None) is not None:
            raise ValueError(f"{name} changes the vertices, so 'data.{key}' "
                             f"would be stale; apply it before transforms "
                             f"that build graphs (LogMap, MLSOperators, ...)")
    return pos, face


def split_attributes(data: Data, num_vertices: int,
                     num_faces: Optional[int]) -> Tuple[List[str], List[str]]:
    """Keys of the per-vertex tensors (first dimension N) and of the
    per-face tensors (first dimension F, where F differs from N), other
    than ``pos`` and ``face``."""
    vertex, face = [], []
    for key, value in data.items():
        if key in ('pos', 'face') or not isinstance(value, Tensor) \
                or value.dim() == 0:
            continue
        if value.size(0) == num_vertices:
            vertex.append(key)
        elif num_faces is not None and value.size(0) == num_faces:
            face.append(key)
    return vertex, face


def rebuild(data: Data, pos: Tensor, face: Optional[Tensor],
            vertex_index: Tensor, face_index: Optional[Tensor] = None
            ) -> Data:
    """A new Data with :obj:`pos`, :obj:`face`, every per-vertex attribute
    taken at :obj:`vertex_index` (an input vertex per output vertex), every
    per-face attribute at :obj:`face_index` (dropped when that is
    :obj:`None`) and everything else as it was."""
    old_face = getattr(data, 'face', None)
    vertex_keys, face_keys = split_attributes(
        data, data.pos.size(0),
        None if old_face is None else old_face.size(1))
    out: Dict[str, object] = {}
    for key, value in data.items():
        if key in ('pos', 'face') or key in face_keys and face_index is None:
            continue
        if key in vertex_keys:
            out[key] = value[vertex_index.to(value.device)]
        elif key in face_keys:
            out[key] = value[face_index.to(value.device)]
        else:
            out[key] = value
    out['pos'] = pos
    if face is not None:
        out['face'] = face
    return data.__class__(**out)


def fan_triangulate(face: Tensor) -> Tuple[Tensor, Tensor]:
    """Polygons ``[k, F]`` (rows: corners in order; a row of -1 pads a
    shorter polygon) as triangle fans ``(c0, c_t, c_t+1)``; returns the
    triangles and the polygon of every triangle."""
    k = face.size(0)
    if k == 3:
        return face, torch.arange(face.size(1), device=face.device)
    tris, owner = [], []
    ids = torch.arange(face.size(1), device=face.device)
    for t in range(1, k - 1):  # a loop over polygon corners, not faces
        tri = torch.stack([face[0], face[t], face[t + 1]])
        keep = (tri >= 0).all(0)
        tris.append(tri[:, keep])
        owner.append(ids[keep])
    order = torch.argsort(torch.cat(owner), stable=True)
    return torch.cat(tris, 1)[:, order], torch.cat(owner)[order]


def nondegenerate(pos: Tensor, face: Tensor,
                  tolerance: float = DEGENERATE_TOLERANCE) -> Tensor:
    """Mask of the triangles with three distinct corners and an area above
    :obj:`tolerance` times their longest edge squared (float64)."""
    if face.size(1) == 0:
        return torch.zeros(0, dtype=torch.bool, device=face.device)
    p = pos.detach().double()
    a, b, c = p[face[0]], p[face[1]], p[face[2]]
    area = 0.5 * torch.linalg.cross(b - a, c - a).norm(dim=-1)
    scale = torch.stack([(b - a).pow(2).sum(-1), (c - b).pow(2).sum(-1),
                         (a - c).pow(2).sum(-1)]).amax(0)
    distinct = (face[0] != face[1]) & (face[1] != face[2]) \
        & (face[0] != face[2])
    return distinct & (area > tolerance * scale) & torch.isfinite(area)


def first_unique_faces(face: Tensor, num_vertices: int) -> Tensor:
    """Sorted indices of the first triangle of every vertex set (either
    orientation): later copies are dropped."""
    if face.size(1) == 0:
        return torch.zeros(0, dtype=torch.long, device=face.device)
    key = torch.sort(face, 0).values
    n = max(num_vertices, 1)
    code = (key[0] * n + key[1]) * n + key[2]
    _, inverse = torch.unique(code, return_inverse=True)
    ids = torch.arange(face.size(1), device=face.device)
    first = torch.full((int(inverse.max()) + 1,), face.size(1),
                       dtype=torch.long, device=face.device)
    first = first.scatter_reduce(0, inverse, ids, reduce='amin')
    return torch.sort(first).values


def compact(face: Tensor, num_vertices: int) -> Tuple[Tensor, Tensor]:
    """Drops the vertices no triangle references: ``(face, kept)`` with
    the re-indexed triangles and the old index of every kept vertex."""
    used = torch.zeros(num_vertices, dtype=torch.bool, device=face.device)
    used[face.flatten()] = True
    kept = used.nonzero().flatten()
    remap = torch.full((num_vertices,), -1, dtype=torch.long,
                       device=face.device)
    remap[kept] = torch.arange(kept.numel(), device=face.device)
    return remap[face], kept


def component_labels(face: Tensor, num_vertices: int) -> np.ndarray:
    """Connected component of every vertex along the triangle edges
    (vertices of no triangle are their own component)."""
    f = face.cpu().numpy()
    a = np.concatenate([f[0], f[1], f[2]])
    b = np.concatenate([f[1], f[2], f[0]])
    graph = coo_matrix((np.ones(a.size, dtype=np.int8), (a, b)),
                       shape=(num_vertices, num_vertices))
    return connected_components(graph, directed=False)[1]


def midpoint_subdivide(pos: Tensor, face: Tensor) -> Tuple[Tensor, Tensor]:
    """Splits every triangle into four at its edge midpoints (the surface
    is unchanged); the new vertices follow the old ones."""
    n = pos.size(0)
    a = torch.cat([face[0], face[1], face[2]])
    b = torch.cat([face[1], face[2], face[0]])
    lo, hi = torch.minimum(a, b), torch.maximum(a, b)
    key, edge = torch.unique(lo * n + hi, return_inverse=True)
    mid = 0.5 * (pos[key // n] + pos[key % n])
    e01, e12, e20 = (n + edge).view(3, -1)
    v0, v1, v2 = face
    new_face = torch.cat([torch.stack([v0, e01, e20]),
                          torch.stack([v1, e12, e01]),
                          torch.stack([v2, e20, e12]),
                          torch.stack([e01, e12, e20])], 1)
    return torch.cat([pos, mid.to(pos.dtype)]), new_face


def nearest_vertices(source: Tensor, target: Tensor) -> Tensor:
    """Index into :obj:`source` of the point nearest to every point of
    :obj:`target` (a k-d tree, CPU)."""
    from scipy.spatial import cKDTree
    tree = cKDTree(source.detach().double().cpu().numpy())
    _, index = tree.query(target.detach().double().cpu().numpy(), k=1,
                          workers=-1)
    return torch.from_numpy(np.asarray(index, dtype=np.int64)).to(
        source.device)


def manifold_subset(face: Tensor, num_vertices: int,
                    order: Tensor) -> Tensor:
    """Greedily keeps triangles, in :obj:`order`, whose every directed
    edge is new and whose undirected edges hold fewer than two kept
    triangles: the result is edge-manifold and consistently oriented.
    Returns the kept triangle indices, sorted."""
    if face.size(1) == 0:
        return torch.zeros(0, dtype=torch.long, device=face.device)
    f = face.t().contiguous().cpu().numpy()
    n = max(num_vertices, 1)
    a = np.concatenate([f[:, 0], f[:, 1], f[:, 2]]).astype(np.int64)
    b = np.concatenate([f[:, 1], f[:, 2], f[:, 0]]).astype(np.int64)
    _, undirected = np.unique(np.minimum(a, b) * n + np.maximum(a, b),
                              return_inverse=True)
    _, directed = np.unique(a * n + b, return_inverse=True)
    m = f.shape[0]
    keep = _greedy_manifold(undirected.reshape(3, m).T.copy(),
                            directed.reshape(3, m).T.copy(),
                            order.cpu().numpy().astype(np.int64))
    return torch.from_numpy(np.flatnonzero(keep)).to(face.device)


@jit
def _greedy_manifold(undirected, directed, order):  # pragma: no cover
    m = undirected.shape[0]
    uses = np.zeros(undirected.max() + 1, dtype=np.int64)
    taken = np.zeros(directed.max() + 1, dtype=np.bool_)
    keep = np.zeros(m, dtype=np.bool_)
    for t in range(order.shape[0]):
        f = order[t]
        ok = True
        for c in range(3):
            if uses[undirected[f, c]] >= 2 or taken[directed[f, c]]:
                ok = False
        if ok:
            keep[f] = True
            for c in range(3):
                uses[undirected[f, c]] += 1
                taken[directed[f, c]] = True
    return keep
