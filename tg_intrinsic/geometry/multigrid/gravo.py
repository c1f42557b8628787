r"""Graph-Voronoi multigrid hierarchies (Gravo MG; Wiersma, Nasikun,
Eisemann and Hildebrandt, SIGGRAPH 2023): sampling, Voronoi cells, coarse
graphs and the prolongation operators, on any neighbour graph. Tensors in
and out, numpy and numba inside;
:class:`tg_intrinsic.transforms.GravoHierarchy` wraps it for
:class:`~torch_geometric.data.Data`."""
import math
from typing import List, NamedTuple

import numpy as np
import torch
from numba import prange
from torch import Tensor

from ..checks import check_choice, check_edge_index, check_points
from ..jit import jit
from .voronoi import dijkstra_from

WEIGHTINGS = ('barycentric', 'inverse_distance', 'uniform')
VORONOI = ('exact', 'sweep')


class GravoLevel(NamedTuple):
    """One coarsening step: ``sample`` (fine indices of the coarse points),
    ``cluster`` (the coarse point whose Voronoi cell holds every fine
    point), the coarse ``pos`` and ``edge_index`` (both directions), and the
    prolongation ``P`` as ``prolong_index`` (2, nnz: fine row, coarse
    column) and ``prolong_weight`` (nnz). Indices are ``torch.long``;
    ``pos`` and ``prolong_weight`` have the input's float dtype; all on the
    input's device."""
    sample: Tensor
    cluster: Tensor
    pos: Tensor
    edge_index: Tensor
    prolong_index: Tensor
    prolong_weight: Tensor


def _csr(edge_index: np.ndarray, n: int):
    """Symmetric adjacency (sorted, no self-loops, no repeats) as CSR."""
    src = np.ascontiguousarray(edge_index[0], dtype=np.int64)
    dst = np.ascontiguousarray(edge_index[1], dtype=np.int64)
    return _csr_kernel(src, dst, n)


@jit
def _csr_kernel(src, dst, n):  # pragma: no cover (numba)
    indptr = np.zeros(n + 1, dtype=np.int64)
    for e in range(src.shape[0]):
        if src[e] != dst[e]:
            indptr[src[e] + 1] += 1
            indptr[dst[e] + 1] += 1
    for v in range(n):
        indptr[v + 1] += indptr[v]
    fill = indptr[:-1].copy()
    indices = np.empty(indptr[n], dtype=np.int64)
    for e in range(src.shape[0]):
        a, b = src[e], dst[e]
        if a != b:
            indices[fill[a]] = b
            fill[a] += 1
            indices[fill[b]] = a
            fill[b] += 1
    # Sort every row and drop repeats, compacting in place.
    out = 0
    start = 0
    for v in range(n):
        stop = indptr[v + 1]
        if stop - start > 32:
            indices[start:stop] = np.sort(indices[start:stop])
        else:  # insertion sort: rows of meshes and k-nn graphs are short
            for k in range(start + 1, stop):
                value = indices[k]
                j = k - 1
                while j >= start and indices[j] > value:
                    indices[j + 1] = indices[j]
                    j -= 1
                indices[j + 1] = value
        indptr[v] = out
        for k in range(start, stop):
            if k == start or indices[k] != indices[k - 1]:
                indices[out] = indices[k]
                out += 1
        start = stop
    indptr[n] = out
    return indptr, indices[:out].copy()


@jit
def _edge_lengths(indptr, indices, pos):  # pragma: no cover (numba)
    length = np.empty(indices.shape[0])
    for v in range(indptr.shape[0] - 1):
        for p in range(indptr[v], indptr[v + 1]):
            u = indices[p]
            length[p] = math.sqrt((pos[u, 0] - pos[v, 0]) ** 2
                                  + (pos[u, 1] - pos[v, 1]) ** 2
                                  + (pos[u, 2] - pos[v, 2]) ** 2)
    return length


@jit
def _sample_sweep(indptr, indices, length, radius):  # pragma: no cover
    """Keeps every still-eligible point (in index order); the neighbours
    closer than ``radius``, and their neighbours within that path length,
    become ineligible. Also returns the shortest such path length to a
    sample and that sample (as the original's sweep records them)."""
    n = indptr.shape[0] - 1
    eligible = np.ones(n, dtype=np.bool_)
    sample = np.empty(n, dtype=np.int64)
    dist = np.full(n, np.inf)
    nearest = np.full(n, -1, dtype=np.int64)
    m = 0
    for v in range(n):
        if not eligible[v]:
            continue
        sample[m] = v
        eligible[v] = False
        dist[v] = 0.0
        nearest[v] = m
        for p in range(indptr[v], indptr[v + 1]):
            u = indices[p]
            d = length[p]
            if d >= radius:
                continue
            eligible[u] = False
            if d < dist[u]:
                dist[u] = d
                nearest[u] = m
            for q in range(indptr[u], indptr[u + 1]):
                w = indices[q]
                d2 = d + length[q]
                if d2 < radius:
                    eligible[w] = False
                    if d2 < dist[w]:
                        dist[w] = d2
                        nearest[w] = m
        m += 1
    return sample[:m].copy(), dist, nearest


@jit
def _coarse_edges(indptr, indices, cluster):  # pragma: no cover (numba)
    """The pairs of cells that touch: (cluster[v], cluster[u]) for every
    fine edge v < u that crosses cells."""
    count = 0
    for sweep in range(2):
        if sweep == 1:
            src = np.empty(count, dtype=np.int64)
            dst = np.empty(count, dtype=np.int64)
            count = 0
        for v in range(indptr.shape[0] - 1):
            for p in range(indptr[v], indptr[v + 1]):
                u = indices[p]
                if u > v and cluster[u] != cluster[v]:
                    if sweep == 1:
                        src[count] = cluster[v]
                        dst[count] = cluster[u]
                    count += 1
    return src, dst


@jit
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


@jit
def _closest_on_triangle(p, a, b, c):  # pragma: no cover (numba)
    """Barycentric coordinates of the point of triangle abc closest to p
    (Ericson, Real-Time Collision Detection, 5.1.5); scalar arithmetic, as
    this runs once per fine point and candidate triangle."""
    abx, aby, abz = b[0] - a[0], b[1] - a[1], b[2] - a[2]
    acx, acy, acz = c[0] - a[0], c[1] - a[1], c[2] - a[2]
    apx, apy, apz = p[0] - a[0], p[1] - a[1], p[2] - a[2]
    d1 = abx * apx + aby * apy + abz * apz
    d2 = acx * apx + acy * apy + acz * apz
    if d1 <= 0.0 and d2 <= 0.0:
        return 1.0, 0.0, 0.0
    bpx, bpy, bpz = p[0] - b[0], p[1] - b[1], p[2] - b[2]
    d3 = abx * bpx + aby * bpy + abz * bpz
    d4 = acx * bpx + acy * bpy + acz * bpz
    if d3 >= 0.0 and d4 <= d3:
        return 0.0, 1.0, 0.0
    vc = d1 * d4 - d3 * d2
    if vc <= 0.0 and d1 >= 0.0 and d3 <= 0.0:
        v = d1 / (d1 - d3)
        return 1.0 - v, v, 0.0
    cpx, cpy, cpz = p[0] - c[0], p[1] - c[1], p[2] - c[2]
    d5 = abx * cpx + aby * cpy + abz * cpz
    d6 = acx * cpx + acy * cpy + acz * cpz
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


@jit(parallel=True)
def _prolong(pos, coarse_pos, cluster, tri_ptr, tri_list, triangles,
             nbr_ptr, nbr, mode):  # pragma: no cover (numba)
    """Row of P for every fine point: the closest candidate triangle
    incident to its own cell's coarse point (mode 0: barycentric weights
    of the closest point, 2: uniform), else, or with mode 1, inverse
    distance weights to the three closest of that coarse point and its
    coarse neighbours. Rows are independent, so they run in parallel."""
    n = pos.shape[0]
    cols = np.full((n, 3), -1, dtype=np.int64)
    vals = np.zeros((n, 3))
    for i in prange(n):
        found = False
        if mode != 1:
            found = _closest_triangle(pos[i], coarse_pos, tri_list[
                tri_ptr[cluster[i]]:tri_ptr[cluster[i] + 1]], triangles,
                mode == 2, cols[i], vals[i])
        if not found:
            s = cluster[i]
            _inverse_distance(pos[i], coarse_pos, s,
                              nbr[nbr_ptr[s]:nbr_ptr[s + 1]], cols[i],
                              vals[i])
    return cols, vals


@jit
def _closest_triangle(p, coarse_pos, candidates, triangles, uniform, cols,
                      vals):  # pragma: no cover (numba)
    best = np.inf
    for t in candidates:
        a, b, c = triangles[t, 0], triangles[t, 1], triangles[t, 2]
        u, v, w = _closest_on_triangle(p, coarse_pos[a], coarse_pos[b],
                                       coarse_pos[c])
        if u < 0.0:
            continue
        d = 0.0
        for k in range(3):
            q = (u * coarse_pos[a, k] + v * coarse_pos[b, k]
                 + w * coarse_pos[c, k])
            d += (q - p[k]) ** 2
        if d < best:
            best = d
            cols[0], cols[1], cols[2] = a, b, c
            if uniform:
                vals[0] = vals[1] = vals[2] = 1.0 / 3.0
            else:
                vals[0], vals[1], vals[2] = u, v, w
    return best < np.inf


@jit
def _inverse_distance(p, coarse_pos, s, neighbours, cols,
                      vals):  # pragma: no cover (numba)
    """Inverse distance weights to the three closest of coarse point s
    and its coarse neighbours; all weight to one of them if p is on it."""
    m = neighbours.shape[0] + 1
    cand = np.empty(m, dtype=np.int64)
    dist = np.empty(m)
    cand[0] = s
    cand[1:] = neighbours
    for k in range(m):
        d = 0.0
        for j in range(3):
            d += (coarse_pos[cand[k], j] - p[j]) ** 2
        dist[k] = math.sqrt(d)
    order = np.argsort(dist)
    total = 0.0
    for k in range(min(3, m)):
        c = cand[order[k]]
        if dist[order[k]] == 0.0:
            cols[:] = -1
            vals[:] = 0.0
            cols[0], vals[0], total = c, 1.0, 1.0
            break
        cols[k] = c
        vals[k] = 1.0 / dist[order[k]]
        total += vals[k]
    for k in range(3):
        vals[k] /= total


@jit
def _compact(cols, vals):  # pragma: no cover (numba)
    """The non-zeros of the (N, 3) rows as (2, nnz) indices and weights."""
    nnz = 0
    for i in range(cols.shape[0]):
        for k in range(3):
            nnz += cols[i, k] >= 0 and vals[i, k] > 0.0
    index = np.empty((2, nnz), dtype=np.int64)
    weight = np.empty(nnz)
    nnz = 0
    for i in range(cols.shape[0]):
        for k in range(3):
            if cols[i, k] >= 0 and vals[i, k] > 0.0:
                index[0, nnz], index[1, nnz] = i, cols[i, k]
                weight[nnz] = vals[i, k]
                nnz += 1
    return index, weight


def gravo_level(pos: Tensor, edge_index: Tensor, ratio: float = 8.0,
                shift: bool = True, weighting: str = 'barycentric',
                voronoi: str = 'exact') -> GravoLevel:
    r"""One Gravo MG coarsening step of the points ``pos`` (N, 3) with the
    neighbour graph ``edge_index`` (2, E; used in both directions).

    Samples are kept greedily in one sweep in index order; every kept
    point makes its neighbours closer than
    :math:`r = \text{ratio}^{1/3}\,\bar h` (:math:`\bar h` the mean edge
    length), and their neighbours within that path length, ineligible.
    With ``voronoi='exact'`` every point joins the graph Voronoi cell of its
    nearest sample (multi-source Dijkstra); ``'sweep'`` keeps the sample
    that claimed it during the sweep unless a Dijkstra from the samples
    that only continues through improved points finds a shorter path, as
    the original implementation does. Two samples are coarse neighbours
    when their cells touch; candidate triangles are the 3-cliques of the
    coarse graph. With ``shift`` every coarse point moves to the mean of its
    cell. Row :math:`i` of the prolongation :math:`P` holds the barycentric
    coordinates of the point closest to :math:`p_i` on the closest
    candidate triangle incident to its cell's coarse point, or, where there
    is none, inverse distance weights to the three closest of that coarse
    point and its coarse neighbours, so rows are non-negative, sum to 1 and
    have at most 3 non-zeros."""
    check_options(ratio, weighting, voronoi)
    like, pos, edge_index = _check_graph(pos, edge_index)
    level = _coarsen(pos, *_csr(edge_index, pos.shape[0]), ratio, shift,
                     weighting, voronoi)[0]
    return _as_tensors(level, like)


def check_options(ratio, weighting: str, voronoi: str):
    """Clear errors for a bad ratio, weighting or Voronoi mode."""
    if not (isinstance(ratio, (int, float)) and math.isfinite(ratio)
            and ratio > 1):
        raise ValueError(f"'ratio' must be a number above 1 (the factor by "
                         f"which each level shrinks), got {ratio!r}")
    check_choice(weighting, 'weighting', WEIGHTINGS)
    check_choice(voronoi, 'voronoi', VORONOI)


def _check_graph(pos, edge_index):
    """Points ``(N, 3)`` and a graph ``(2, E)`` (tensors or arrays) checked
    by the shared checks; returns the checked points and both as float64 /
    int64 numpy."""
    pos = check_points(torch.as_tensor(pos), 'pos')
    edge_index = torch.as_tensor(edge_index)
    if not edge_index.is_floating_point():
        edge_index = edge_index.long()
    edge_index = check_edge_index(edge_index, pos.size(0), pos)
    return (pos, np.ascontiguousarray(pos.detach().double().cpu().numpy()),
            np.ascontiguousarray(edge_index.cpu().numpy()))


def _as_tensors(level: GravoLevel, like: Tensor) -> GravoLevel:
    """A level of numpy arrays as tensors on ``like``'s device, positions
    and weights in its dtype."""
    def tensor(array, float_like=False):
        out = torch.from_numpy(np.ascontiguousarray(array))
        return out.to(like.device, like.dtype if float_like else None)
    return GravoLevel(tensor(level.sample), tensor(level.cluster),
                      tensor(level.pos, True), tensor(level.edge_index),
                      tensor(level.prolong_index),
                      tensor(level.prolong_weight, True))


def _coarsen(pos, indptr, indices, ratio, shift, weighting, voronoi):
    """gravo_level on a CSR graph; also returns the coarse CSR graph."""
    if indices.size == 0:
        raise ValueError("the neighbour graph has no edges between distinct "
                         "points; pass mesh edges or a k-nn graph")
    length = _edge_lengths(indptr, indices, pos)
    radius = ratio ** (1.0 / 3.0) * float(length.mean())
    sample, dist, cluster = _sample_sweep(indptr, indices, length, radius)
    if voronoi == 'exact':
        dist[:] = np.inf
        cluster[:] = -1
    dijkstra_from(indptr, indices, length, sample, dist, cluster)
    m = sample.size
    c_ptr, c_nbr = _csr(np.stack(_coarse_edges(indptr, indices, cluster)),
                        m)
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
    index, weight = _compact(cols, vals)
    return GravoLevel(sample, cluster, coarse_pos, coarse_edges, index,
                      weight), c_ptr, c_nbr


def gravo_hierarchy(pos: Tensor, edge_index: Tensor,
                    ratio: float = 8.0, lower_bound: int = 1000,
                    max_levels: int = 10, shift: bool = True,
                    weighting: str = 'barycentric', voronoi: str = 'exact'
                    ) -> List[GravoLevel]:
    """Coarsens with :func:`gravo_level` while the next level would keep at
    least ``lower_bound`` points, at most ``max_levels`` times. A level
    that keeps every point (all points coincide, so no sample covers
    another) ends the hierarchy: it would repeat forever."""
    check_options(ratio, weighting, voronoi)
    like, pos, edge_index = _check_graph(pos, edge_index)
    graph = _csr(edge_index, pos.shape[0])
    levels = []
    while len(levels) < max_levels and pos.shape[0] > lower_bound:
        level, *graph = _coarsen(pos, *graph, ratio, shift, weighting,
                                 voronoi)
        if level.sample.size < lower_bound \
                or level.sample.size >= pos.shape[0]:
            break
        levels.append(level)
        pos = level.pos
    return [_as_tensors(level, like) for level in levels]
