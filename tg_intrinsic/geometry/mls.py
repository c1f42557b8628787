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

import torch
from torch import Tensor

from ._checks import (check_batch, check_points, check_positive_float,
                      check_tensor, same_device)

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


def check_edge_index(edge_index, num_nodes: int, ref: Tensor) -> Tensor:
    """Validates an ``edge_index [2, E]`` (long, in range)."""
    edge_index = check_tensor(edge_index, 'edge_index')
    if edge_index.dim() != 2 or edge_index.size(0) != 2:
        raise ValueError(f"'edge_index' must have shape [2, E], got "
                         f"{list(edge_index.shape)}")
    if edge_index.dtype != torch.long:
        raise ValueError(f"'edge_index' must be torch.long, got "
                         f"{edge_index.dtype}")
    same_device(edge_index, 'edge_index', ref)
    if edge_index.numel() > 0 and (int(edge_index.min()) < 0
                                   or int(edge_index.max()) >= num_nodes):
        raise ValueError(f"'edge_index' points outside [0, {num_nodes})")
    return edge_index


def mls_grad_div(pos: Tensor, frame: Tensor, edge_index: Tensor,
                 batch: Optional[Tensor] = None, kernel_width: float = 1.0,
                 regularizer: float = 1e-3, normalized: bool = True
                 ) -> Tuple[Tensor, Tensor]:
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
    h_edge = h[edge_batch]

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

    if normalized:
        row_sums = _scatter_sum(grad_weight.norm(dim=-1), i, n)
        norm = torch.full((num_examples, ), 0.0, dtype=pos.dtype,
                          device=pos.device)
        norm = norm.scatter_reduce(0, batch, row_sums, 'amax')
        scale = norm.clamp_min(torch.finfo(pos.dtype).tiny)[edge_batch]
        grad_weight = grad_weight / scale.unsqueeze(-1)
        div_weight = div_weight / scale.unsqueeze(-1)
    return grad_weight, div_weight
