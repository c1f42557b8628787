r"""Graph Voronoi diagrams: every point is assigned to its nearest seed
along the edges of a neighbour graph (multi-source Dijkstra, compiled)."""
from typing import Optional, Tuple

import numpy as np
import torch
from torch import Tensor

from ..checks import (check_edge_index, check_index, check_points,
                      check_tensor)
from ..heap import sift_down, sift_up
from ..jit import jit


def graph_voronoi(pos: Tensor, edge_index: Tensor, seeds: Tensor,
                  edge_length: Optional[Tensor] = None
                  ) -> Tuple[Tensor, Tensor]:
    r"""Assigns every point to the seed at the smallest graph distance. It
    computes

    .. math::
        c(i) = \operatorname*{arg\,min}_{s \in S} d_G(i, s),

    with :math:`d_G` the shortest-path distance along the edges (lengths
    :math:`\|p_i - p_j\|` unless given). Ties go to the seed reached first.
    Edges are used in both directions.

    Args:
        pos (torch.Tensor): Point positions :math:`(N, 3)`.
        edge_index (torch.Tensor): Neighbour graph :math:`(2, E)`.
        seeds (torch.Tensor): Indices of the seeds :math:`(S)`.
        edge_length (torch.Tensor, optional): Length of every edge
            :math:`(E)`. (default: :obj:`None`)

    Returns:
        (cell, distance): the position in :obj:`seeds` of every point's seed
        :math:`(N)` and its graph distance :math:`(N)`.

    Raises:
        ValueError: if some point cannot reach any seed (a component of the
            graph without a seed): add a seed there or drop the component.
    """
    pos = check_points(pos)
    n = pos.size(0)
    edge_index = check_edge_index(edge_index, n, pos)
    seeds = check_tensor(seeds, 'seeds')
    if seeds.numel() == 0:
        raise ValueError("'seeds' is empty; pass at least one seed index")
    seeds = check_index(seeds, 'seeds', n, pos, ref_name='pos')
    src, dst = edge_index.cpu().numpy()
    if edge_length is None:
        p = pos.detach().cpu().double().numpy()
        length = np.sqrt(((p[src] - p[dst]) ** 2).sum(1))
    else:
        length = edge_length.detach().cpu().double().numpy()
        if length.shape != src.shape or not np.all(np.isfinite(length)) \
                or (length < 0).any():
            raise ValueError("'edge_length' must be [E], finite and "
                             "non-negative")
    # CSR of the symmetrised graph
    a = np.concatenate([src, dst])
    b = np.concatenate([dst, src])
    w = np.concatenate([length, length])
    order = np.argsort(a, kind='stable')
    indptr = np.zeros(n + 1, dtype=np.int64)
    indptr[1:] = np.cumsum(np.bincount(a, minlength=n))
    cell, dist = _multi_source_dijkstra(
        indptr, b[order].astype(np.int64), w[order],
        seeds.cpu().numpy().astype(np.int64), n)
    if (cell < 0).any():
        bad = np.nonzero(cell < 0)[0]
        raise ValueError(f"{bad.size} point(s) (first: {bad[:5].tolist()}) "
                         f"cannot reach any seed: their graph component has "
                         f"no seed; add one there or remove the component")
    device = pos.device
    return (torch.from_numpy(cell).to(device),
            torch.from_numpy(dist).to(device, pos.dtype))


@jit
def _multi_source_dijkstra(indptr, indices, weights, seeds, n
                           ):  # pragma: no cover (numba)
    dist = np.full(n, np.inf)
    cell = np.full(n, -1, dtype=np.int64)
    dijkstra_from(indptr, indices, weights, seeds, dist, cell)
    return cell, dist


@jit
def dijkstra_from(indptr, indices, weights, seeds, dist, cell
                   ):  # pragma: no cover (numba)
    """Multi-source Dijkstra that updates ``dist`` and ``cell`` in place.
    Only the seeds enter the queue, so finite starting distances elsewhere
    are kept wherever no shorter path reaches them (Gravo MG's 'sweep'
    correction); with infinite ones this is the exact graph Voronoi.

    The queue is a ring of buckets of width ``delta`` = the shortest
    positive edge (Dial's algorithm): a point taken from bucket b relaxes
    its neighbours into buckets after b, so every bucket is final when
    reached and there is no heap. Where edge lengths span too many buckets
    (or there are no positive lengths) a binary heap is used instead."""
    delta = np.inf
    longest = 0.0
    for w in weights:
        if 0.0 < w < delta:
            delta = w
        longest = max(longest, w)
    if delta == np.inf or longest / delta > 4.0 * dist.size + 64:
        _heap_dijkstra_from(indptr, indices, weights, seeds, dist, cell)
        return
    ring = int(longest / delta) + 2
    head = np.full(ring, -1, dtype=np.int64)
    capacity = indices.size + seeds.size
    following = np.empty(capacity, dtype=np.int64)
    entry_v = np.empty(capacity, dtype=np.int64)
    entry_d = np.empty(capacity)
    used = 0
    queued = np.zeros(dist.size, dtype=np.bool_)
    for s in range(seeds.size):
        v = seeds[s]
        if not queued[v]:  # a repeated seed keeps its first index
            queued[v] = True
            dist[v] = 0.0
            cell[v] = s
            entry_v[used], entry_d[used] = v, 0.0
            following[used], head[0] = head[0], used
            used += 1
    pending = used
    bucket = 0
    while pending > 0:
        slot = bucket % ring
        while head[slot] >= 0:
            k = head[slot]
            head[slot] = following[k]
            pending -= 1
            u, d = entry_v[k], entry_d[k]
            if d > dist[u]:
                continue  # a stale entry
            for e in range(indptr[u], indptr[u + 1]):
                v = indices[e]
                nd = d + weights[e]
                if nd < dist[v]:
                    dist[v] = nd
                    cell[v] = cell[u]
                    t = int(nd / delta) % ring
                    entry_v[used], entry_d[used] = v, nd
                    following[used], head[t] = head[t], used
                    used += 1
                    pending += 1
        bucket += 1


@jit
def _heap_dijkstra_from(indptr, indices, weights, seeds, dist, cell
                        ):  # pragma: no cover (numba)
    heap_d = np.empty(indices.size + seeds.size)
    heap_v = np.empty(indices.size + seeds.size, dtype=np.int64)
    size = 0
    queued = np.zeros(dist.size, dtype=np.bool_)
    for s in range(seeds.size):
        v = seeds[s]
        if not queued[v]:
            queued[v] = True
            dist[v] = 0.0
            cell[v] = s
            heap_d[size], heap_v[size] = 0.0, v
            size += 1
    for k in range(size // 2 - 1, -1, -1):
        sift_down(heap_d, heap_v, k, size)
    while size > 0:
        d, u = heap_d[0], heap_v[0]
        size -= 1
        heap_d[0], heap_v[0] = heap_d[size], heap_v[size]
        sift_down(heap_d, heap_v, 0, size)
        if d > dist[u]:
            continue
        for e in range(indptr[u], indptr[u + 1]):
            v = indices[e]
            nd = d + weights[e]
            if nd < dist[v]:
                dist[v] = nd
                cell[v] = cell[u]
                heap_d[size], heap_v[size] = nd, v
                sift_up(heap_d, heap_v, size)
                size += 1
