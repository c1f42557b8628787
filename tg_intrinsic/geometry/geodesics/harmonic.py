r"""Circular-harmonic filters on surfaces (Harmonic Surface Networks,
Wiersma et al., SIGGRAPH 2020).

Features are complex and split into rotation-order streams
:math:`M = 0, \dots, P`: when the tangent frame at a point turns by
:math:`-\varphi`, an order-:math:`M` feature there is multiplied by
:math:`e^{iM\varphi}`. A convolution from stream :math:`M` to stream
:math:`M + m` is

.. math::
    x_i^{M+m} = \sum_{j \in \mathcal{N}(i)} w_j\, R(r_{ij})\,
    e^{i(m\theta_{ij} + \beta)}\, e^{iM\phi_{ji}}\, x_j^M .

Everything in it that does not depend on learned parameters is computed
once: :func:`harmonic_terms` gives per edge the ring-by-order terms
:math:`w_j \mu_q(r_{ij}) e^{im\theta_{ij}}` (:math:`\mu_q` the linear
interpolation weights of ring :math:`q`), and :class:`HarmonicOperator`
folds them with the transport :math:`e^{iM\phi_{ji}}` into one sparse
matrix, so that a layer aggregates the neighbourhoods first (memory
:math:`N \times Q \times \text{orders}^2 \times C`) and contracts with its
weights afterwards; per-edge messages of size
:math:`E \times Q \times \text{orders}^2 \times C` never exist.

Edges follow PyG's flow: ``edge_index[0]`` is the neighbour :math:`j`,
``edge_index[1]`` the centre :math:`i`; ``logmap`` :math:`(r_{ij},
\theta_{ij})` is the log map of :math:`p_j` in the frame of :math:`i` and
``transport`` :math:`\phi_{ji}` the angle that parallel transport from
:math:`T_j` to :math:`T_i` adds to a vector's angle.
"""
from typing import Optional

import torch
from torch import Tensor

from ..checks import (check_edge_index, check_float_tensor,
                      check_positive_float, check_positive_int, check_rows,
                      check_tensor, same_device)
# A^H is what complex autograd needs in the backward pass.
from ..precision import at_least_float32
from ..sparse import CSR, sparse_mm


def ring_weights(r: Tensor, radius: float, rings: int) -> Tensor:
    r"""Linear interpolation weights :math:`\mu_q(r)` of :math:`Q` rings at
    radii :math:`q \epsilon / Q`, :math:`q = 0, \dots, Q - 1`; the profile
    falls to zero at :math:`r = \epsilon` (the last ring is 0). Points at
    :math:`r \geq \epsilon` get no weight.

    Shapes:
        - **input:** :math:`(E)`
        - **output:** :math:`(E, Q)`
    """
    t = (r / radius).clamp(min=0) * rings
    low = t.floor()
    frac = t - low
    low = low.long()
    out = r.new_zeros(r.numel(), rings + 1)
    inside = low < rings
    rows = torch.arange(r.numel(), device=r.device)[inside]
    out[rows, low[inside]] = 1 - frac[inside]
    out[rows, low[inside] + 1] = frac[inside]
    return out[:, :rings]


def harmonic_terms(edge_index: Tensor, logmap: Tensor, weight: Tensor,
                   radius: float, rings: int, max_order: int,
                   num_nodes: Optional[int] = None) -> Tensor:
    r"""The precomputed part of every circular-harmonic filter, per edge,
    ring and order :math:`m = 0, \dots, \text{max\_order}`.

    .. math::
        h_{e, q, m} = \frac{w_j}{\sum_{k \in \mathcal{N}(i)} w_k}\,
        \mu_q(r_{ij})\, e^{i m \theta_{ij}}, \qquad e = (j \to i).

    Where :math:`r_{ij} = 0` (the centre itself, or a coincident point) the
    angle is undefined, so every :math:`m \neq 0` term is zero there; a
    nonzero value would depend on the choice of frame and break gauge
    equivariance. Negative orders are the complex conjugates.

    Args:
        edge_index (torch.Tensor): Disc graph (``[0]`` neighbour, ``[1]``
            centre).
        logmap (torch.Tensor): :math:`(r_{ij}, \theta_{ij})` per edge.
        weight (torch.Tensor): Integration weight (area) of every point.
        radius (float): Disc radius :math:`\epsilon`.
        rings (int): Number of rings :math:`Q`.
        max_order (int): Highest order :math:`m`.
        num_nodes (int, optional): Number of points.

    Shapes:
        - **input:** edge_index :math:`(2, E)`, logmap :math:`(E, 2)`,
          weight :math:`(N)`
        - **output:** complex :math:`(E, Q, \text{max\_order} + 1)`
    """
    edge_index = check_tensor(edge_index, 'edge_index')
    logmap = check_tensor(logmap, 'logmap')
    weight = check_tensor(weight, 'weight')
    radius = check_positive_float(radius, 'radius')
    rings = check_positive_int(rings, 'rings')
    max_order = check_positive_int(max_order, 'max_order', minimum=0)
    if logmap.dim() != 2 or logmap.size(1) != 2 \
            or logmap.size(0) != edge_index.size(1):
        raise ValueError(f"'logmap' must have shape [E, 2] = "
                         f"[{edge_index.size(1)}, 2], got "
                         f"{list(logmap.shape)}")
    if not bool(torch.isfinite(logmap).all()) \
            or not bool(torch.isfinite(weight).all()):
        raise ValueError("'logmap' and 'weight' must be finite; recompute "
                         "the log map (LogMap) and the point weights")
    if bool((weight < 0).any()):
        raise ValueError("'weight' must be non-negative (point areas)")
    j, i = edge_index
    n = num_nodes if num_nodes is not None else weight.numel()
    w = weight[j]
    total = torch.zeros(n, dtype=w.dtype, device=w.device).index_add_(0, i, w)
    if bool((total[i] <= 0).any()):
        raise ValueError("some neighbourhoods have zero total weight; every "
                         "disc needs at least one point with positive area")
    w = w / total[i]
    r, theta = logmap[:, 0], logmap[:, 1]
    mu = ring_weights(r, radius, rings)  # [E, Q]
    orders = torch.arange(max_order + 1, device=r.device, dtype=r.dtype)
    phase = torch.polar(torch.ones_like(theta).unsqueeze(1),
                        theta.unsqueeze(1) * orders)  # [E, O]
    phase = torch.where((r == 0).unsqueeze(1) & (orders > 0), 0, phase)
    return (w.unsqueeze(1) * mu).unsqueeze(2) * phase.unsqueeze(1)


def check_harmonic_graph(edge_index: Tensor, harmonic: Tensor,
                         transport: Tensor, orders: int,
                         rings: Optional[int] = None) -> Tensor:
    r"""Checks the per-edge inputs of a harmonic convolution against each
    other, before any of them is indexed: ``harmonic`` complex
    :math:`(E, Q, K)` with :math:`K \geq` ``orders`` (and :math:`Q =`
    ``rings`` when given), ``edge_index`` :math:`(2, E)` and ``transport``
    finite float :math:`(E)` on the device of ``harmonic``. Whether the
    indices of ``edge_index`` lie in range is left to
    :func:`~tg_intrinsic.geometry.checks.check_edge_index`, which knows
    what they index.

    Args:
        edge_index (torch.Tensor): Disc graph.
        harmonic (torch.Tensor): :func:`harmonic_terms`.
        transport (torch.Tensor): :math:`\phi_{ji}` per edge.
        orders (int): Orders the caller reads, :math:`\max(P, O) + 1`.
        rings (int, optional): Rings the caller expects.

    Returns:
        ``harmonic``.
    """
    harmonic = check_tensor(harmonic, 'harmonic')
    edge_index = check_tensor(edge_index, 'edge_index')
    transport = check_tensor(transport, 'transport')
    if not harmonic.is_complex() or harmonic.dim() != 3:
        raise ValueError(f"'harmonic' must be complex [E, rings, orders] "
                         f"(from HarmonicPrecompute), got {harmonic.dtype} "
                         f"of shape {list(harmonic.shape)}")
    e, q_count, k = harmonic.shape
    if k < orders:
        raise ValueError(f"'harmonic' holds orders up to {k - 1} but "
                         f"this layer needs {orders - 1}; precompute with "
                         f"max_order >= {orders - 1}")
    if rings is not None and q_count != rings:
        raise ValueError(f"'harmonic' has {q_count} rings but this layer has "
                         f"{rings}; precompute with rings={rings}")
    if tuple(edge_index.shape) != (2, e):
        raise ValueError(f"'edge_index' must be [2, E] with E = {e} (the "
                         f"rows of 'harmonic'), got {list(edge_index.shape)}")
    if tuple(transport.shape) != (e, ):
        raise ValueError(f"'transport' must be [E] with E = {e} (the rows "
                         f"of 'harmonic'), got {list(transport.shape)}")
    check_float_tensor(transport, 'transport', (e, ))
    same_device(transport, 'transport', harmonic, 'harmonic')
    return harmonic


class HarmonicOperator:
    r"""The neighbourhood aggregation of a harmonic convolution as one
    sparse complex matrix, built once per (batched) disc graph and shared
    by every layer on it.

    For input orders :math:`M = 0..P` and output orders
    :math:`M' = 0..O` it computes

    .. math::
        y_{i, q, M, M'} = \sum_{j} h_{(j \to i), q, M' - M}\,
        e^{iM\phi_{ji}}\, x_j^M ,

    the aggregated neighbourhood that the layer's radial profiles and
    phase offsets are contracted with. Only the two rings that interpolate
    each :math:`r_{ij}` are stored, so the matrix holds
    :math:`2E(P + 1)(O + 1)` entries whatever :math:`Q`.

    Args:
        edge_index (torch.Tensor): Disc graph (``[0]`` neighbour, ``[1]``
            centre).
        harmonic (torch.Tensor): :func:`harmonic_terms`, complex
            :math:`(E, Q, K)` with :math:`K > \max(P, O)`.
        transport (torch.Tensor): :math:`\phi_{ji}` per edge :math:`(E)`.
        num_nodes (int): Number of points :math:`N`.
        in_orders (int): :math:`P + 1`.
        out_orders (int): :math:`O + 1`.
        layout (tuple, optional): :func:`harmonic_layout` of the same
            graph, shared by the operators of one level.
    """
    def __init__(self, edge_index: Tensor, harmonic: Tensor,
                 transport: Tensor, num_nodes: int, in_orders: int,
                 out_orders: int, layout: Optional[tuple] = None):
        check_harmonic_graph(edge_index, harmonic, transport,
                             max(in_orders, out_orders))
        q_count = harmonic.size(1)
        # the graph it was built on, for layers that must send per-edge
        # messages instead (edge masks, explainers, propagate hooks)
        self.graph = (edge_index, harmonic, transport)
        self.num_nodes = n = num_nodes
        self.rings, self.in_orders, self.out_orders = q_count, in_orders, \
            out_orders
        if layout is None:
            layout = harmonic_layout(edge_index, harmonic, n)
        edge, ring, src, bucket, rank, count, rank_j, count_j = layout
        transport = at_least_float32(transport)  # complex maths in float32
        src_order = torch.arange(in_orders, device=src.device)
        dst_order = torch.arange(out_orders, device=src.device)
        m = dst_order.view(1, -1) - src_order.view(-1, 1)  # [P+1, O+1]
        h = harmonic[edge, ring][:, m.abs()]  # [K, P+1, O+1]
        h = torch.where(m < 0, h.conj(), h)
        spin = torch.polar(torch.ones_like(transport[edge]).unsqueeze(1),
                           transport[edge].unsqueeze(1) * src_order)
        values = h * spin.unsqueeze(2)  # [K, P+1, O+1]
        # Row (i, q, M, M'), column (j, M). The CSR layout is assembled from
        # ranks of the base entries (edge, ring) within their row group, so
        # only 2E keys are sorted, not the 2E (P+1)(O+1) matrix entries.
        p, o = in_orders, out_orders
        crow = _crow(count.repeat_interleave(p * o))
        m_in, m_out = src_order.view(1, -1, 1), dst_order.view(1, 1, -1)
        row = bucket.view(-1, 1, 1) * (p * o) + m_in * o + m_out
        col = (src.view(-1, 1, 1) * p + m_in).expand_as(row)
        slot = crow[row] + rank.view(-1, 1, 1)
        shape = (n * q_count * p * o, n * p)
        self.matrix = CSR.of(_scatter_csr(crow, slot, col, values, shape))
        # A^H: row (j, M) holds the entries of source j for every M'.
        crow_t = _crow((count_j * o).repeat_interleave(p))
        slot_t = crow_t[src.view(-1, 1, 1) * p + m_in] \
            + rank_j.view(-1, 1, 1) * o + m_out
        self.adjoint = CSR.of(_scatter_csr(crow_t, slot_t, row,
                                           values.conj(), shape[::-1]))

    def aggregate(self, x: Tensor) -> Tensor:
        r"""``[N, P + 1, C]`` complex -> ``[N, Q, P + 1, O + 1, C]``."""
        check_rows(x, 'x', self.num_nodes, 'the operator')
        c = x.size(-1)
        flat = x.reshape(self.num_nodes * self.in_orders, c)
        out = sparse_mm(self.matrix, self.adjoint, flat)
        return out.view(self.num_nodes, self.rings, self.in_orders,
                        self.out_orders, c)


def harmonic_layout(edge_index: Tensor, harmonic: Tensor, num_nodes: int
                    ) -> tuple:
    """The sparsity layout of :class:`HarmonicOperator`, which does not
    depend on the orders: the (edge, ring) pairs with weight (at most two
    per edge), their row group (centre, ring) and source, and the rank of
    every pair within both."""
    # Out-of-range nodes would give CSR columns past the end of x.
    j, i = check_edge_index(edge_index, num_nodes, harmonic,
                            ref_name='harmonic')
    edge, ring = (harmonic[:, :, 0] != 0).nonzero(as_tuple=True)
    src, bucket = j[edge], i[edge] * harmonic.size(1) + ring
    rank, count = _ranks(bucket, num_nodes * harmonic.size(1))
    rank_j, count_j = _ranks(src, num_nodes)
    return edge, ring, src, bucket, rank, count, rank_j, count_j


def _ranks(group: Tensor, num_groups: int):
    """Position of every entry within its group (stable) and the group
    sizes."""
    count = torch.bincount(group, minlength=num_groups)
    order = torch.argsort(group, stable=True)
    start = torch.cumsum(count, 0) - count
    rank = torch.empty_like(group)
    rank[order] = torch.arange(group.numel(), device=group.device) \
        - start[group[order]]
    return rank, count


def _crow(count: Tensor) -> Tensor:
    crow = torch.zeros(count.numel() + 1, dtype=torch.long,
                       device=count.device)
    crow[1:] = torch.cumsum(count, 0)
    return crow


def _scatter_csr(crow: Tensor, slot: Tensor, col: Tensor, value: Tensor,
                 shape) -> Tensor:
    cols = torch.empty(int(crow[-1]), dtype=torch.long, device=crow.device)
    values = torch.empty(int(crow[-1]), dtype=value.dtype,
                         device=crow.device)
    cols[slot.reshape(-1)] = col.reshape(-1)
    values[slot.reshape(-1)] = value.reshape(-1)
    return torch.sparse_csr_tensor(crow, cols, values, shape,
                                   check_invariants=False)


def transport_features(x: Tensor, angle: Tensor) -> Tensor:
    r"""Parallel transport of complex stream features by an angle per row:
    order :math:`M` is multiplied by :math:`e^{iM\phi}`.

    Shapes:
        - **input:** x :math:`(N, P + 1, C)` complex, angle :math:`(N)`
        - **output:** :math:`(N, P + 1, C)`
    """
    angle = at_least_float32(angle)  # complex maths in float32
    orders = torch.arange(x.size(1), device=x.device, dtype=angle.dtype)
    spin = torch.polar(torch.ones_like(angle).unsqueeze(1),
                       angle.unsqueeze(1) * orders)
    return x * spin.unsqueeze(2)


__all__ = ['ring_weights', 'harmonic_terms', 'check_harmonic_graph',
           'harmonic_layout', 'HarmonicOperator', 'transport_features']
