r"""Batch-aware neighbour search and farthest point sampling.

:func:`knn`, :func:`radius` and :func:`fps` replace ``torch_cluster``'s
functions of the same names without a compiled extension:

* on CPU, :func:`knn` and :func:`radius` query one
  :class:`scipy.spatial.cKDTree` (all cores) built over every example at
  once: each point gets an extra coordinate ``batch * offset`` with
  ``offset`` larger than any distance inside an example, so a single tree
  never returns a neighbour from another example;
  :func:`fps` runs a numba kernel, parallel across examples;
* on other devices (CUDA), :func:`knn` of 3-D points sorts them into a
  uniform grid per example and ranks the points of the cells around each
  centre, with the same rule and so the same graph as on the CPU; other
  dimensions and :func:`radius` pad the points to a dense
  ``[B, N_max, D]`` batch searched with chunked :func:`torch.cdist` +
  :func:`torch.topk` (about 256 MB per chunk); :func:`fps` is a loop over
  the samples whose distance update is vectorised over all examples at
  once.

Edges follow PyG's ``source_to_target`` flow: ``edge_index[0]`` is the
neighbour :math:`j` (an index into ``x``), ``edge_index[1]`` the centre
:math:`i` (an index into ``x``, or into ``query`` when one is given). Edges are
sorted by centre, and within a centre by distance (ties by neighbour index).
The distance that ranks :func:`knn`'s neighbours is the float64 squared
distance summed coordinate by coordinate, on every device.
"""
import itertools
import math
from typing import Optional, Tuple

import numpy as np
import torch
from numba import prange
from scipy.spatial import cKDTree
from torch import Tensor

from ..checks import (batch_sizes, check_batch, check_points,
                      check_positive_float, check_positive_int, same_device)
from ..jit import jit

__all__ = ['knn', 'radius', 'fps']

# Memory budget of one distance chunk on the dense (GPU) path.
_CHUNK_BYTES = 256 * 2 ** 20
# Entries (rows * neighbours) of one cKDTree query chunk on the CPU path.
_TREE_CHUNK = 2 ** 21
# Above this many neighbours per centre, radius() uses a ball query on CPU.
_BALL_QUERY_K = 256


def _use_dense(x: Tensor) -> bool:
    """Whether to use the dense (cdist + topk) path instead of cKDTree."""
    return x.device.type != 'cpu'


# ----------------------------------------------------------------------------
# validation
# ----------------------------------------------------------------------------
def _check_magnitude(p: Tensor, name: str):
    """Rejects coordinates so large that squared distances would overflow."""
    if p.numel() == 0:
        return
    limit = math.sqrt(torch.finfo(p.dtype).max / (4.0 * p.size(1))) / 2.0
    biggest = float(p.detach().abs().max())
    if biggest > limit:
        raise ValueError(f"'{name}' has coordinates up to {biggest:.3g} in "
                         f"absolute value, so squared distances would "
                         f"overflow {p.dtype}; rescale the points first "
                         f"(e.g. divide by their bounding-box size)")


def _check_batch_named(batch, num: int, ref: Tensor, name: str,
                       ref_name: str) -> Optional[Tensor]:
    try:
        return check_batch(batch, num, ref)
    except ValueError as err:
        msg = str(err).replace("'batch'", f"'{name}'")
        raise ValueError(msg.replace("'pos'", f"'{ref_name}'")) from None


def _check_cloud(x, name: str, min_points: int, dim: Optional[int] = None):
    x = check_points(x, name, dim=dim, min_points=min_points)
    if x.size(1) < 1:
        raise ValueError(f"'{name}' must have shape [N, D] with at least one "
                         f"coordinate column (D >= 1), got {list(x.shape)}")
    _check_magnitude(x, name)
    return x


def _check_inputs(x, batch, query, query_batch, min_points: int):
    """Validates (x, batch, query, query_batch); returns them as tensors."""
    x = _check_cloud(x, 'x', min_points)
    batch = _check_batch_named(batch, x.size(0), x, 'batch', 'x')
    if query is None:
        if query_batch is not None:
            raise ValueError("'query_batch' was given without 'query'; pass "
                             "the query points too, or drop 'query_batch'")
        return x, batch, None, None
    query = _check_cloud(query, 'query', 0, dim=x.size(1))
    same_device(query, 'query', x, 'x')
    if query.dtype != x.dtype:
        raise ValueError(f"'query' is {query.dtype} but 'x' is {x.dtype}; "
                         f"convert one of them so both have the same dtype")
    query_batch = _check_batch_named(query_batch, query.size(0), x,
                                     'query_batch', 'x')
    return x, batch, query, query_batch


def _example_sizes(batch: Optional[Tensor], num: int, length: int) -> Tensor:
    """Points per example (CPU LongTensor of the given length)."""
    sizes = batch_sizes(batch, num)
    if sizes.numel() < length:
        sizes = torch.cat([sizes, sizes.new_zeros(length - sizes.numel())])
    return sizes


def _sizes(x, batch, query, query_batch) -> Tuple[Tensor, Tensor]:
    """Per-example sizes of x and of the centres, padded to one length."""
    sx = batch_sizes(batch, x.size(0))
    if query is None:
        return sx, sx
    sq = batch_sizes(query_batch, query.size(0))
    length = max(sx.numel(), sq.numel(), 1)
    return (_example_sizes(batch, x.size(0), length),
            _example_sizes(query_batch, query.size(0), length))


def _check_k(k: int, sx: Tensor, sq: Tensor, graph: bool, loop: bool):
    avail = sx - 1 if graph and not loop else sx
    bad = ((sq > 0) & (avail < k)).nonzero().flatten()
    if bad.numel() == 0:
        return
    b = int(bad[0])
    most = int(avail[sq > 0].min())
    if most < 1:
        todo = ('remove that example' if graph else
                "give 'x' points in that example or remove its queries")
        if graph and not loop:
            todo += ' or pass loop=True'
    else:
        todo = f'lower k to at most {most}'
    if graph:
        extra = (f' and loop=False excludes the point itself, so it has '
                 f'only {int(avail[b])} candidate neighbour(s) per centre'
                 if not loop else '')
        raise ValueError(f"knn: example {b} has {int(sx[b])} point(s){extra},"
                         f" fewer than k={k}; {todo}")
    raise ValueError(f"knn: query example {b} has {int(sq[b])} query "
                     f"point(s) but 'x' has only {int(sx[b])} point(s) in "
                     f"that example, fewer than k={k}; {todo}")


def _empty_edges(device) -> Tensor:
    return torch.empty(2, 0, dtype=torch.long, device=device)


# ----------------------------------------------------------------------------
# CPU path: one cKDTree over all examples
# ----------------------------------------------------------------------------
def _as_np(t: Tensor) -> np.ndarray:
    return t.detach().cpu().to(torch.float64).numpy()


def _batch_np(batch: Optional[Tensor], num: int) -> np.ndarray:
    if batch is None:
        return np.zeros(num, dtype=np.int64)
    return batch.detach().cpu().numpy()


def _tree_coords(xn, bx, qn, bq, reach: float):
    """Appends ``batch * offset`` as a coordinate when there are examples.

    ``offset`` exceeds every distance between points of one example (the
    bounding-box diagonal of all points) plus ``reach``, so neighbours at
    distance <= reach (or the k nearest of an example with >= k points) never
    come from another example. Points of one example share the extra
    coordinate exactly, so their tree distance is unchanged.
    """
    allb = np.concatenate([bx, bq])
    if allb.size == 0 or allb.min() == allb.max():
        return xn, qn, None
    allp = np.concatenate([xn, qn])
    diag = float(np.linalg.norm(allp.max(0) - allp.min(0)))
    offset = 2.0 * diag + 2.0 * reach + 1.0
    xt = np.hstack([xn, (bx * offset)[:, None]])
    qt = np.hstack([qn, (bq * offset)[:, None]])
    return xt, qt, diag


def _sqdist_np(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """Row-wise squared distances, summed coordinate by coordinate."""
    d = (a[:, 0] - b[:, 0]) ** 2
    for j in range(1, a.shape[1]):
        d += (a[:, j] - b[:, j]) ** 2
    return d


def _finish_rows(rows: np.ndarray, nbr: np.ndarray, key: np.ndarray,
                 limit: int, num_rows: int, row0: int):
    """Keeps the ``limit`` smallest-key entries of every row.

    ``rows`` is ascending (row-major order of a query result, already sorted
    by the tree's distance within a row); rows are re-sorted by (key, index)
    only where that order is off (ties, rounding). Returns (neighbour,
    centre) arrays sorted by centre, then by distance.
    """
    same = rows[1:] == rows[:-1]
    bad = same & ((key[1:] < key[:-1])
                  | ((key[1:] == key[:-1]) & (nbr[1:] < nbr[:-1])))
    if bad.any():
        order = np.lexsort((nbr, key, rows))
        rows, nbr = rows[order], nbr[order]
    first = np.zeros(num_rows + 1, dtype=np.int64)
    np.cumsum(np.bincount(rows, minlength=num_rows), out=first[1:])
    keep = np.arange(rows.size) - first[rows] < limit
    return nbr[keep], rows[keep] + row0


def _to_edge_index(nbr, ctr, device) -> Tensor:
    out = torch.from_numpy(np.stack([np.asarray(nbr, dtype=np.int64),
                                     np.asarray(ctr, dtype=np.int64)]))
    return out.to(device)


def _knn_tree(x: Tensor, k: int, batch: Optional[Tensor], loop: bool,
              query: Optional[Tensor], query_batch: Optional[Tensor]):
    """The k nearest by the rule of :func:`knn` (float64 squared distance
    summed coordinate by coordinate, ties by index): the tree proposes
    candidates, which are ranked by that key; a row whose k-th key is not
    clearly inside the tree's reach (ties or rounding at the boundary) is
    asked again with twice as many candidates."""
    graph = query is None
    xn = _as_np(x)
    bx = _batch_np(batch, x.size(0))
    qn = xn if graph else _as_np(query)
    bq = bx if graph else _batch_np(query_batch, query.size(0))
    xt, qt, _ = _tree_coords(xn, bx, qn, bq, 0.0)
    tree = cKDTree(xt, balanced_tree=False)
    base = k + 1 if graph and not loop else k
    nbrs, ctrs = [], []
    rows_todo = np.arange(qt.shape[0])
    want = base + 2
    while rows_todo.size:
        want = min(want, xt.shape[0])
        step = max(1, _TREE_CHUNK // want)
        retry = []
        for s in range(0, rows_todo.size, step):
            centres = rows_todo[s:s + step]
            dist, idx = tree.query(qt[centres], k=want, workers=-1)
            dist = dist.reshape(-1, want)
            idx = idx.reshape(-1, want).astype(np.int64)
            found = idx < xn.shape[0]
            safe = np.where(found, idx, 0)
            same = found & (bx[safe] == bq[centres][:, None])
            if graph and not loop:
                same &= idx != centres[:, None]
            # every point of the example was proposed when the tree also
            # returned another example's points, or ran out
            whole = (~same[:, -1]) | (want == xt.shape[0])
            q = qn[centres]
            key = (xn[safe, 0] - q[:, None, 0]) ** 2
            for j in range(1, xn.shape[1]):
                key += (xn[safe, j] - q[:, None, j]) ** 2
            key[~same] = np.inf
            if graph and not loop:  # the centre itself out: mostly first
                moved = np.nonzero(idx[:, 0] != centres)[0]
                if moved.size:
                    order = np.argsort(~same[moved], axis=1, kind='stable')
                    order = np.concatenate([order[:, -1:], order[:, :-1]],
                                           1)  # the centre's inf first
                    key[moved] = np.take_along_axis(key[moved], order, 1)
                    safe[moved] = np.take_along_axis(safe[moved], order, 1)
                key, safe = key[:, 1:], safe[:, 1:]
            # the tree's order is the rule's but for ties and rounding:
            # sort only the rows where it is not
            off = (key[:, 1:] < key[:, :-1]) | (
                (key[:, 1:] == key[:, :-1]) & (safe[:, 1:] < safe[:, :-1]))
            bad = np.nonzero(off.any(1))[0]
            if bad.size:
                order = np.lexsort((safe[bad], key[bad]), axis=-1)
                key[bad] = np.take_along_axis(key[bad], order, 1)
                safe[bad] = np.take_along_axis(safe[bad], order, 1)
            reach = dist[:, -1] ** 2 * (1 - 1e-9)
            done = whole | (key[:, k - 1] < reach)
            nbrs.append(safe[done, :k].reshape(-1))
            ctrs.append(np.repeat(centres[done], k))
            retry.append(centres[~done])
        rows_todo = np.concatenate(retry)
        want *= 2
    nbr, ctr = np.concatenate(nbrs), np.concatenate(ctrs)
    order = np.argsort(ctr, kind='stable')  # rows kept their rank order
    return _to_edge_index(nbr[order], ctr[order], x.device)


def _radius_tree(x: Tensor, r: float, batch: Optional[Tensor], cap: int,
                 loop: bool, query: Optional[Tensor],
                 query_batch: Optional[Tensor], sx: Tensor):
    graph = query is None
    xn = _as_np(x)
    bx = _batch_np(batch, x.size(0))
    qn = xn if graph else _as_np(query)
    bq = bx if graph else _batch_np(query_batch, query.size(0))
    allp = np.concatenate([xn, qn])
    diag = float(np.linalg.norm(allp.max(0) - allp.min(0)))
    # Search slightly beyond r (the tree rounds differently), then filter by
    # the exact squared distance. Beyond the diagonal nothing more is found.
    # (All points coincident: diag = 0 would make the reach 0, and the
    # tree compares squared distances, so even self-pairs would be lost.)
    reach = float(np.nextafter((min(r, diag) if diag > 0 else r)
                               * (1 + 1e-6), np.inf))
    xt, qt, _ = _tree_coords(xn, bx, qn, bq, reach)
    tree = cKDTree(xt, balanced_tree=False)
    r2 = r * r
    kq = min(cap + 1 if graph and not loop else cap, int(sx.max()))
    num_q = qt.shape[0]
    if kq <= _BALL_QUERY_K:
        step = max(1, _TREE_CHUNK // kq)
        nbrs, ctrs = [], []
        for s in range(0, num_q, step):
            _, idx = tree.query(qt[s:s + step], k=kq, workers=-1,
                                distance_upper_bound=reach)
            idx = idx.reshape(-1, kq).astype(np.int64)
            valid = idx < xn.shape[0]
            if graph and not loop:
                valid &= idx != np.arange(s, s + idx.shape[0])[:, None]
            rows, cols = np.nonzero(valid)
            nbr = idx[rows, cols]
            d2 = _sqdist_np(qn[rows + s], xn[nbr])
            ok = d2 <= r2
            nbr, ctr = _finish_rows(rows[ok], nbr[ok], d2[ok], cap,
                                    idx.shape[0], s)
            nbrs.append(nbr)
            ctrs.append(ctr)
        return _to_edge_index(np.concatenate(nbrs), np.concatenate(ctrs),
                              x.device)
    # Large caps: a ball query returns only what is within reach.
    lists = tree.query_ball_point(qt, reach, workers=-1, return_sorted=False)
    lens = np.fromiter((len(a) for a in lists), dtype=np.int64, count=num_q)
    nbr = np.fromiter(itertools.chain.from_iterable(lists), dtype=np.int64,
                      count=int(lens.sum()))
    ctr = np.repeat(np.arange(num_q, dtype=np.int64), lens)
    d2 = _sqdist_np(qn[ctr], xn[nbr])
    keep = d2 <= r2
    if graph and not loop:
        keep &= nbr != ctr
    nbr, ctr, d2 = nbr[keep], ctr[keep], d2[keep]
    # ctr is ascending; _finish_rows sorts the (unsorted) ball results
    nbr, ctr = _finish_rows(ctr, nbr, d2, cap, num_q, 0)
    return _to_edge_index(nbr, ctr, x.device)


# ----------------------------------------------------------------------------
# dense path (GPU): padded batch, chunked cdist + topk
# ----------------------------------------------------------------------------
def _pad(p: Tensor, batch: Optional[Tensor], num_examples: int):
    """torch_geometric-free ``to_dense_batch``: [B, N_max, D], mask, ptr."""
    n = p.size(0)
    if batch is None:
        batch = torch.zeros(n, dtype=torch.long, device=p.device)
    sizes = torch.bincount(batch, minlength=num_examples)
    ptr = torch.zeros(num_examples + 1, dtype=torch.long, device=p.device)
    ptr[1:] = sizes.cumsum(0)
    n_max = int(sizes.max()) if n > 0 else 0
    local = torch.arange(n, device=p.device) - ptr[batch]
    dense = p.new_zeros(num_examples, n_max, p.size(1))
    dense[batch, local] = p
    mask = torch.zeros(num_examples, n_max, dtype=torch.bool, device=p.device)
    mask[batch, local] = True
    return dense, mask, ptr, batch


def _chunk_rows(num_examples: int, n_max: int, itemsize: int) -> int:
    # distances + topk / sort temporaries: ~4 arrays of [B, c, N_max]
    per_row = max(1, num_examples * n_max * itemsize * 4)
    return max(1, _CHUNK_BYTES // per_row)


def _tie_sort(val: Tensor, idx: Tensor) -> Tuple[Tensor, Tensor]:
    """Sorts the last dim by value, ties by index."""
    idx, order = idx.sort(dim=-1)
    val = val.gather(-1, order)
    val, order = val.sort(dim=-1, stable=True)
    return val, idx.gather(-1, order)


def _dense_setup(x, batch, query, query_batch, length):
    graph = query is None
    if graph:
        query, query_batch = x, batch
    x = x.detach()
    query = query.detach()
    xd, xmask, xptr, _ = _pad(x, batch, length)
    qd, qmask, _, qb = _pad(query, query_batch, length)
    return graph, xd, xmask, xptr, qd, qmask, qb


def _dist_chunk(qd, xd, xmask, s, e, exclude_self):
    d = torch.cdist(qd[:, s:e], xd,
                    compute_mode='donot_use_mm_for_euclid_dist')
    d.masked_fill_(~xmask[:, None, :], float('inf'))
    if exclude_self:  # graph mode: local query index == local x index
        rows = torch.arange(s, e, device=d.device)
        d[:, rows - s, rows] = float('inf')
    return d


def _knn_dense(x: Tensor, k: int, batch: Optional[Tensor], loop: bool,
               query: Optional[Tensor], query_batch: Optional[Tensor],
               length: int) -> Tensor:
    graph, xd, xmask, xptr, qd, qmask, qb = _dense_setup(
        x, batch, query, query_batch, length)
    num_examples, m_max = qd.shape[:2]
    if qmask.sum() == 0:
        return _empty_edges(x.device)
    out = torch.empty(num_examples, m_max, k, dtype=torch.long,
                      device=x.device)
    step = _chunk_rows(num_examples, xd.size(1), xd.element_size())
    for s in range(0, m_max, step):
        e = min(s + step, m_max)
        d = _dist_chunk(qd, xd, xmask, s, e, graph and not loop)
        val, idx = d.topk(k, dim=-1, largest=False, sorted=True)
        out[:, s:e] = _tie_sort(val, idx)[1]
    nbr = out[qmask] + xptr[qb][:, None]  # rows in global centre order
    ctr = torch.arange(nbr.size(0), device=x.device)
    return torch.stack([nbr.reshape(-1), ctr.repeat_interleave(k)])


# ----------------------------------------------------------------------------
# grid path (GPU, 3-D points): a uniform grid per example, rings of cells
# ----------------------------------------------------------------------------
# points per occupied cell the grid aims at, as a share of k
_CELL_SHARE = 0.5
# candidates handled at once (about 24 bytes each)
_GRID_CHUNK = 2 ** 24


def _scatter_extreme(p: Tensor, index: Tensor, size: int, reduce: str):
    out = p.new_zeros(size, p.size(1))
    return out.scatter_reduce_(0, index[:, None].expand_as(p), p, reduce,
                               include_self=False)


def _cell_index(cell: Tensor, dims: Tensor) -> Tensor:
    """The linear index of integer cells ``(..., 3)`` in grids of
    ``dims`` ``(..., 3)`` cells per axis."""
    return (cell[..., 0] * dims[..., 1] + cell[..., 1]) * dims[..., 2] \
        + cell[..., 2]


def _grid_cells(xd, xb, size: int, k: int):
    r"""Per example: the grid origin, cell size and cells per axis, with the
    cell size set so that the cell of a point holds about
    ``_CELL_SHARE * k`` points: the occupancy seen from the points
    (:math:`\sum c^2 / \sum c` over the cells' counts :math:`c`, which dense
    regions dominate), refined twice from a volume estimate; surfaces fill
    few cells."""
    lo = _scatter_extreme(xd, xb, size, 'amin')
    hi = _scatter_extreme(xd, xb, size, 'amax')
    count = torch.bincount(xb, minlength=size).to(xd.dtype)
    extent = (hi - lo).clamp_min(1e-12)
    target = max(1.0, _CELL_SHARE * k)
    h = (extent.prod(1) / count.clamp_min(1) * target).pow(1 / 3)
    h = torch.maximum(h, extent.max(1).values / 1024)  # at most 1024^3
    for _ in range(2):
        dims = (extent / h[:, None]).floor().long() + 1
        cell = ((xd - lo[xb]) / h[xb, None]).floor().long()
        cell = torch.minimum(cell, dims[xb] - 1)
        key = _cell_index(cell, dims[xb]) + xb * (1 << 31)
        cells, per_cell = torch.unique(key, return_counts=True)
        seen = torch.zeros(size, dtype=xd.dtype, device=xd.device)
        seen.index_add_(0, cells >> 31, per_cell.to(xd.dtype).square())
        seen = seen / count.clamp_min(1)
        # occupancy grows like h^2 on a surface, h^3 in a volume
        h = torch.maximum(h * (target / seen.clamp_min(1e-12)).pow(0.4),
                          extent.max(1).values / 1024)
    dims = (extent / h[:, None]).floor().long() + 1
    return lo, h, dims


def _knn_grid(x: Tensor, k: int, batch: Optional[Tensor], loop: bool,
              query: Optional[Tensor], query_batch: Optional[Tensor],
              length: int) -> Tensor:
    """:func:`knn` on a grid, on any device, by the rule of :func:`knn`
    (float64 squared distance summed coordinate by coordinate, ties by
    index), so its graph is the CPU path's. Each centre takes the points of
    the cells within ``R`` cells of its own, which hold every point closer
    than ``R`` cell sizes; a centre whose k-th neighbour is not closer is
    asked again with ``R + 1``, and after ``R = 2`` with its whole
    example."""
    graph = query is None
    device = x.device
    xd = x.detach().double()
    xb = torch.zeros(x.size(0), dtype=torch.long, device=device) \
        if batch is None else batch
    qd = xd if graph else query.detach().double()
    qb = xb if graph else (torch.zeros(qd.size(0), dtype=torch.long,
                                       device=device)
                           if query_batch is None else query_batch)
    lo, h, dims = _grid_cells(xd, xb, length, k)
    volume = dims.prod(1)
    base = torch.zeros(length + 1, dtype=torch.long, device=device)
    base[1:] = volume.cumsum(0)

    def cells(p, b):
        c = ((p - lo[b]) / h[b, None]).floor().long()
        return torch.minimum(c.clamp_min(0), dims[b] - 1)

    def keys(c, b):
        return base[b] + _cell_index(c, dims[b])
    xkey = keys(cells(xd, xb), xb)
    sorted_keys, order = xkey.sort(stable=True)
    qcell = cells(qd, qb)
    m = qd.size(0)
    out = torch.empty(m, k, dtype=torch.long, device=device)
    todo = torch.arange(m, device=device)
    for ring in (1, 2, None):
        if todo.numel() == 0:
            break
        b = qb[todo]
        if ring is None:  # the whole example
            start = torch.searchsorted(sorted_keys, base[b])[:, None]
            end = torch.searchsorted(sorted_keys, base[b + 1])[:, None]
        else:
            steps = torch.arange(-ring, ring + 1, device=device)
            offsets = torch.cartesian_prod(steps, steps, steps)
            c = qcell[todo][:, None, :] + offsets[None]
            inside = ((c >= 0) & (c < dims[b][:, None, :])).all(-1)
            ckey = keys(c.clamp_min(0), b[:, None])
            start = torch.searchsorted(sorted_keys, ckey)
            end = torch.searchsorted(sorted_keys, ckey, right=True)
            end = torch.where(inside, end, start)
        counts = end - start
        total = counts.sum(1)
        done = torch.zeros(todo.numel(), dtype=torch.bool, device=device)
        bounds = torch.cumsum(total, 0)
        first = 0
        while first < todo.numel():
            # centres [first, last) hold at most _GRID_CHUNK candidates
            limit = (bounds[first - 1] if first else 0) + _GRID_CHUNK
            last = max(first + 1, int(torch.searchsorted(
                bounds, torch.as_tensor(limit, device=device),
                right=True)))
            last = min(last, todo.numel())
            rows = slice(first, last)
            pair_count = counts[rows].reshape(-1)
            pair = torch.repeat_interleave(
                torch.arange(pair_count.numel(), device=device), pair_count)
            pair_first = torch.cumsum(pair_count, 0) - pair_count
            position = start[rows].reshape(-1)[pair] + (
                torch.arange(pair.numel(), device=device) - pair_first[pair])
            cand = order[position]
            row = pair // counts.size(1)
            centre = todo[rows][row]
            if graph and not loop:
                keep = cand != centre
                cand, row, centre = cand[keep], row[keep], centre[keep]
            diff = xd[cand] - qd[centre]
            key = diff[:, 0].square()
            for j in range(1, diff.size(1)):
                key = key + diff[:, j].square()
            # sort by (row, key, candidate): stable sorts, last key first
            perm = cand.argsort(stable=True)
            perm = perm[key[perm].argsort(stable=True)]
            perm = perm[row[perm].argsort(stable=True)]
            cand, row, key = cand[perm], row[perm], key[perm]
            per_row = torch.bincount(row, minlength=last - first)
            row_first = torch.cumsum(per_row, 0) - per_row
            rank = torch.arange(row.numel(), device=device) - row_first[row]
            enough = per_row >= k
            kth = torch.full((last - first,), float('inf'),
                             dtype=key.dtype, device=device)
            at_k = rank == k - 1
            kth[row[at_k]] = key[at_k]
            if ring is None:
                ok = enough
            else:
                reach = (ring * h[b[rows]]).square() * (1 - 1e-9)
                ok = enough & (kth < reach)
            take = (rank < k) & ok[row]
            out[todo[rows][row[take]], rank[take]] = cand[take]
            done[rows] = ok
            first = last
        todo = todo[~done]
    ctr = torch.arange(m, device=device).repeat_interleave(k)
    return torch.stack([out.reshape(-1), ctr])


def _radius_dense(x: Tensor, r: float, batch: Optional[Tensor], cap: int,
                  loop: bool, query: Optional[Tensor],
                  query_batch: Optional[Tensor], length: int) -> Tensor:
    graph, xd, xmask, xptr, qd, qmask, qb = _dense_setup(
        x, batch, query, query_batch, length)
    num_examples, m_max = qd.shape[:2]
    if xd.size(1) == 0 or qmask.sum() == 0:
        return _empty_edges(x.device)
    kk = min(cap, xd.size(1))
    # global index of every dense query row (-1 for padding)
    qglob = torch.full(qmask.shape, -1, dtype=torch.long, device=x.device)
    qglob[qmask] = torch.arange(int(qmask.sum()), device=x.device)
    step = _chunk_rows(num_examples, xd.size(1), xd.element_size())
    nbrs, ctrs = [], []
    for s in range(0, m_max, step):
        e = min(s + step, m_max)
        d = _dist_chunk(qd, xd, xmask, s, e, graph and not loop)
        val, idx = _tie_sort(*d.topk(kk, dim=-1, largest=False, sorted=True))
        ok = (val <= r) & torch.isfinite(val) & qmask[:, s:e, None]
        nbr = idx + xptr[:-1, None, None]
        ctr = qglob[:, s:e, None].expand_as(idx)
        nbrs.append(nbr[ok])
        ctrs.append(ctr[ok])
    nbr, ctr = torch.cat(nbrs), torch.cat(ctrs)
    # chunks are interleaved across examples: regroup by centre, keeping the
    # (distance-sorted) order of each centre's edges
    ctr, order = ctr.sort(stable=True)
    return torch.stack([nbr[order], ctr])


# ----------------------------------------------------------------------------
# farthest point sampling
# ----------------------------------------------------------------------------
@jit
def _fps_update(pts, cur_pt, dist):  # pragma: no cover (numba)
    """dist[i] = min(dist[i], |pts[:, i] - cur_pt|^2); returns the first i of
    the maximum (chosen points hold -1 and stay there)."""
    dim, n = pts.shape
    if dim == 3:  # unrolled, vectorises
        a, b, c = pts[0], pts[1], pts[2]
        ca, cb, cc = cur_pt[0], cur_pt[1], cur_pt[2]
        for i in range(n):
            t0 = a[i] - ca
            t1 = b[i] - cb
            t2 = c[i] - cc
            dist[i] = min(dist[i], t0 * t0 + t1 * t1 + t2 * t2)
    else:
        for i in range(n):
            d = 0.0
            for j in range(dim):
                t = pts[j, i] - cur_pt[j]
                d += t * t
            dist[i] = min(dist[i], d)
    best = 0
    best_d = dist[0]
    for i in range(1, n):
        if dist[i] > best_d:  # strict: ties keep the lowest index
            best_d = dist[i]
            best = i
    return best


@jit(parallel=True)
def _fps_examples(pos_t, ptr, starts, out_ptr, out):  # pragma: no cover
    """Many examples: one thread per example."""
    for b in prange(ptr.shape[0] - 1):
        lo, hi = ptr[b], ptr[b + 1]
        m = out_ptr[b + 1] - out_ptr[b]
        if m == 0:
            continue
        pts = pos_t[:, lo:hi]
        dist = np.full(hi - lo, np.inf)
        cur = starts[b]
        for s in range(m):
            out[out_ptr[b] + s] = lo + cur
            dist[cur] = -1.0  # chosen: never again
            cur = _fps_update(pts, pts[:, cur].copy(), dist)


def _fps_numba(pos: Tensor, ptr: Tensor, starts: Tensor,
               counts: Tensor) -> Tensor:
    out_ptr = torch.zeros(counts.numel() + 1, dtype=torch.long)
    out_ptr[1:] = counts.cumsum(0)
    out = np.empty(int(out_ptr[-1]), dtype=np.int64)
    pos_t = np.ascontiguousarray(_as_np(pos).T)  # [D, N]: vectorises
    # One thread per example. (Splitting every step of one large example
    # across threads needs a barrier per sample; measured 1.7x faster on an
    # idle 2-core machine but up to 6x slower when another process competes
    # for the cores, so it is not done.)
    _fps_examples(pos_t, ptr.numpy(), starts.numpy(), out_ptr.numpy(), out)
    return torch.from_numpy(out).to(pos.device)


def _fps_dense(pos: Tensor, batch: Optional[Tensor], starts: Tensor,
               counts: Tensor) -> Tensor:
    num_examples = counts.numel()
    dev = pos.device
    pd, mask, ptr, _ = _pad(pos.detach(), batch, num_examples)
    starts, counts = starts.to(dev), counts.to(dev)
    num_s = int(counts.max())
    dist = torch.full(mask.shape, float('inf'), dtype=pos.dtype, device=dev)
    dist.masked_fill_(~mask, -1.0)
    sel = torch.zeros(num_examples, num_s, dtype=torch.long, device=dev)
    ar = torch.arange(num_examples, device=dev)
    cur = starts
    for s in range(num_s):
        sel[:, s] = cur
        p = pd[ar, cur]  # [B, D]
        d = (pd[:, :, 0] - p[:, None, 0]) ** 2
        for j in range(1, pd.size(2)):
            d += (pd[:, :, j] - p[:, None, j]) ** 2
        dist = torch.minimum(dist, d)
        dist[ar, cur] = -1.0
        cur = dist.argmax(dim=1)  # first maximum: ties -> lowest index
    keep = torch.arange(num_s, device=dev)[None, :] < counts[:, None]
    return (sel + ptr[:-1, None])[keep]


# ----------------------------------------------------------------------------
# public API
# ----------------------------------------------------------------------------
def knn(x: Tensor, k: int, batch: Optional[Tensor] = None, loop: bool = False,
        *, query: Optional[Tensor] = None,
        query_batch: Optional[Tensor] = None) -> Tensor:
    r"""Computes the k-nearest-neighbour graph of a batch of point clouds.

    For every centre :math:`\mathbf{y}_i` (a point of :obj:`x`, or of
    :obj:`query` when given) returns its :math:`k` nearest points of :obj:`x`
    within the same example :math:`\mathcal{B}(i)`:

    .. math::
        \mathcal{N}(i) = \underset{j \in \mathcal{B}(i),\ j \neq i}
        {\operatorname{arg\,min}^{(k)}} \, \| \mathbf{x}_j - \mathbf{y}_i \|_2

    (:math:`j \neq i` only without :obj:`query` and with :obj:`loop=False`;
    the centre is excluded by index, so a duplicate point at distance 0 is
    still a valid neighbour). Edges follow PyG's ``source_to_target`` flow:
    :obj:`edge_index[0]` is the neighbour :math:`j` (index into :obj:`x`),
    :obj:`edge_index[1]` the centre :math:`i` (index into :obj:`x`, or into
    :obj:`query`). Edges are sorted by centre and, within a centre, by
    distance (ties by neighbour index). Note that this is the opposite row
    order of ``torch_cluster.knn(x, y)`` in the bipartite case.

    The neighbours are ranked by the float64 squared distance summed
    coordinate by coordinate, ties by index, on every device, so the graph
    does not depend on it. On CPU one :class:`scipy.spatial.cKDTree` serves
    all examples; on other devices 3-D points are searched in a grid of
    cells per example, other dimensions in a padded batch with chunked
    :func:`torch.cdist` + :func:`torch.topk`.

    Args:
        x (torch.Tensor): Point coordinates, float32 or float64, any
            dimension :math:`D \geq 1`.
        k (int): Number of neighbours of every centre.
        batch (torch.Tensor, optional): Sorted example index of every point
            of :obj:`x` (PyG's :obj:`batch`). (default: :obj:`None`, one
            example)
        loop (bool, optional): If :obj:`True`, a point is its own neighbour
            (graph mode only; ignored with :obj:`query`).
            (default: :obj:`False`)
        query (torch.Tensor, optional): Centres :math:`\mathbf{y}`, same
            dtype, device and :math:`D` as :obj:`x`; if given, the result is
            the bipartite graph from :obj:`x` to :obj:`query`.
            (default: :obj:`None`)
        query_batch (torch.Tensor, optional): Sorted example index of every
            query point. (default: :obj:`None`, example 0)

    Raises:
        ValueError: on malformed input, or when an example with centres has
            fewer than :obj:`k` candidate neighbours (lower :obj:`k`).

    Shapes:
        - **input:** :obj:`x` :math:`(N, D)`, :obj:`batch` :math:`(N)`,
          :obj:`query` :math:`(M, D)`, :obj:`query_batch` :math:`(M)`
        - **output:** :obj:`edge_index` :math:`(2, M k)` (:math:`M = N`
          without :obj:`query`), int64 on :obj:`x`'s device
    """
    x, batch, query, query_batch = _check_inputs(x, batch, query,
                                                 query_batch, min_points=1)
    k = check_positive_int(k, 'k')
    loop = bool(loop)
    graph = query is None
    sx, sq = _sizes(x, batch, query, query_batch)
    if not graph and query.size(0) == 0:
        return _empty_edges(x.device)
    _check_k(k, sx, sq, graph, loop)
    if not _use_dense(x):
        return _knn_tree(x, k, batch, loop, query, query_batch)
    if x.size(1) == 3:
        return _knn_grid(x, k, batch, loop, query, query_batch, sx.numel())
    return _knn_dense(x, k, batch, loop, query, query_batch, sx.numel())


def radius(x: Tensor, r: float, batch: Optional[Tensor] = None,
           max_num_neighbors: int = 64, loop: bool = False, *,
           query: Optional[Tensor] = None,
           query_batch: Optional[Tensor] = None) -> Tensor:
    r"""Computes the radius graph of a batch of point clouds.

    For every centre :math:`\mathbf{y}_i` (a point of :obj:`x`, or of
    :obj:`query` when given) returns the points of :obj:`x` of the same
    example :math:`\mathcal{B}(i)` within distance :math:`r`,

    .. math::
        \mathcal{N}(i) = \{ j \in \mathcal{B}(i) :
        \| \mathbf{x}_j - \mathbf{y}_i \|_2 \leq r \},

    keeping the :obj:`max_num_neighbors` *nearest* ones when there are more
    (``torch_cluster`` keeps arbitrary ones). Centres with no neighbour have
    no edge. Edges follow PyG's ``source_to_target`` flow:
    :obj:`edge_index[0]` is the neighbour :math:`j` (index into :obj:`x`),
    :obj:`edge_index[1]` the centre :math:`i` (index into :obj:`x`, or into
    :obj:`query`), sorted by centre and then by distance (ties by index).
    On CPU the test is :math:`\|\cdot\|_2^2 \leq r^2` in float64; on CUDA it
    is :func:`torch.cdist` in the input dtype.

    Args:
        x (torch.Tensor): Point coordinates, float32 or float64, any
            dimension :math:`D \geq 1`. May be empty.
        r (float): Radius, finite and positive.
        batch (torch.Tensor, optional): Sorted example index of every point
            of :obj:`x`. (default: :obj:`None`, one example)
        max_num_neighbors (int, optional): Most neighbours per centre (the
            nearest are kept). (default: :obj:`64`)
        loop (bool, optional): If :obj:`True`, a point is its own neighbour
            (graph mode only; the centre is excluded by index, duplicates stay
            neighbours). (default: :obj:`False`)
        query (torch.Tensor, optional): Centres, same dtype, device and
            :math:`D` as :obj:`x`. (default: :obj:`None`)
        query_batch (torch.Tensor, optional): Sorted example index of every
            query point. (default: :obj:`None`, example 0)

    Shapes:
        - **input:** :obj:`x` :math:`(N, D)`, :obj:`batch` :math:`(N)`,
          :obj:`query` :math:`(M, D)`, :obj:`query_batch` :math:`(M)`
        - **output:** :obj:`edge_index` :math:`(2, E)`, int64 on :obj:`x`'s
          device
    """
    x, batch, query, query_batch = _check_inputs(x, batch, query,
                                                 query_batch, min_points=0)
    r = check_positive_float(r, 'r')
    cap = check_positive_int(max_num_neighbors, 'max_num_neighbors')
    loop = bool(loop)
    if x.size(0) == 0 or (query is not None and query.size(0) == 0):
        return _empty_edges(x.device)
    sx, _ = _sizes(x, batch, query, query_batch)
    if _use_dense(x):
        length = sx.numel()
        return _radius_dense(x, r, batch, cap, loop, query, query_batch,
                             length)
    return _radius_tree(x, r, batch, cap, loop, query, query_batch, sx)


def fps(pos: Tensor, ratio: float, batch: Optional[Tensor] = None,
        random_start: bool = True) -> Tensor:
    r"""Farthest point sampling of a batch of point clouds.

    Within every example, takes :math:`m_b = \lceil \text{ratio} \cdot n_b
    \rceil` points greedily: the first at random (or the example's first
    point), then each next one farthest from those already taken,

    .. math::
        p_{s+1} = \underset{i \notin \{p_1, \dots, p_s\}}
        {\operatorname{arg\,max}} \; \min_{t \leq s}
        \| \mathbf{x}_i - \mathbf{x}_{p_t} \|_2^2,

    ties going to the lowest index. Random starts use torch's global RNG, so
    :func:`torch.manual_seed` reproduces them. CPU runs a numba kernel in
    float64, parallel across examples; CUDA a loop over the samples with the
    distance update vectorised over all examples.

    Args:
        pos (torch.Tensor): Point coordinates, float32 or float64, any
            dimension :math:`D \geq 1`.
        ratio (float): Sampling ratio in :math:`(0, 1]`.
        batch (torch.Tensor, optional): Sorted example index of every point.
            (default: :obj:`None`, one example)
        random_start (bool, optional): If :obj:`False`, every example starts
            from its first point. (default: :obj:`True`)

    Shapes:
        - **input:** :obj:`pos` :math:`(N, D)`, :obj:`batch` :math:`(N)`
        - **output:** :obj:`index` :math:`(\sum_b m_b)`, int64 global indices
          into :obj:`pos` on its device, grouped by example in order, each
          example's samples in selection order
    """
    pos = _check_cloud(pos, 'pos', 1)
    batch = check_batch(batch, pos.size(0), pos)
    if isinstance(ratio, bool):
        raise ValueError(f"'ratio' must be a number in (0, 1], got {ratio!r}")
    ratio = check_positive_float(ratio, 'ratio')
    if ratio > 1.0:
        raise ValueError(f"'ratio' must be in (0, 1] (the fraction of points "
                         f"to keep), got {ratio}")
    sizes = batch_sizes(batch, pos.size(0))
    # ceil(ratio * n), robust to 0.1 * 30 = 3.0000000000000004
    counts = torch.ceil(sizes.double() * ratio * (1.0 - 1e-12)).long()
    counts = torch.minimum(counts.clamp(min=1), sizes)
    if random_start:
        starts = torch.rand(sizes.numel(), dtype=torch.float64)
        starts = (starts * sizes).long()
        starts = torch.minimum(starts, (sizes - 1).clamp(min=0))
    else:
        starts = torch.zeros(sizes.numel(), dtype=torch.long)
    if _use_dense(pos):
        return _fps_dense(pos, batch, starts, counts)
    ptr = torch.zeros(sizes.numel() + 1, dtype=torch.long)
    ptr[1:] = sizes.cumsum(0)
    return _fps_numba(pos, ptr, starts, counts)
