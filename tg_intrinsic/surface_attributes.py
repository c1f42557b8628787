r"""Where a :class:`~torch_geometric.data.Data` keeps its surface's normals,
tangent frames and neighbour graph, decided once for every transform, model
and solver. Normals and frames are found in this order:

1. ``data.frame`` :math:`(N, 3, 3)` (rows :math:`e_u, e_v, n`), else
2. ``data.normal`` (or ``data.norm``, PyG's older name) :math:`(N, 3)`, else
3. for a mesh (``data.face`` present) the area-weighted vertex normals, else
4. for a point cloud PCA normals of :math:`k` neighbours, oriented
   consistently (:func:`~tg_intrinsic.geometry.estimate_normals`, per
   example of ``data.batch``).
"""
import warnings
from typing import Optional

import torch
from torch import Tensor
from torch_geometric.data import Data

from tg_intrinsic.geometry.checks import (check_edge_index, check_faces,
                                          check_frames, check_points,
                                          check_referenced, check_vectors)
from tg_intrinsic.geometry.mesh import vertex_normals
from tg_intrinsic.geometry.pointcloud.frames import (estimate_normals,
                                                     tangent_frames)
from tg_intrinsic.geometry.pointcloud.neighbors import knn

__all__ = ['given_normals', 'computed_normals', 'resolve_normals',
           'resolve_frames', 'surface_graph', 'mls_parameters',
           'check_mls_parameters']


def _positions(data: Data) -> Tensor:
    pos = getattr(data, 'pos', None)
    if pos is None:
        raise ValueError("the data has no positions: set 'data.pos' "
                         "(N, 3) first")
    return check_points(pos, 'data.pos')


def given_normals(data: Data) -> Optional[Tensor]:
    """The normals ``data`` already carries (steps 1-2), validated against
    ``data.pos``, or :obj:`None`."""
    pos = _positions(data)
    frame = getattr(data, 'frame', None)
    if frame is not None:
        return check_frames(frame, pos.size(0), pos)[:, 2]
    for name in ('normal', 'norm'):
        normal = getattr(data, name, None)
        if normal is not None:
            return check_vectors(normal, f'data.{name}', pos.size(0), pos)
    return None


def computed_normals(data: Data, k: int = 10) -> Tensor:
    """Normals computed from the geometry alone (steps 3-4)."""
    pos = _positions(data)
    face = getattr(data, 'face', None)
    if face is not None:
        return vertex_normals(pos, face)
    return estimate_normals(pos, k, getattr(data, 'batch', None))


def resolve_normals(data: Data, k: int = 10) -> Tensor:
    """The normals of ``data`` by the order above, in the dtype of
    ``data.pos``; :obj:`k` is used only when they must be estimated from a
    point cloud."""
    normal = given_normals(data)
    if normal is None:
        return computed_normals(data, k)
    return normal.to(data.pos.dtype)


def resolve_frames(data: Data, k: int = 10) -> Tensor:
    """The tangent frames of ``data`` by the order above:
    ``data.frame`` as given, else
    :func:`~tg_intrinsic.geometry.tangent_frames` of
    :func:`resolve_normals`, in the dtype of ``data.pos``."""
    frame = getattr(data, 'frame', None)
    if frame is not None:
        pos = _positions(data)
        return check_frames(frame, pos.size(0), pos).to(pos.dtype)
    return tangent_frames(resolve_normals(data, k))


def surface_graph(data: Data, k: int = 8) -> Tensor:
    """The neighbour graph ``[2, E]`` of ``data``: the edges of its
    triangles (``data.face``), else ``data.edge_index``, else the :obj:`k`
    nearest neighbours of every point. Every point must lie on an edge."""
    pos = _positions(data)
    face = getattr(data, 'face', None)
    if face is not None:
        face = check_faces(face, pos.size(0), pos)
        graph = torch.cat([face[[0, 1]], face[[1, 2]], face[[2, 0]]], 1)
    elif getattr(data, 'edge_index', None) is not None:
        graph = check_edge_index(data.edge_index, pos.size(0), pos)
    else:
        graph = knn(pos, min(k, pos.size(0) - 1))
    check_referenced(graph, pos.size(0), 'edge',
                     "they lie on no edge, so no level can reach them; "
                     "remove unreferenced vertices first")
    return graph


def mls_parameters(k: int, regularizer: float, kernel_width: float,
                   normalized: bool = True) -> Tensor:
    """The record ``[[k, regularizer, kernel_width, normalized]]`` that
    :class:`~tg_intrinsic.transforms.MLSOperators` stores beside its
    weights."""
    return torch.tensor([[float(k), float(regularizer), float(kernel_width),
                          float(bool(normalized))]], dtype=torch.float64)


def _describe(row: Tensor) -> str:
    k, regularizer, kernel_width, normalized = row.tolist()
    return (f'k={int(k)}, regularizer={regularizer:g}, '
            f'kernel_width={kernel_width:g}, normalized={bool(normalized)}')


def check_mls_parameters(data: Data, k: int, regularizer: float,
                         kernel_width: float, normalized: bool = True):
    """Precomputed MLS weights in ``data`` must have been built with the
    parameters of the model reading them: raises a :class:`ValueError`
    naming both otherwise, and warns when ``data`` has no record (weights
    built by an older version)."""
    recorded = getattr(data, 'mls_parameters', None)
    wanted = mls_parameters(k, regularizer, kernel_width, normalized)
    if recorded is None:
        warnings.warn("the precomputed MLS operators in this data carry no "
                      "record of the parameters they were built with (made "
                      "by an older version); the model cannot check that "
                      "they match its own: rebuild them (e.g. "
                      "force_reload=True)", UserWarning, stacklevel=3)
        return
    recorded = recorded.detach().double().cpu().reshape(-1, 4)
    wrong = ~torch.isclose(recorded, wanted, rtol=1e-9, atol=0.0).all(1)
    if bool(wrong.any()):
        got = recorded[wrong.nonzero()[0, 0]]
        raise ValueError(f"the precomputed MLS operators were built with "
                         f"{_describe(got)} but the model uses "
                         f"{_describe(wanted[0])}; build the model and "
                         f"MLSOperators with the same values, or drop the "
                         f"precomputed operators so that the model builds "
                         f"its own")
