r"""Graph-Voronoi multigrid hierarchies (Gravo MG; Wiersma, Nasikun,
Eisemann and Hildebrandt, SIGGRAPH 2023): sampling, Voronoi cells, coarse
graphs and the prolongation operators, on any neighbour graph. Pure numpy
and numba; :class:`tg_intrinsic.transforms.GravoHierarchy` wraps it for
:class:`~torch_geometric.data.Data`."""
import math
from typing import List, NamedTuple

import numpy as np
from numba import njit

from .voronoi import _multi_source_dijkstra

WEIGHTINGS = ('barycentric', 'inverse_distance', 'uniform')


class GravoLevel(NamedTuple):
    """One coarsening step: ``sample`` (fine indices of the coarse points),
    ``cluster`` (the coarse point whose Voronoi cell holds every fine
    point), the coarse ``pos`` and ``edge_index`` (both directions), and the
    prolongation ``P`` as ``prolong_index`` (2, nnz: fine row, coarse
    column) and ``prolong_weight`` (nnz)."""
    sample: np.ndarray
    cluster: np.ndarray
    pos: np.ndarray
    edge_index: np.ndarray
    prolong_index: np.ndarray
    prolong_weight: np.ndarray


def _csr(edge_index: np.ndarray, n: int):
    """Symmetric adjacency (sorted, no self-loops, no repeats) as CSR."""
    src, dst = edge_index
    keep = src != dst
    a = np.concatenate([src[keep], dst[keep]])
    b = np.concatenate([dst[keep], src[keep]])
    key = np.unique(a.astype(np.int64) * n + b)
    a, b = key // n, key % n
    indptr = np.zeros(n + 1, dtype=np.int64)
    np.cumsum(np.bincount(a, minlength=n), out=indptr[1:])
    return indptr, b.astype(np.int64)


@njit(cache=True)
def _sample_sweep(indptr, indices, pos, radius):  # pragma: no cover (numba)
    """Keeps every still-eligible point (in index order) and makes the
    points of its 2-ring within ``radius`` ineligible."""
    n = indptr.shape[0] - 1
    eligible = np.ones(n, dtype=np.bool_)
    keep = np.zeros(n, dtype=np.bool_)
    r2 = radius * radius
    for v in range(n):
        if not eligible[v]:
            continue
        keep[v] = True
        eligible[v] = False
        for p in range(indptr[v], indptr[v + 1]):
            u = indices[p]
            for q in range(indptr[u], indptr[u + 1] + 1):
                w = u if q == indptr[u + 1] else indices[q]
                d = 0.0
                for k in range(3):
                    d += (pos[w, k] - pos[v, k]) ** 2
                if d < r2:
                    eligible[w] = False
    return np.flatnonzero(keep)


@njit(cache=True)
def _triangles(indptr, indices):  # pragma: no cover (numba)
    """All 3-cliques (a < b < c) of a graph with sorted CSR rows."""
    count = 0
    for sweep in range(2):
        if sweep == 1:
            out = np.empty((count, 3), dtype=np.int64)
            count = 0
        for a in range(indptr.shape[0] - 1):
            for p in range(indptr[a], indptr[a + 1]):
                b = indices[p]
                if b <= a:
                    continue
                for q in range(indptr[b], indptr[b + 1]):
                    c = indices[q]
                    if c <= b:
                        continue
                    lo, hi = indptr[a], indptr[a + 1]
                    while lo < hi:  # is c a neighbour of a?
                        mid = (lo + hi) // 2
                        if indices[mid] < c:
                            lo = mid + 1
                        else:
                            hi = mid
                    if lo < indptr[a + 1] and indices[lo] == c:
                        if sweep == 1:
                            out[count, 0] = a
                            out[count, 1] = b
                            out[count, 2] = c
                        count += 1
    return out


@njit(cache=True)
def _closest_on_triangle(p, a, b, c):  # pragma: no cover (numba)
    """Barycentric coordinates of the point of triangle abc closest to p
    (Ericson, Real-Time Collision Detection, 5.1.5)."""
    ab = b - a
    ac = c - a
    ap = p - a
    d1 = np.dot(ab, ap)
    d2 = np.dot(ac, ap)
    if d1 <= 0.0 and d2 <= 0.0:
        return 1.0, 0.0, 0.0
    bp = p - b
    d3 = np.dot(ab, bp)
    d4 = np.dot(ac, bp)
    if d3 >= 0.0 and d4 <= d3:
        return 0.0, 1.0, 0.0
    vc = d1 * d4 - d3 * d2
    if vc <= 0.0 and d1 >= 0.0 and d3 <= 0.0:
        v = d1 / (d1 - d3)
        return 1.0 - v, v, 0.0
    cp = p - c
    d5 = np.dot(ab, cp)
    d6 = np.dot(ac, cp)
    if d6 >= 0.0 and d5 <= d6:
        return 0.0, 0.0, 1.0
    vb = d5 * d2 - d1 * d6
    if vb <= 0.0 and d2 >= 0.0 and d6 <= 0.0:
        w = d2 / (d2 - d6)
        return 1.0 - w, 0.0, w
    va = d3 * d6 - d5 * d4
    if va <= 0.0 and (d4 - d3) >= 0.0 and (d5 - d6) >= 0.0:
        w = (d4 - d3) / ((d4 - d3) + (d5 - d6))
        return 0.0, 1.0 - w, w
    denom = va + vb + vc
    if denom <= 0.0:  # a degenerate (co-linear) triangle
        return -1.0, -1.0, -1.0
    v = vb / denom
    w = vc / denom
    return 1.0 - v - w, v, w


@njit(cache=True)
def _prolong(pos, coarse_pos, cluster, tri_ptr, tri_list, triangles,
             nbr_ptr, nbr, mode):  # pragma: no cover (numba)
    """Row of P for every fine point: the closest candidate triangle
    incident to its own cell's coarse point (mode 0: barycentric weights
    of the closest point, 2: uniform), else, or with mode 1, inverse
    distance weights to the three closest of that coarse point and its
    coarse neighbours."""
    n = pos.shape[0]
    cols = np.full((n, 3), -1, dtype=np.int64)
    vals = np.zeros((n, 3))
    for i in range(n):
        s = cluster[i]
        p = pos[i]
        best = np.inf
        if mode != 1:
            for k in range(tri_ptr[s], tri_ptr[s + 1]):
                t = tri_list[k]
                a, b, c = triangles[t, 0], triangles[t, 1], triangles[t, 2]
                u, v, w = _closest_on_triangle(p, coarse_pos[a],
                                               coarse_pos[b], coarse_pos[c])
                if u < 0.0:
                    continue
                q = u * coarse_pos[a] + v * coarse_pos[b] + w * coarse_pos[c]
                d = np.sum((q - p) ** 2)
                if d < best:
                    best = d
                    cols[i, 0], cols[i, 1], cols[i, 2] = a, b, c
                    if mode == 2:
                        vals[i, 0] = vals[i, 1] = vals[i, 2] = 1.0 / 3.0
                    else:
                        vals[i, 0], vals[i, 1], vals[i, 2] = u, v, w
        if best < np.inf:
            continue
        # Inverse distance weights to the three closest candidates.
        m = nbr_ptr[s + 1] - nbr_ptr[s] + 1
        cand = np.empty(m, dtype=np.int64)
        dist = np.empty(m)
        cand[0] = s
        for k in range(nbr_ptr[s], nbr_ptr[s + 1]):
            cand[k - nbr_ptr[s] + 1] = nbr[k]
        for k in range(m):
            dist[k] = np.sqrt(np.sum((coarse_pos[cand[k]] - p) ** 2))
        order = np.argsort(dist)
        total = 0.0
        for k in range(min(3, m)):
            c = cand[order[k]]
            if dist[order[k]] == 0.0:  # on a coarse point: all weight there
                cols[i, :] = -1
                vals[i, :] = 0.0
                cols[i, 0], vals[i, 0], total = c, 1.0, 1.0
                break
            cols[i, k] = c
            vals[i, k] = 1.0 / dist[order[k]]
            total += vals[i, k]
        for k in range(3):
            vals[i, k] /= total
    return cols, vals


def gravo_level(pos: np.ndarray, edge_index: np.ndarray, ratio: float = 8.0,
                shift: bool = True, weighting: str = 'barycentric'
                ) -> GravoLevel:
    r"""One Gravo MG coarsening step of the points ``pos`` (N, 3) with the
    neighbour graph ``edge_index`` (2, E; used in both directions).

    Samples are kept greedily in one sweep; every kept point makes the
    points of its 2-ring closer than :math:`r = \text{ratio}^{1/3}\,\bar h`
    (:math:`\bar h` the mean edge length) ineligible. Every point joins the
    graph Voronoi cell of its nearest sample (multi-source Dijkstra); two
    samples are coarse neighbours when their cells touch; candidate
    triangles are the 3-cliques of the coarse graph. With ``shift`` every
    coarse point moves to the mean of its cell. Row :math:`i` of the
    prolongation :math:`P` holds the barycentric coordinates of the point
    closest to :math:`p_i` on the closest candidate triangle incident to its
    cell's coarse point, or, where there is none, inverse distance weights
    to the three closest of that coarse point and its coarse neighbours, so
    rows are non-negative, sum to 1 and have at most 3 non-zeros."""
    if weighting not in WEIGHTINGS:
        raise ValueError(f"'weighting' must be one of {WEIGHTINGS}, got "
                         f"{weighting!r}")
    n = pos.shape[0]
    indptr, indices = _csr(edge_index, n)
    length = np.linalg.norm(pos[np.repeat(np.arange(n), np.diff(indptr))]
                            - pos[indices], axis=1)
    radius = ratio ** (1.0 / 3.0) * float(length.mean())
    sample = _sample_sweep(indptr, indices, pos, radius)
    cluster, _ = _multi_source_dijkstra(indptr, indices, length, sample, n)
    src, dst = edge_index
    cross = cluster[src] != cluster[dst]
    coarse_edges = np.stack([cluster[src][cross], cluster[dst][cross]])
    m = sample.size
    c_ptr, c_nbr = _csr(coarse_edges, m)
    coarse_edges = np.stack([np.repeat(np.arange(m), np.diff(c_ptr)),
                             c_nbr])
    if shift:
        coarse_pos = np.stack([np.bincount(cluster, pos[:, k], m)
                               for k in range(3)], 1) \
            / np.bincount(cluster, minlength=m)[:, None]
    else:
        coarse_pos = pos[sample]
    triangles = _triangles(c_ptr, c_nbr)
    owner = triangles.reshape(-1)
    tri_list = np.argsort(owner, kind='stable') // 3
    tri_ptr = np.zeros(m + 1, dtype=np.int64)
    np.cumsum(np.bincount(owner, minlength=m), out=tri_ptr[1:])
    cols, vals = _prolong(pos, coarse_pos, cluster, tri_ptr, tri_list,
                          triangles, c_ptr, c_nbr,
                          WEIGHTINGS.index(weighting))
    keep = (cols >= 0) & (vals > 0)
    rows = np.repeat(np.arange(n), 3).reshape(n, 3)
    return GravoLevel(sample, cluster, coarse_pos, coarse_edges,
                      np.stack([rows[keep], cols[keep]]), vals[keep])


def gravo_hierarchy(pos: np.ndarray, edge_index: np.ndarray,
                    ratio: float = 8.0, lower_bound: int = 1000,
                    max_levels: int = 10, shift: bool = True,
                    weighting: str = 'barycentric') -> List[GravoLevel]:
    """Coarsens with :func:`gravo_level` while the next level would keep at
    least ``lower_bound`` points, at most ``max_levels`` times."""
    if not (isinstance(ratio, (int, float)) and math.isfinite(ratio)
            and ratio > 1):
        raise ValueError(f"'ratio' must be a number above 1 (the factor by "
                         f"which each level shrinks), got {ratio!r}")
    levels = []
    while len(levels) < max_levels and pos.shape[0] / ratio >= lower_bound:
        level = gravo_level(pos, edge_index, ratio, shift, weighting)
        if level.sample.size < lower_bound:
            break
        levels.append(level)
        pos, edge_index = level.pos, level.edge_index
    return levels
