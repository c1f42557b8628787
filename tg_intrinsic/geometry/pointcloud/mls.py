r"""Gradient and divergence on point clouds by moving least squares (MLS), as
in DeltaConv (Wiersma et al., SIGGRAPH 2022, supplement A).

Operators are stored per edge of the neighbour graph: for an edge
:math:`(j \to i)` (``edge_index[0] = j`` the neighbour, ``edge_index[1] = i``
the centre), ``grad_weight[e]`` is the pair :math:`(G^u_{ij}, G^v_{ij})` such
that

.. math::
    (\nabla f)_i = \sum_{j \in \mathcal{N}(i)} f_j \,
    (G^u_{ij}, G^v_{ij}) \in T_i

in the frame :math:`(e_u, e_v)` of :math:`i`, and ``div_weight[e]`` the pair
:math:`(D^a_{ij}, D^b_{ij})` with
:math:`(\nabla \cdot X)_i = \sum_j D^a_{ij} X^a_j + D^b_{ij} X^b_j` for a
tangent field with coordinates :math:`(X^a_j, X^b_j)` in the frame of
:math:`j`. Because the weights live on the edges, concatenating graphs in a
PyG batch concatenates the operators.
"""
from typing import Optional, Tuple

import numpy as np
import torch
from numba import prange
from torch import Tensor

from ..checks import (check_batch, check_edge_index, check_points,
                      check_positive_float, check_positive_int, check_tensor,
                      same_device)
from ..jit import jit

#: Fewest points of an MLS neighbourhood (the point included): a tangent
#: gradient needs the point and two neighbours off its line; with fewer the
#: weights are all zero.
MIN_MLS_NEIGHBOURS = 3

#: Monomials of the quadratic fit: 1, u, v, u^2, sqrt(2) uv, v^2. The factor
#: sqrt(2) makes the Tikhonov term rotation invariant (the quadratic part is a
#: symmetric matrix Q, and |(q11, sqrt(2) q12, q22)| is its Frobenius norm),
#: so the operators do not depend on the choice of e_u in the tangent plane.
NUM_MONOMIALS = 6
SQRT2 = 2 ** 0.5


def _scatter_sum(src: Tensor, index: Tensor, size: int) -> Tensor:
    out = src.new_zeros((size, ) + tuple(src.shape[1:]))
    return out.index_add_(0, index, src)


def _monomials(u: Tensor, v: Tensor) -> Tensor:
    return torch.stack([torch.ones_like(u), u, v, u * u, SQRT2 * u * v, v * v],
                       -1)


def mls_grad_div(pos: Tensor, frame: Tensor, edge_index: Tensor,
                 batch: Optional[Tensor] = None, kernel_width: float = 1.0,
                 regularizer: float = 1e-3, normalized: bool = True,
                 backend: Optional[str] = None) -> Tuple[Tensor, Tensor]:
    r"""Per-edge weights of the MLS gradient :math:`G` and divergence
    :math:`D` (DeltaConv, supplement A).

    For every centre :math:`i`, the neighbours are projected to the tangent
    plane, :math:`(u_j, v_j) = ((p_j - p_i) \cdot e_u, (p_j - p_i) \cdot
    e_v) / h`, with :math:`h` the mean neighbour distance of the example, and
    a quadratic :math:`c^\top b(u, v)`,
    :math:`b = (1, u, v, u^2, \sqrt{2} uv, v^2)`,
    is fitted by weighted, Tikhonov-regularised least squares:

    .. math::
        c_i = \underbrace{\Big(\sum_j w_{ij} b_j b_j^\top + \lambda P
        \Big)^{-1}}_{A_i^{-1}} \sum_j w_{ij} b_j f_j, \qquad
        w_{ij} \propto \exp\!\Big(-\frac{\|p_j - p_i\|^2}{(\sigma h)^2}
        \Big),

    normalised to :math:`\sum_j w_{ij} = 1`, and
    :math:`P = \operatorname{diag}(0, 1, 1, 1, 1, 1)`: the constant is not
    penalised, so :math:`G \mathbf{1} = 0` exactly. The gradient is the linear
    part, :math:`G_{ij} = (A_i^{-1} w_{ij} b_j)_{u, v} / h`. The divergence
    fits the height :math:`z_j = (p_j - p_i) \cdot n_i / h` with the same
    weights, giving the Monge patch :math:`\Gamma(u, v) = (u, v, z(u, v))`
    with metric :math:`g = I + \nabla z \nabla z^\top`; a vector
    :math:`X_j` in the frame of :math:`j` gets chart coordinates
    :math:`M_{ij} X_j` with

    .. math::
        M_{ij} = g^{-1}(u_j, v_j)
        \begin{pmatrix} \Gamma_u \cdot e_u^j & \Gamma_u \cdot e_v^j \\
        \Gamma_v \cdot e_u^j & \Gamma_v \cdot e_v^j \end{pmatrix},
        \qquad D_{ij} = G_{ij}^\top M_{ij}.

    Coordinates are scaled by :math:`h`, so the operators are invariant to
    the size of the shape and :math:`\lambda` is relative. The
    :math:`\sqrt{2}` makes :math:`\lambda \|c\|^2` invariant to rotations of
    the tangent frame, so :math:`G` rotates exactly with the frames (the
    original's :math:`uv` monomial breaks this at the level of
    :math:`\lambda`). With :obj:`normalized=True`, :math:`G` and :math:`D`
    of every example are divided by the :math:`\ell_\infty` operator norm of
    its :math:`G`, taken with the Euclidean norm on tangent vectors so that it
    does not depend on the frames either: :math:`\max_i \sum_j \|G_{ij}\|_2`.

    Degenerate neighbourhoods (coincident or collinear points) stay finite
    through :math:`\lambda > 0`: their fit falls back towards zero
    derivatives in the directions the points do not span.

    Args:
        pos (torch.Tensor): Point positions.
        frame (torch.Tensor): Tangent frames, rows :math:`(e_u, e_v, n)`.
        edge_index (torch.Tensor): Neighbour graph; ``edge_index[0]`` is the
            neighbour :math:`j`, ``edge_index[1]`` the centre :math:`i`.
            Include self-loops so that :math:`f_i` enters its own fit.
        batch (torch.Tensor, optional): Example of every point.
            (default: :obj:`None`)
        kernel_width (float, optional): :math:`\sigma`, relative to
            :math:`h`. (default: :obj:`1.0`)
        regularizer (float, optional): :math:`\lambda > 0`.
            (default: :obj:`1e-3`)
        normalized (bool, optional): Normalise by the :math:`\ell_\infty`
            norm of :math:`G`. (default: :obj:`True`)
        backend (str, optional): ``'numba'`` (a compiled loop over centres,
            CPU) or ``'torch'`` (vectorised over edges, any device).
            (default: :obj:`None`: numba on CPU, torch elsewhere)

    Returns:
        (grad_weight, div_weight), both :math:`(E, 2)`.

    Shapes:
        - **input:** pos :math:`(N, 3)`, frame :math:`(N, 3, 3)`,
          edge_index :math:`(2, E)`, batch :math:`(N)`
        - **output:** :math:`(E, 2)`, :math:`(E, 2)`
    """
    pos = check_points(pos)
    n = pos.size(0)
    frame = check_tensor(frame, 'frame')
    if frame.shape != (n, 3, 3) or frame.dtype != pos.dtype:
        raise ValueError(f"'frame' must be a {pos.dtype} tensor of shape "
                         f"[{n}, 3, 3] (rows e_u, e_v, normal), got "
                         f"{frame.dtype} {list(frame.shape)}; build it with "
                         f"tangent_frames(normal)")
    same_device(frame, 'frame', pos)
    if not bool(torch.isfinite(frame).all()):
        raise ValueError("'frame' contains NaN or infinite values")
    edge_index = check_edge_index(edge_index, n, pos)
    batch = check_batch(batch, n, pos)
    kernel_width = check_positive_float(kernel_width, 'kernel_width')
    regularizer = check_positive_float(regularizer, 'regularizer')
    j, i = edge_index
    if batch is None:
        batch = torch.zeros(n, dtype=torch.long, device=pos.device)
    num_examples = int(batch.max()) + 1 if n > 0 else 0

    # Local scale h of every example: the mean distance to the neighbours.
    diff = pos[j] - pos[i]
    dist = diff.norm(dim=-1)
    edge_batch = batch[i]
    not_self = (j != i).to(pos.dtype)
    total = _scatter_sum(dist, edge_batch, num_examples)
    count = _scatter_sum(not_self, edge_batch, num_examples)
    if bool((total[count > 0] <= 0).any()):
        raise ValueError("all neighbours of an example coincide with their "
                         "centre, so no local scale exists; remove duplicate "
                         "points")
    h = (total / count.clamp_min(1)).clamp_min(torch.finfo(pos.dtype).tiny)

    if backend is None:
        backend = 'numba' if pos.device.type == 'cpu' else 'torch'
    if backend == 'numba':
        grad_weight, div_weight = _mls_numba(pos, frame, edge_index, h,
                                             batch, kernel_width, regularizer)
    elif backend == 'torch':
        grad_weight, div_weight = _mls_torch(pos, frame, edge_index, h,
                                             batch, kernel_width, regularizer)
    else:
        raise ValueError(f"'backend' must be None, 'numba' or 'torch', got "
                         f"{backend!r}")

    if normalized:
        row_sums = _scatter_sum(grad_weight.norm(dim=-1), i, n)
        norm = torch.full((num_examples, ), 0.0, dtype=pos.dtype,
                          device=pos.device)
        norm = norm.scatter_reduce(0, batch, row_sums, 'amax')
        scale = norm.clamp_min(torch.finfo(pos.dtype).tiny)[batch[i]]
        grad_weight = grad_weight / scale.unsqueeze(-1)
        div_weight = div_weight / scale.unsqueeze(-1)
    return grad_weight, div_weight


def build_mls_operators(pos: Tensor, k: int = 20,
                        batch: Optional[Tensor] = None,
                        normal: Optional[Tensor] = None,
                        frame: Optional[Tensor] = None,
                        kernel_width: float = 1.0, regularizer: float = 1e-3,
                        normalized: bool = True, normal_k: int = 10
                        ) -> Tuple[Tensor, Tensor, Tensor, Tensor]:
    r"""Builds everything DeltaConv needs from positions alone: the k-nn
    graph with self-loops, tangent frames (from :obj:`frame`, else from
    :obj:`normal`, else from PCA normals of :obj:`normal_k` neighbours) and
    the MLS weights of :func:`mls_grad_div`. Runs on the device of
    :obj:`pos`, so a model can rebuild its operators after augmentation.

    With :obj:`normalized=True` (the default, DeltaNet's convention) the
    gradient is divided by the largest absolute row sum of :math:`G`: a
    scale for a network's layers, not the gradient of the field; pass
    :obj:`normalized=False` to measure gradients.

    Returns:
        (edge_index, frame, grad_weight, div_weight) with shapes
        :math:`(2, N k)`, :math:`(N, 3, 3)`, :math:`(N k, 2)`,
        :math:`(N k, 2)`.
    """
    from ..checks import check_frames
    from .frames import estimate_normals, tangent_frames
    from .neighbors import knn

    pos = check_points(pos)
    k = check_positive_int(k, 'k', minimum=MIN_MLS_NEIGHBOURS)
    if frame is not None:
        frame = check_frames(frame, pos.size(0), pos)
    else:
        if normal is None:
            normal = estimate_normals(pos, normal_k, batch)
        else:
            normal = check_points(normal, 'normal')
            if normal.shape != pos.shape:
                raise ValueError(f"'normal' must have shape {list(pos.shape)}"
                                 f", got {list(normal.shape)}")
        frame = tangent_frames(normal.to(pos.dtype))
    # k neighbours including the point itself, which enters its own fit.
    edge_index = knn(pos, k, batch, loop=True)
    grad_weight, div_weight = mls_grad_div(
        pos, frame, edge_index, batch, kernel_width=kernel_width,
        regularizer=regularizer, normalized=normalized)
    return edge_index, frame, grad_weight, div_weight


def _mls_torch(pos, frame, edge_index, h, batch, kernel_width, regularizer):
    """Vectorised over edges; the reference for the numba kernel."""
    n = pos.size(0)
    j, i = edge_index
    h_edge = h[batch[i]]
    diff = pos[j] - pos[i]
    dist = diff.norm(dim=-1)
    e_u, e_v, normal = frame[:, 0], frame[:, 1], frame[:, 2]
    u = (diff * e_u[i]).sum(-1) / h_edge
    v = (diff * e_v[i]).sum(-1) / h_edge
    z = (diff * normal[i]).sum(-1) / h_edge

    weight = torch.exp(-(dist / h_edge) ** 2 / kernel_width ** 2)
    weight = weight / _scatter_sum(weight, i, n)[i]

    basis = _monomials(u, v)  # [E, 6]
    weighted = weight.unsqueeze(-1) * basis
    system = _scatter_sum(
        (weighted.unsqueeze(-1) * basis.unsqueeze(-2)).flatten(1), i, n)
    system = system.view(n, NUM_MONOMIALS, NUM_MONOMIALS)
    # The constant is not penalised, so constants are fitted exactly: G 1 = 0.
    penalty = torch.ones(NUM_MONOMIALS, dtype=pos.dtype, device=pos.device)
    penalty[0] = 0.0
    system = system + regularizer * torch.diag(penalty)
    # fit[e] maps f_j to the coefficients c_i: c_i = sum_e fit[e] f_j.
    fit = torch.linalg.solve(system[i], weighted)  # [E, 6]

    grad_weight = fit[:, 1:3] / h_edge.unsqueeze(-1)

    # Height function of the Monge patch and its slope at (u_j, v_j).
    height = _scatter_sum(fit * z.unsqueeze(-1), i, n)[i]  # [E, 6]
    z_u = height[:, 1] + 2 * height[:, 3] * u + SQRT2 * height[:, 4] * v
    z_v = height[:, 2] + SQRT2 * height[:, 4] * u + 2 * height[:, 5] * v
    gamma_u = e_u[i] + normal[i] * z_u.unsqueeze(-1)
    gamma_v = e_v[i] + normal[i] * z_v.unsqueeze(-1)
    det = 1 + z_u ** 2 + z_v ** 2
    g_inv = torch.stack([1 + z_v ** 2, -z_u * z_v,
                         -z_u * z_v, 1 + z_u ** 2], -1).view(-1, 2, 2)
    g_inv = g_inv / det.view(-1, 1, 1)
    pushed = torch.stack([(gamma_u * e_u[j]).sum(-1),
                          (gamma_u * e_v[j]).sum(-1),
                          (gamma_v * e_u[j]).sum(-1),
                          (gamma_v * e_v[j]).sum(-1)], -1).view(-1, 2, 2)
    to_chart = g_inv @ pushed
    div_weight = (grad_weight.unsqueeze(1) @ to_chart).squeeze(1)
    return grad_weight, div_weight


def _mls_numba(pos, frame, edge_index, h, batch, kernel_width, regularizer):
    """A compiled loop over centres (CPU), parallel across points."""
    j, i = edge_index
    order = None
    if i.numel() > 1 and bool((i[1:] < i[:-1]).any()):
        order = torch.argsort(i, stable=True)
        j, i = j[order], i[order]
    n = pos.size(0)
    ptr = torch.zeros(n + 1, dtype=torch.long)
    ptr[1:] = torch.bincount(i.cpu(), minlength=n).cumsum(0)
    dtype = pos.dtype
    grad_w, div_w = _mls_kernel(
        pos.detach().cpu().double().numpy(),
        frame.detach().cpu().double().numpy(), ptr.numpy(),
        j.cpu().numpy(), h[batch].cpu().double().numpy(),
        float(kernel_width), float(regularizer))
    grad_weight = torch.from_numpy(grad_w).to(dtype)
    div_weight = torch.from_numpy(div_w).to(dtype)
    if order is not None:
        grad_weight = torch.empty_like(grad_weight).index_copy_(
            0, order, grad_weight)
        div_weight = torch.empty_like(div_weight).index_copy_(
            0, order, div_weight)
    return grad_weight, div_weight


@jit(parallel=True, fastmath=False)
def _mls_kernel(pos, frame, ptr, nbr, h_point, kernel_width,
                regularizer):  # pragma: no cover (numba)
    num_edges = nbr.shape[0]
    grad_w = np.zeros((num_edges, 2))
    div_w = np.zeros((num_edges, 2))
    sqrt2 = np.sqrt(2.0)
    for i in prange(pos.shape[0]):
        lo, hi = ptr[i], ptr[i + 1]
        k = hi - lo
        if k == 0:
            continue
        h = h_point[i]
        eu = frame[i, 0]
        ev = frame[i, 1]
        nn = frame[i, 2]
        basis = np.empty((k, 6))
        wgt = np.empty(k)
        z = np.empty(k)
        wsum = 0.0
        for e in range(k):
            jj = nbr[lo + e]
            d0 = pos[jj, 0] - pos[i, 0]
            d1 = pos[jj, 1] - pos[i, 1]
            d2 = pos[jj, 2] - pos[i, 2]
            u = (d0 * eu[0] + d1 * eu[1] + d2 * eu[2]) / h
            v = (d0 * ev[0] + d1 * ev[1] + d2 * ev[2]) / h
            z[e] = (d0 * nn[0] + d1 * nn[1] + d2 * nn[2]) / h
            r2 = (d0 * d0 + d1 * d1 + d2 * d2) / (h * h)
            wgt[e] = np.exp(-r2 / (kernel_width * kernel_width))
            wsum += wgt[e]
            basis[e, 0] = 1.0
            basis[e, 1] = u
            basis[e, 2] = v
            basis[e, 3] = u * u
            basis[e, 4] = sqrt2 * u * v
            basis[e, 5] = v * v
        system = np.zeros((6, 6))
        for e in range(k):
            wgt[e] /= wsum
            for a in range(6):
                wa = wgt[e] * basis[e, a]
                for b in range(a, 6):
                    system[a, b] += wa * basis[e, b]
        for a in range(1, 6):
            system[a, a] += regularizer
        # Cholesky factorisation of the symmetric positive definite system.
        chol = np.zeros((6, 6))
        for a in range(6):
            for b in range(a + 1):
                acc = system[b, a]
                for c in range(b):
                    acc -= chol[a, c] * chol[b, c]
                if a == b:
                    chol[a, a] = np.sqrt(acc)
                else:
                    chol[a, b] = acc / chol[b, b]
        fit = np.empty((k, 6))
        height = np.zeros(6)
        for e in range(k):
            y = np.empty(6)
            for a in range(6):  # forward substitution
                acc = wgt[e] * basis[e, a]
                for c in range(a):
                    acc -= chol[a, c] * y[c]
                y[a] = acc / chol[a, a]
            for a in range(5, -1, -1):  # backward substitution
                acc = y[a]
                for c in range(a + 1, 6):
                    acc -= chol[c, a] * fit[e, c]
                fit[e, a] = acc / chol[a, a]
            for a in range(6):
                height[a] += fit[e, a] * z[e]
        for e in range(k):
            jj = nbr[lo + e]
            u = basis[e, 1]
            v = basis[e, 2]
            gu = fit[e, 1] / h
            gv = fit[e, 2] / h
            zu = height[1] + 2.0 * height[3] * u + sqrt2 * height[4] * v
            zv = height[2] + sqrt2 * height[4] * u + 2.0 * height[5] * v
            ej_u = frame[jj, 0]
            ej_v = frame[jj, 1]
            t00 = 0.0
            t01 = 0.0
            t10 = 0.0
            t11 = 0.0
            for c in range(3):
                gam_u = eu[c] + nn[c] * zu
                gam_v = ev[c] + nn[c] * zv
                t00 += gam_u * ej_u[c]
                t01 += gam_u * ej_v[c]
                t10 += gam_v * ej_u[c]
                t11 += gam_v * ej_v[c]
            det = 1.0 + zu * zu + zv * zv
            i00 = (1.0 + zv * zv) / det
            i01 = -zu * zv / det
            i11 = (1.0 + zu * zu) / det
            m00 = i00 * t00 + i01 * t10
            m01 = i00 * t01 + i01 * t11
            m10 = i01 * t00 + i11 * t10
            m11 = i01 * t01 + i11 * t11
            grad_w[lo + e, 0] = gu
            grad_w[lo + e, 1] = gv
            div_w[lo + e, 0] = gu * m00 + gv * m10
            div_w[lo + e, 1] = gu * m01 + gv * m11
    return grad_w, div_w
