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
           'check_mls_parameters', 'operator_graph', 'record_operator_graph',
           'check_operator_graph']


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
    # A record cast with the rest of a batch (.half(), .to(bfloat16)) is
    # compared to the precision it kept.
    rtol = 1e-9 if recorded.dtype == torch.float64 \
        else 2 * torch.finfo(recorded.dtype).eps
    recorded = recorded.detach().double().cpu().reshape(-1, 4)
    wrong = ~torch.isclose(recorded, wanted, rtol=rtol, atol=0.0).all(1)
    if bool(wrong.any()):
        got = recorded[wrong.nonzero()[0, 0]]
        raise ValueError(f"the precomputed MLS operators were built with "
                         f"{_describe(got)} but the model uses "
                         f"{_describe(wanted[0])}; build the model and "
                         f"MLSOperators with the same values, or drop the "
                         f"precomputed operators so that the model builds "
                         f"its own")


# Odd multipliers below 2**20 and a prime modulus below 2**31: every product
# in operator_graph stays below 2**63, so int64 arithmetic is exact on any
# device.
_HASH_MULTIPLIERS = (1000003, 999983, 1000033)
_HASH_MODULUS = 2147483647


def operator_graph(edge_index: Tensor, num_nodes: int,
                   batch: Optional[Tensor] = None) -> Tensor:
    r"""The record ``[[E, h]]`` per graph of a (batched) ``edge_index``
    that precompute transforms store beside per-edge operators (as
    ``data.operator_graph``): the number of edges :math:`E` and a
    fingerprint :math:`h` of the edges in their order. The fingerprint is

    .. math::
        h = \sum_e a_e^3 \bmod p, \qquad
        a_e = (c_1 j_e + c_2 i_e + c_3 e + 1) \bmod p,

    with node indices :math:`j_e, i_e` and the position :math:`e` counted
    from the graph's own first node and edge, so that PyG's batching keeps
    every graph's record. Any edge added, removed, changed or moved changes
    it (PyG's ``coalesce`` sorts the edges without their other attributes).

    Shapes:
        - **input:** edge_index :math:`(2, E)`, batch :math:`(N)`
        - **output:** :math:`(B, 2)`, int64
    """
    j, i = edge_index
    device = edge_index.device
    if batch is None:
        batch = torch.zeros(num_nodes, dtype=torch.long, device=device)
    num_graphs = int(batch.max()) + 1 if batch.numel() > 0 else 1
    nodes = torch.bincount(batch, minlength=num_graphs)
    node_start = torch.cumsum(nodes, 0) - nodes
    graph = batch[i]
    edges = torch.bincount(graph, minlength=num_graphs)
    edge_start = torch.cumsum(edges, 0) - edges
    position = torch.arange(i.numel(), device=device) - edge_start[graph]
    c1, c2, c3 = _HASH_MULTIPLIERS
    a = (c1 * (j - node_start[graph]) + c2 * (i - node_start[graph])
         + c3 * position + 1) % _HASH_MODULUS
    cube = (a * a % _HASH_MODULUS) * a % _HASH_MODULUS
    fingerprint = torch.zeros(num_graphs, dtype=torch.long, device=device)
    fingerprint = fingerprint.index_add(0, graph, cube)
    return torch.stack([edges, fingerprint], dim=1)


def record_operator_graph(data: Data) -> Data:
    """Stores :func:`operator_graph` of ``data.edge_index`` as
    ``data.operator_graph`` (``data`` is changed and returned): called by
    every transform that writes per-edge operators."""
    data.operator_graph = operator_graph(data.edge_index, data.num_nodes,
                                         getattr(data, 'batch', None))
    return data


def check_operator_graph(data: Data, operators: str, built_by: str):
    """Per-edge operators in ``data`` (named by ``operators``, built by the
    transform ``built_by``) must still sit on the graph ``data.edge_index``
    they were built on: raises a one-line :class:`ValueError` otherwise
    (PyG's edge transforms run after the precompute). Data without a
    record (an older version's cache) is not checked."""
    record = getattr(data, 'operator_graph', None)
    if record is None:
        return
    now = operator_graph(data.edge_index, data.num_nodes,
                         getattr(data, 'batch', None))
    record = record.reshape(-1, 2).to(now.device)
    if record.shape == now.shape and torch.equal(record, now):
        return
    then, edges = int(record[:, 0].sum()), int(now[:, 0].sum())
    change = f'{then} edges then, {edges} now' if then != edges \
        else f'{edges} edges, changed or reordered'
    raise ValueError(
        f"the precomputed operators ({operators}) were built on another "
        f"graph than 'data.edge_index' ({change}): "
        f"PyG edge transforms (ToUndirected, AddSelfLoops, "
        f"RemoveDuplicatedEdges, ...) must run before {built_by}, not "
        f"after; or drop the operators so that the model builds its own")
