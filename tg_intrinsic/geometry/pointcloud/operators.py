r"""Vector calculus on point clouds from per-edge gradient and divergence
weights (see :mod:`tg_intrinsic.geometry.pointcloud.mls`).

Scalar fields are ``[N, C]``; tangent vector fields are ``[N, C, 2]``, the
coordinates of every vector in its point's own frame :math:`(e_u, e_v)`.
Edges follow PyG's flow: ``edge_index[0]`` is the neighbour :math:`j`,
``edge_index[1]`` the centre :math:`i`.

Two interchangeable back ends apply the operators:

* :class:`SurfaceOperators` assembles :math:`G` and :math:`D` once as sparse
  CSR matrices and applies them with :func:`torch.sparse.mm` (the fast path,
  used by the layers);
* the functions :func:`grad`, :func:`div`, ... gather and scatter along the
  edges directly (the reference the tests compare against).

With :math:`J` the rotation by 90 degrees in every tangent plane, the
derived operators are

.. math::
    \operatorname{curl} = -D J, \qquad \Delta = -D G, \qquad
    \Delta_H = -(G D - J G D J).
"""
import warnings
from typing import Optional

import numpy as np
import torch
from numba import prange
from torch import Tensor

from ..checks import (check_edge_index, check_float_tensor,
                      check_positive_int, check_rows, same_device)
from ..jit import jit
from ..precision import LOW_PRECISION, full_precision
from ..sparse import CSR, sparse_mm

# CSR matrix products are stable for what is used here (mm with a dense
# matrix, and its backward); the generic "beta" notice is noise for users.
warnings.filterwarnings('ignore', message='Sparse CSR tensor support is in '
                        'beta state')


def planar(v: Tensor) -> Tensor:
    """A ``[2, N, C]`` view of a ``[N, C, 2]`` vector field (no copy)."""
    return v.permute(2, 0, 1)


def interleaved(v: Tensor) -> Tensor:
    """The ``[N, C, 2]`` view of a ``[2, N, C]`` vector field (no copy).

    Vector features are ``[N, C, 2]`` in every public signature; inside the
    layers they are stored as two contiguous planes ``[2, N, C]`` and handed
    around as this view, so that linear maps, concatenation and
    elementwise work run on contiguous memory instead of pairs.
    """
    return v.permute(1, 2, 0)


def rotate_j(v: Tensor) -> Tensor:
    r"""Rotates every tangent vector by +90 degrees,
    :math:`J (a, b) = (-b, a)`.

    Shapes:
        - **input / output:** :math:`(N, C, 2)`
    """
    p = planar(v)
    return interleaved(torch.stack([-p[1], p[0]]))


def cat_vectors(vectors) -> Tensor:
    """Concatenates ``[N, C_k, 2]`` vector fields along the channels."""
    return interleaved(torch.cat([planar(v) for v in vectors], dim=-1))


def vector_norm(v: Tensor, eps: float = 1e-8) -> Tensor:
    r"""Length of every tangent vector, :math:`\sqrt{a^2 + b^2 +
    \epsilon^2}`, smooth at zero.

    Shapes:
        - **input:** :math:`(N, C, 2)`
        - **output:** :math:`(N, C)`
    """
    p = planar(v)
    return (p[0].square() + p[1].square() + eps ** 2).sqrt()


def grad(x: Tensor, edge_index: Tensor, grad_weight: Tensor) -> Tensor:
    r"""Gradient :math:`(G x)_i = \sum_j x_j \, G_{ij}` by scatter.

    Shapes:
        - **input:** x :math:`(N, C)`, edge_index :math:`(2, E)`,
          grad_weight :math:`(E, 2)`
        - **output:** :math:`(N, C, 2)`
    """
    j, i = edge_index
    msg = x[j].unsqueeze(-1) * grad_weight.unsqueeze(1)
    out = x.new_zeros(x.size(0), x.size(1), 2)
    return out.index_add_(0, i, msg)


def div(v: Tensor, edge_index: Tensor, div_weight: Tensor) -> Tensor:
    r"""Divergence :math:`(D v)_i = \sum_j D_{ij} \cdot v_j` by scatter.

    Shapes:
        - **input:** v :math:`(N, C, 2)`, edge_index :math:`(2, E)`,
          div_weight :math:`(E, 2)`
        - **output:** :math:`(N, C)`
    """
    j, i = edge_index
    msg = (v[j] * div_weight.unsqueeze(1)).sum(-1)
    out = v.new_zeros(v.size(0), v.size(1))
    return out.index_add_(0, i, msg)


def curl(v: Tensor, edge_index: Tensor, div_weight: Tensor) -> Tensor:
    r"""Curl :math:`-D J v` (scalar, :math:`(N, C)`)."""
    return -div(rotate_j(v), edge_index, div_weight)


def laplacian(x: Tensor, edge_index: Tensor, grad_weight: Tensor,
              div_weight: Tensor) -> Tensor:
    r"""Laplace-Beltrami :math:`-D G x` (positive semi-definite sign)."""
    return -div(grad(x, edge_index, grad_weight), edge_index, div_weight)


def hodge_laplacian(v: Tensor, edge_index: Tensor, grad_weight: Tensor,
                    div_weight: Tensor) -> Tensor:
    r"""Hodge Laplacian :math:`-(G D - J G D J) v` on tangent fields."""
    gd = grad(div(v, edge_index, div_weight), edge_index, grad_weight)
    jgdj = rotate_j(grad(div(rotate_j(v), edge_index, div_weight),
                         edge_index, grad_weight))
    return -(gd - jgdj)


#: The reductions :meth:`SurfaceOperators.neighbor_reduce` computes without
#: per-edge messages (PyG's names; ``'add'`` is ``'sum'``).
FAST_REDUCTIONS = ('max', 'min', 'sum', 'mean')


class VectorCalculus:
    r"""The operators derived from a gradient :math:`G` and a divergence
    :math:`D`: :math:`\operatorname{curl} = -DJ`, :math:`\Delta = -DG`
    and :math:`\Delta_H = -(GD - JGDJ)`. A subclass defines :meth:`grad`
    (``[N, C]`` -> ``[N, C, 2]``) and :meth:`div` (``[N, C, 2]`` ->
    ``[N, C]``)."""
    def grad(self, x: Tensor) -> Tensor:  # pragma: no cover (abstract)
        raise NotImplementedError

    def div(self, v: Tensor) -> Tensor:  # pragma: no cover (abstract)
        raise NotImplementedError

    def curl(self, v: Tensor) -> Tensor:
        """:math:`-D J v`: ``[N, C, 2]`` -> ``[N, C]``."""
        return -self.div(rotate_j(v))

    def laplacian(self, x: Tensor) -> Tensor:
        """:math:`-D G x`: ``[N, C]`` -> ``[N, C]``."""
        return -self.div(self.grad(x))

    def hodge_laplacian(self, v: Tensor) -> Tensor:
        """:math:`-(G D - J G D J) v`: ``[N, C, 2]`` -> ``[N, C, 2]``."""
        # Both terms share G: stack D v and D J v along channels.
        c = v.size(1)
        both = self.grad(self.div(cat_vectors([v, rotate_j(v)])))
        return rotate_j(both[:, c:]) - both[:, :c]


class SurfaceOperators(VectorCalculus):
    r"""Gradient and divergence of a (batched) point cloud as sparse CSR
    matrices, built once and shared by every layer of a network.

    :math:`G` is stored as the block matrix :math:`[G_u; G_v]` of shape
    :math:`(2N, N)` and :math:`D` as :math:`[D_a, D_b]` of shape
    :math:`(N, 2N)`, together with their transposes for the backward pass;
    all four are assembled without sorting from edges grouped by centre.
    Vector fields are converted from and to ``[N, C, 2]`` at the boundary.
    The neighbour graph is kept too: when every centre has the same number
    :math:`k` of neighbours (a k-nn graph), :meth:`neighbor_reduce` is a
    dense reduction over a :math:`(N, k, C)` view.

    Half and bfloat16 features (``torch.autocast``, ``model.half()``) are
    multiplied in float32 and returned in their own dtype. The sparse
    products and the CPU's neighbour maximum are custom operators, which
    ``torch.compile`` calls as they are.

    Args:
        edge_index (torch.Tensor): Graph the weights live on
            (``edge_index[0]`` neighbour :math:`j`, ``edge_index[1]`` centre
            :math:`i`).
        grad_weight (torch.Tensor): :math:`(E, 2)` gradient weights.
        div_weight (torch.Tensor): :math:`(E, 2)` divergence weights.
        num_nodes (int): Number of points :math:`N`.
    """
    def __init__(self, edge_index: Tensor, grad_weight: Tensor,
                 div_weight: Tensor, num_nodes: int):
        # The CSR matrices are assembled unchecked and the numba sweeps do
        # not bound-check: bad indices must fail here, not as garbage.
        n = check_positive_int(num_nodes, 'num_nodes', minimum=0)
        edge_index = check_edge_index(edge_index, n, edge_index,
                                      f'points (num_nodes={n})')
        e = edge_index.size(1)
        for name, weight in (('grad_weight', grad_weight),
                             ('div_weight', div_weight)):
            check_float_tensor(weight, name, (e, 2))
            same_device(weight, name, edge_index, 'edge_index')
        # As given, for identity checks and for per-edge messages.
        self.source_edge_index = edge_index
        self.source_weights = (grad_weight, div_weight)
        j, i = edge_index
        if i.numel() > 1 and bool((i[1:] < i[:-1]).any()):
            order = torch.argsort(i, stable=True)
            j, i = j[order], i[order]
            grad_weight, div_weight = grad_weight[order], div_weight[order]
        self.edge_index = torch.stack([j, i])
        self.num_nodes = n
        count = torch.bincount(i, minlength=n)
        self.crow = _crow(count)
        self.in_degree = count
        self.k = int(count[0]) if n > 0 and bool((count == count[0]).all()) \
            else None
        self.G = CSR.of(_block_rows(i, j, grad_weight, count, n))
        self.D = CSR.of(_block_cols(i, j, div_weight, count, n))
        by_j = torch.argsort(j, stable=True)
        count_j = torch.bincount(j, minlength=n)
        self.G_t = CSR.of(_block_cols(j[by_j], i[by_j], grad_weight[by_j],
                                      count_j, n))
        self.out_degree = count_j
        self.D_t = CSR.of(_block_rows(j[by_j], i[by_j], div_weight[by_j],
                                      count_j, n))
        # the adjacency (j -> i) and its transpose, for neighbor_sum
        ones = torch.ones_like(j, dtype=grad_weight.dtype)
        self.A = CSR(self.crow, j, ones)
        self.A_t = CSR(_crow(count_j), i[by_j], ones)

    def weights_on(self, edge_index: Tensor):
        """``(grad_weight, div_weight)`` in the order of ``edge_index``,
        which must be the graph the operators were built on (the same
        tensor, or an equal one); per-edge messages read them."""
        source = self.source_edge_index
        if edge_index is not source and not torch.equal(edge_index, source):
            raise ValueError(
                "per-edge messages (an edge mask, an explainer or a "
                "propagate hook) need 'edge_index' to be the graph the "
                "operators were built on, edge for edge; pass the same "
                "edge_index that built them")
        return self.source_weights

    def grad(self, x: Tensor) -> Tensor:
        """:math:`G x`: ``[N, C]`` -> ``[N, C, 2]``."""
        check_rows(x, 'x', self.num_nodes, 'the operators')
        out = self._product(self.G, self.G_t, x)  # [2N, C]
        return interleaved(out.view(2, self.num_nodes, -1))

    def div(self, v: Tensor) -> Tensor:
        """:math:`D v`: ``[N, C, 2]`` -> ``[N, C]``."""
        check_rows(v, 'v', self.num_nodes, 'the operators')
        flat = planar(v).reshape(2 * self.num_nodes, -1)
        return self._product(self.D, self.D_t, flat)

    @staticmethod
    def _product(matrix: CSR, transposed: CSR, x: Tensor) -> Tensor:
        # Sparse kernels exist for float32/64 only; autocast must not
        # lower them either.
        dtype = x.dtype
        with full_precision(x.device.type):
            if dtype in LOW_PRECISION:
                x = x.float()
            out = sparse_mm(matrix.cast(x.dtype), transposed.cast(x.dtype), x)
        return out.to(dtype)

    def neighbor_reduce(self, x: Tensor, reduce: str = 'max') -> Tensor:
        r"""Per centre, :math:`\bigoplus_{j \in \mathcal{N}(i)} x_j` for
        ``reduce`` in :data:`FAST_REDUCTIONS` (0 where a point has no
        neighbour, as PyG's aggregations)."""
        if reduce == 'max':
            return self.neighbor_max(x)
        if reduce == 'min':
            return -self.neighbor_max(-x)
        total = self.neighbor_sum(x)
        if reduce == 'sum':
            return total
        if reduce == 'mean':
            return total / self.in_degree.clamp(min=1).to(total.dtype)[:, None]
        raise ValueError(f"reduce must be one of {FAST_REDUCTIONS}, got "
                         f"{reduce!r}")

    def neighbor_max(self, x: Tensor, backend: Optional[str] = None
                     ) -> Tensor:
        r""":math:`\max_{j \in \mathcal{N}(i)} x_j` over the graph (0 where a
        point has no neighbour). The winning neighbour of every channel is
        found without autograd and then gathered, so the backward pass is a
        scatter of :math:`(N, C)` values instead of an :math:`(E, C)` mask.
        ``backend``: ``'numba'`` (CPU) or ``'torch'``; default: numba on CPU
        (torch when traced by ``torch.compile``).
        """
        check_rows(x, 'x', self.num_nodes, 'the operators')
        j, i = self.edge_index
        c = x.size(1)
        if j.numel() == 0:
            return x.new_zeros(self.num_nodes, c) + 0 * x.sum()
        if backend is None:
            backend = 'numba' if x.device.type == 'cpu' else 'torch'
        empty = None
        with torch.no_grad():
            if backend == 'numba':
                # numpy has no bfloat16; the winner is found in float32
                values = x.detach()
                if values.dtype in LOW_PRECISION:
                    values = values.float()
                winner = neighbor_argmax(values, self.crow, j)
                empty = winner < 0
                winner = winner.clamp(min=0)
            elif self.k is not None:
                slot = x[j].view(self.num_nodes, self.k, c).argmax(dim=1)
                winner = j.view(self.num_nodes, self.k).gather(1, slot)
            else:
                best = x.new_full((self.num_nodes, c), float('-inf'))
                best = best.scatter_reduce(0, i[:, None].expand(-1, c), x[j],
                                           'amax')
                # The first edge (lowest position) that attains the maximum.
                hit = x[j] == best[i]
                pos = torch.arange(j.numel(), device=j.device)[:, None]
                pos = torch.where(hit, pos, j.numel())
                first = torch.full((self.num_nodes, c), j.numel(),
                                   device=j.device, dtype=torch.long)
                first = first.scatter_reduce(0, i[:, None].expand(-1, c), pos,
                                             'amin')
                empty = first == j.numel()
                winner = j[first.clamp(max=max(j.numel() - 1, 0))]
        out = x.gather(0, winner)
        if empty is not None:  # no data-dependent branch: compiles
            out = out.masked_fill(empty, 0.0)
        return out

    def neighbor_sum(self, x: Tensor) -> Tensor:
        r""":math:`\sum_{j \in \mathcal{N}(i)} x_j` over the graph."""
        check_rows(x, 'x', self.num_nodes, 'the operators')
        return self._product(self.A, self.A_t, x)

    def edge_reduce(self, values: Tensor, reduce: str = 'max') -> Tensor:
        r"""Per centre, the ``reduce`` (:data:`FAST_REDUCTIONS`) of per-edge
        values given in the order of :attr:`edge_index` (0 where a point
        has no edge)."""
        if reduce not in FAST_REDUCTIONS:
            raise ValueError(f"reduce must be one of {FAST_REDUCTIONS}, got "
                             f"{reduce!r}")
        if self.k is not None:
            dense = values.view(self.num_nodes, self.k, -1)
            return {'max': dense.amax, 'min': dense.amin, 'sum': dense.sum,
                    'mean': dense.mean}[reduce](dim=1)
        i = self.edge_index[1]
        out = values.new_zeros(self.num_nodes, values.size(1))
        if reduce in ('sum', 'mean'):
            out = out.index_add(0, i, values)
            if reduce == 'mean':
                out = out / self.in_degree.clamp(min=1).to(out.dtype)[:, None]
            return out
        return out.scatter_reduce(0, i[:, None].expand_as(values), values,
                                  'a' + reduce, include_self=False)

    def edge_max(self, values: Tensor) -> Tensor:
        r"""Per centre, the maximum of per-edge values given in the order of
        :attr:`edge_index` (0 where a point has no edge)."""
        return self.edge_reduce(values, 'max')

    def to(self, device) -> 'SurfaceOperators':
        for name in ('G', 'D', 'G_t', 'D_t', 'A', 'A_t'):
            setattr(self, name, getattr(self, name).on(device))
        for name in ('edge_index', 'crow', 'out_degree', 'in_degree',
                     'source_edge_index'):
            setattr(self, name, getattr(self, name).to(device))
        self.source_weights = tuple(w.to(device)
                                    for w in self.source_weights)
        return self

    def __repr__(self) -> str:
        return (f'{self.__class__.__name__}(num_nodes={self.num_nodes}, '
                f'num_edges={self.edge_index.size(1)}, k={self.k})')


def _crow(count: Tensor) -> Tensor:
    crow = torch.zeros(count.numel() + 1, dtype=torch.long,
                       device=count.device)
    crow[1:] = count.cumsum(0)
    return crow


def _block_rows(row: Tensor, col: Tensor, value: Tensor, count: Tensor,
                n: int) -> Tensor:
    """CSR of ``[A_0; A_1]`` (2n x n), ``A_c[row, col] = value[:, c]``, from
    entries sorted by row."""
    crow = _crow(count)
    e = row.numel()
    return torch.sparse_csr_tensor(
        torch.cat([crow, crow[1:] + e]), torch.cat([col, col]),
        torch.cat([value[:, 0], value[:, 1]]), (2 * n, n),
        check_invariants=False)


def _block_cols(row: Tensor, col: Tensor, value: Tensor, count: Tensor,
                n: int) -> Tensor:
    """CSR of ``[A_0, A_1]`` (n x 2n), ``A_c[row, col] = value[:, c]``, from
    entries sorted by row."""
    crow = _crow(count)
    slot = torch.arange(row.numel(), device=row.device) - crow[row]
    first = 2 * crow[row] + slot  # row r: its A_0 entries, then its A_1
    second = first + count[row]
    cols = torch.empty(2 * row.numel(), dtype=torch.long, device=row.device)
    values = torch.empty(2 * row.numel(), dtype=value.dtype,
                         device=row.device)
    cols[first], cols[second] = col, col + n
    values[first], values[second] = value[:, 0], value[:, 1]
    return torch.sparse_csr_tensor(2 * crow, cols, values, (n, 2 * n),
                                   check_invariants=False)


@torch.library.custom_op('tg_intrinsic::neighbor_argmax', mutates_args=())
def neighbor_argmax(x: Tensor, crow: Tensor, neighbor: Tensor) -> Tensor:
    """Per point and channel of ``x`` (CPU), the neighbour holding the
    maximum over the CSR graph ``crow``/``neighbor`` (the first on ties),
    -1 for points without neighbours: a numba sweep, as a custom operator
    that ``torch.compile`` calls as it is."""
    return torch.from_numpy(_neighbor_argmax(
        x.contiguous().numpy(), crow.numpy(), neighbor.numpy()))


@neighbor_argmax.register_fake
def _(x, crow, neighbor):
    return x.new_empty(crow.size(0) - 1, x.size(1), dtype=torch.long)


@jit(parallel=True)
def _neighbor_argmax(x, crow, nbr):  # pragma: no cover (numba)
    """Per point and channel, the neighbour holding the maximum (the first
    one on ties); -1 for points without neighbours."""
    n, c = crow.shape[0] - 1, x.shape[1]
    winner = np.full((n, c), -1, dtype=np.int64)
    best = np.empty((n, c), dtype=x.dtype)  # one buffer, no per-point copy
    for i in prange(n):
        lo, hi = crow[i], crow[i + 1]
        if hi == lo:
            continue
        first = nbr[lo]
        top = best[i]
        win = winner[i]
        for ch in range(c):
            top[ch] = x[first, ch]
            win[ch] = first
        for e in range(lo + 1, hi):
            j = nbr[e]
            row = x[j]
            for ch in range(c):  # branch-free, so that it vectorises
                better = row[ch] > top[ch]
                top[ch] = row[ch] if better else top[ch]
                win[ch] = j if better else win[ch]
    return winner
