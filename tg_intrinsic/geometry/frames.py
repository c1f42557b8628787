r"""Point-cloud normals and tangent frames."""
from typing import Optional

import numpy as np
import scipy.sparse as sp
import torch
from numba import njit, prange
from scipy.sparse.csgraph import connected_components, minimum_spanning_tree
from torch import Tensor

from ._checks import (check_batch, check_points, check_positive_int,
                      check_vectors)
from .neighbors import knn


def estimate_normals(pos: Tensor, k: int = 10,
                     batch: Optional[Tensor] = None,
                     orient: bool = True) -> Tensor:
    r"""Estimates unit normals of a point cloud by local PCA (Hoppe et al.,
    1992): the normal of point :math:`i` is the eigenvector of the smallest
    eigenvalue of the covariance of :math:`i` and its :math:`k` nearest
    neighbours :math:`\mathcal{N}(i)`,

    .. math::
        C_i = \frac{1}{k + 1} \sum_{j \in \{i\} \cup \mathcal{N}(i)}
        (p_j - \bar{p}_i)(p_j - \bar{p}_i)^\top .

    With :obj:`orient=True` the signs are made consistent by propagating
    along a minimum spanning tree of the k-nn graph with edge cost
    :math:`(1.05 - |n_i^\top n_j|) \|p_i - p_j\|`; then every connected
    component is turned outwards so that its flux
    :math:`\sum_i n_i^\top (p_i - c)` about its own centroid :math:`c` is
    positive (on a closed surface this is three times the enclosed volume).
    This does not assume that the shape is centred at the origin. Flat
    components get the sign that makes the mean normal's largest coordinate
    positive.

    Args:
        pos (torch.Tensor): Point positions.
        k (int, optional): Number of neighbours (at least 2).
            (default: :obj:`10`)
        batch (torch.Tensor, optional): Example index of every point; the
            neighbourhoods never cross examples. (default: :obj:`None`)
        orient (bool, optional): Orient the normals consistently.
            (default: :obj:`True`)

    Shapes:
        - **input:** pos :math:`(N, 3)`, batch :math:`(N)`
        - **output:** :math:`(N, 3)`, unit length

    Raises:
        ValueError: if a neighbourhood is degenerate (its points coincide or
            lie on a line), so that no plane can be fitted; remove duplicate
            points or increase :obj:`k`.
    """
    pos = check_points(pos, min_points=1)
    k = check_positive_int(k, 'k', minimum=2)
    batch = check_batch(batch, pos.size(0), pos)
    edge_index = knn(pos, k, batch, loop=False)
    # knn returns exactly k neighbours per centre, grouped by centre.
    neighbours = edge_index[0].view(-1, k)
    pos64 = pos.double()
    if pos.device.type == 'cpu':
        evals, normal = _pca_numba(pos64.contiguous().numpy(),
                                   neighbours.contiguous().numpy())
        evals, normal = torch.from_numpy(evals), torch.from_numpy(normal)
    else:
        evals, normal = _pca_torch(pos64, neighbours)
    tol = 1e3 * torch.finfo(torch.float64).eps
    degenerate = evals[:, 1] <= tol * evals[:, 2].clamp_min(
        torch.finfo(torch.float64).tiny)
    if bool(degenerate.any()):
        bad = degenerate.nonzero().flatten()
        raise ValueError(f"the neighbourhoods of {bad.numel()} point(s) "
                         f"(first: {bad[:5].tolist()}) are degenerate: their "
                         f"{k + 1} points coincide or lie on a line, so no "
                         f"tangent plane can be fitted; remove duplicate "
                         f"points or increase k")
    if orient:
        normal = _orient(pos64, normal, edge_index)
    return normal.to(pos.dtype)


def _pca_torch(pos: Tensor, neighbours: Tensor):
    """Ascending covariance eigenvalues and the normal (eigenvector of the
    smallest one) of every patch; the reference for :func:`_pca_numba`."""
    patch = torch.cat([pos.unsqueeze(1), pos[neighbours]], dim=1)
    centred = patch - patch.mean(dim=1, keepdim=True)
    cov = centred.transpose(1, 2) @ centred / patch.size(1)
    evals, evecs = torch.linalg.eigh(cov)
    return evals, evecs[:, :, 0]


@njit(cache=True, parallel=True)
def _pca_numba(pos, neighbours):  # pragma: no cover (numba)
    """Covariance of every patch and its eigen-decomposition by cyclic
    Jacobi rotations (exact to rounding for 3 x 3), parallel over points."""
    num, k = neighbours.shape
    evals = np.empty((num, 3))
    normal = np.empty((num, 3))
    for i in prange(num):
        mean = pos[i].copy()
        for a in range(k):
            mean += pos[neighbours[i, a]]
        mean /= k + 1
        d = pos[i] - mean
        c = np.outer(d, d)
        for a in range(k):
            d = pos[neighbours[i, a]] - mean
            for r in range(3):
                for s in range(3):
                    c[r, s] += d[r] * d[s]
        c /= k + 1
        v = np.eye(3)
        for _ in range(50):
            off = c[0, 1] ** 2 + c[0, 2] ** 2 + c[1, 2] ** 2
            if off <= 1e-30 * (c[0, 0] ** 2 + c[1, 1] ** 2 + c[2, 2] ** 2) \
                    or off == 0.0:
                break
            for p in range(2):
                for q in range(p + 1, 3):
                    if c[p, q] == 0.0:
                        continue
                    theta = (c[q, q] - c[p, p]) / (2.0 * c[p, q])
                    t = np.sign(theta) / (abs(theta)
                                          + np.sqrt(theta * theta + 1.0))
                    if theta == 0.0:
                        t = 1.0
                    cs = 1.0 / np.sqrt(t * t + 1.0)
                    sn = t * cs
                    for r in range(3):  # c <- c G
                        a_rp, a_rq = c[r, p], c[r, q]
                        c[r, p] = cs * a_rp - sn * a_rq
                        c[r, q] = sn * a_rp + cs * a_rq
                    for r in range(3):  # c <- G^T c
                        a_pr, a_qr = c[p, r], c[q, r]
                        c[p, r] = cs * a_pr - sn * a_qr
                        c[q, r] = sn * a_pr + cs * a_qr
                    for r in range(3):  # v <- v G
                        v_rp, v_rq = v[r, p], v[r, q]
                        v[r, p] = cs * v_rp - sn * v_rq
                        v[r, q] = sn * v_rp + cs * v_rq
        order = np.argsort(np.array([c[0, 0], c[1, 1], c[2, 2]]))
        for r in range(3):
            evals[i, r] = c[order[r], order[r]]
        lo = order[0]
        for r in range(3):
            normal[i, r] = v[r, lo]
    return evals, normal


def _orient(pos: Tensor, normal: Tensor, edge_index: Tensor) -> Tensor:
    device = normal.device
    p = pos.cpu().numpy()
    n = normal.cpu().numpy().copy()
    num = p.shape[0]
    src, dst = edge_index.cpu().numpy()
    # Hoppe's cost 1 - |n_i . n_j|, offset and scaled by the edge length so
    # that the tree prefers short hops and does not jump across thin parts.
    length = np.sqrt(((p[src] - p[dst]) ** 2).sum(1))
    cost = (1.0 - np.abs((n[src] * n[dst]).sum(1)) + 0.05) * (
        length / max(length.mean(), np.finfo(np.float64).tiny) + 1e-9)
    graph = sp.coo_matrix((cost, (dst, src)), shape=(num, num)).tocsr()
    graph = graph.maximum(graph.T)
    tree = minimum_spanning_tree(graph)
    tree = (tree + tree.T).tocsr()
    num_comp, label = connected_components(tree, directed=False)
    roots = np.unique(label, return_index=True)[1]
    _propagate_signs(tree.indptr, tree.indices, roots.astype(np.int64), n)
    # Global sign per component: outward normals have a positive "flux"
    # sum_i n_i . (p_i - c) (divergence theorem: 3 x volume on closed shapes).
    count = np.bincount(label, minlength=num_comp).astype(np.float64)
    centroid = np.stack([np.bincount(label, p[:, d], num_comp)
                         for d in range(3)], 1) / count[:, None]
    offset = p - centroid[label]
    flux = np.bincount(label, (n * offset).sum(1), num_comp)
    scale = np.bincount(label, np.sqrt((offset ** 2).sum(1)), num_comp)
    # Flat patches have no outside; make the mean normal's dominant
    # coordinate positive so that the result is still deterministic.
    mean = np.stack([np.bincount(label, n[:, d], num_comp)
                     for d in range(3)], 1)
    dominant = mean[np.arange(num_comp), np.abs(mean).argmax(1)]
    flat = np.abs(flux) <= 1e-3 * scale
    sign = np.where(flat, np.sign(dominant), np.sign(flux))
    sign[sign == 0] = 1.0
    n *= sign[label][:, None]
    return torch.from_numpy(n).to(device)


@njit(cache=True)
def _propagate_signs(indptr, indices, roots, normal):
    num = normal.shape[0]
    visited = np.zeros(num, dtype=np.bool_)
    queue = np.empty(num, dtype=np.int64)
    for root in roots:
        head = 0
        tail = 1
        queue[0] = root
        visited[root] = True
        while head < tail:
            u = queue[head]
            head += 1
            for e in range(indptr[u], indptr[u + 1]):
                v = indices[e]
                if visited[v]:
                    continue
                visited[v] = True
                dot = (normal[u, 0] * normal[v, 0] + normal[u, 1] * normal[v, 1]
                       + normal[u, 2] * normal[v, 2])
                if dot < 0.0:
                    normal[v, 0] = -normal[v, 0]
                    normal[v, 1] = -normal[v, 1]
                    normal[v, 2] = -normal[v, 2]
                queue[tail] = v
                tail += 1


def tangent_frames(normal: Tensor) -> Tensor:
    r"""Builds an orthonormal, right-handed tangent frame at every point.

    Row 0 is :math:`e_u`, the unit projection onto the tangent plane of the
    coordinate axis least aligned with :math:`n`; row 1 is
    :math:`e_v = n \times e_u`; row 2 is :math:`n`. Hence
    :math:`e_u \times e_v = n`. A tangent vector with coordinates
    :math:`(a, b)` is :math:`a e_u + b e_v`. The choice of :math:`e_u` is a
    gauge: intrinsic operators in this library are independent of it.

    Args:
        normal (torch.Tensor): Normals (need not be unit length, must not be
            zero).

    Shapes:
        - **input:** :math:`(N, 3)`
        - **output:** :math:`(N, 3, 3)` with rows :math:`(e_u, e_v, n)`
    """
    normal = check_points(normal, 'normal', min_points=0)
    length = normal.norm(dim=-1, keepdim=True)
    zero = length.squeeze(-1) <= torch.finfo(normal.dtype).tiny
    if bool(zero.any()):
        bad = zero.nonzero().flatten()
        raise ValueError(f"{bad.numel()} normal(s) have zero length (first: "
                         f"{bad[:5].tolist()}); estimate them first, e.g. "
                         f"with estimate_normals(pos)")
    n = normal / length
    axis = torch.zeros_like(n)
    axis.scatter_(1, n.abs().argmin(dim=1, keepdim=True), 1.0)
    e_u = axis - (axis * n).sum(-1, keepdim=True) * n
    e_u = e_u / e_u.norm(dim=-1, keepdim=True)
    e_v = torch.linalg.cross(n, e_u)
    return torch.stack([e_u, e_v, n], dim=1)


def check_frames(frame, num: int, like: Tensor) -> Tensor:
    """Validates user-supplied frames ``[N, 3, 3]`` (rows e_u, e_v, n)."""
    if not isinstance(frame, Tensor) or frame.dim() != 3 \
            or tuple(frame.shape[1:]) != (3, 3):
        raise ValueError("'frame' must be a tensor of shape [N, 3, 3] with "
                         "rows (e_u, e_v, normal)")
    check_vectors(frame.reshape(-1, 3), 'frame', 3 * num, like)
    eye = torch.eye(3, dtype=frame.dtype, device=frame.device)
    gram = frame @ frame.transpose(1, 2)
    tol = 1e-4 if frame.dtype == torch.float32 else 1e-8
    if not bool(((gram - eye).abs() <= tol).all()):
        raise ValueError("'frame' rows must be orthonormal; build frames "
                         "with tangent_frames(normal)")
    if not bool((torch.linalg.det(frame) > 0).all()):
        raise ValueError("'frame' must be right-handed (e_u x e_v = normal)")
    return frame
