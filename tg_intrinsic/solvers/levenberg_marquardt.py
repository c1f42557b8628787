r"""Batched Levenberg-Marquardt for many small problems, such as one SVBRDF
per surface point: independent rows, each with its own residuals, damping
and acceptance, solved at once as ``[N, P, P]`` systems
(:func:`levenberg_marquardt`); or rows coupled by a total variation over a
graph, solved together (:func:`levenberg_marquardt_tv`)."""
import math
from dataclasses import dataclass, field
from typing import Callable, List, Optional

import torch
import torch.autograd.forward_ad as forward_ad
from torch import Tensor

from tg_intrinsic.geometry.checks import (check_choice, check_float_tensor,
                                          check_positive_float,
                                          check_positive_int)

LOSSES = ('l2', 'l1')


@dataclass
class LMInfo:
    """What a :func:`levenberg_marquardt` run did: iterations, the mean
    objective over the rows before and after each iteration, how many rows
    were still moving (``active``) after each, and whether all rows
    stopped before ``max_iter``."""
    iterations: int = 0
    objective: List[float] = field(default_factory=list)
    active: List[int] = field(default_factory=list)
    converged: bool = False


def levenberg_marquardt(residual: Callable[[Tensor], Tensor], x0: Tensor,
                        weight: Optional[Tensor] = None,
                        lower: Optional[Tensor] = None,
                        upper: Optional[Tensor] = None, loss: str = 'l2',
                        max_iter: int = 30, tol: float = 1e-6,
                        damping: float = 1e-3, l1_epsilon: float = 1e-3,
                        jacobian: Optional[Callable] = None,
                        max_step: Optional[float] = None) -> tuple:
    r"""Minimises a weighted sum of losses of residuals within bounds, for
    every row :math:`n` independently. The objective of row :math:`n` is

    .. math::
        E_n(x_n) = \sum_k w_{nk}\, \rho(r_{nk}(x_n)), \qquad
        \text{lower}_n \le x_n \le \text{upper}_n,

    with :math:`\rho(r) = r^2` (:obj:`loss='l2'`) or :math:`|r|`
    (:obj:`loss='l1'`, by iteratively reweighted least squares with
    weights :math:`1 / \max(|r|, \epsilon)`). Each iteration solves the
    damped normal equations of every row,

    .. math::
        (J^\top W J + \lambda \operatorname{diag}(J^\top W J))\, \delta =
        -J^\top W r,

    with the parameters that sit on a bound and would leave it held there,
    projects :math:`x + \delta` onto the bounds and keeps it only where the
    objective decreased; :math:`\lambda` shrinks on success and grows on
    failure, per row. Rows that stopped are not evaluated again. The
    Jacobian comes from forward-mode automatic differentiation, in one
    evaluation of :obj:`residual` on :math:`P` stacked copies of the rows,
    so :obj:`residual` must be built from differentiable torch
    operations, unless :obj:`jacobian` computes it.

    Args:
        residual (callable): ``residual(x, rows)`` maps the parameters
            :math:`(n, P)` of the rows ``rows`` (a ``torch.long`` index
            :math:`(n)` into :math:`0, \dots, N - 1`) to their residuals
            :math:`(n, R)`; row :math:`i` of the output may depend on row
            :math:`i` of ``x`` only.
        x0 (torch.Tensor): Start :math:`(N, P)`, inside the bounds.
        weight (torch.Tensor, optional): Non-negative weights
            :math:`(N, R)`. (default: :obj:`None`, all 1)
        lower, upper (torch.Tensor, optional): Bounds :math:`(P)` or
            :math:`(N, P)`. (default: :obj:`None`, unbounded)
        loss (str, optional): :obj:`'l2'` or :obj:`'l1'`.
            (default: :obj:`'l2'`)
        max_iter (int, optional): Iterations. (default: :obj:`30`)
        tol (float, optional): A row stops once an accepted step lowers its
            objective by less than :obj:`tol` times its value, or its
            damping has grown past :math:`10^{8}` (no step helps).
            (default: :obj:`1e-6`)
        damping (float, optional): Initial :math:`\lambda`.
            (default: :obj:`1e-3`)
        l1_epsilon (float, optional): :math:`\epsilon` of the L1 weights,
            in the units of the residuals; below it the loss is quadratic,
            as Huber's. (default: :obj:`1e-3`)
        max_step (float, optional): Longest step of any one parameter in
            one iteration (a trust region in parameter units, which keeps
            a fit near its start where the objective has several minima).
            (default: :obj:`None`)
        jacobian (callable, optional): ``jacobian(x, rows)`` returns the
            residuals and their Jacobian :math:`(n, R, P)` of those rows,
            e.g. analytic; forward-mode differentiation of
            :obj:`residual` otherwise. (default: :obj:`None`)

    Returns:
        ``(x, info)``: the parameters :math:`(N, P)` and an
        :class:`LMInfo`.
    """
    x = check_float_tensor(x0, 'x0', x0.shape).detach().clone()
    if x.dim() != 2:
        raise ValueError(f"'x0' must be [N, P] (one row per problem), got "
                         f"{list(x.shape)}")
    loss = check_choice(loss, 'loss', LOSSES)
    max_iter = check_positive_int(max_iter, 'max_iter', minimum=0)
    tol = check_positive_float(tol, 'tol', allow_zero=True)
    damping = check_positive_float(damping, 'damping')
    l1_epsilon = check_positive_float(l1_epsilon, 'l1_epsilon')
    if max_step is not None:
        max_step = check_positive_float(max_step, 'max_step')
    num, num_params = x.shape
    lower = _bound(lower, 'lower', x, -float('inf'))
    upper = _bound(upper, 'upper', x, float('inf'))
    if bool((lower > upper).any()):
        raise ValueError("'lower' must not exceed 'upper'")
    if bool(((x < lower) | (x > upper)).any()):
        raise ValueError("'x0' lies outside the bounds; clamp it first")

    every = torch.arange(num, device=x.device)
    with torch.no_grad():
        r = _residual(residual, x, every)
    if not bool(torch.isfinite(r).all()):
        raise ValueError("'residual' is NaN or infinite at 'x0'")
    if weight is None:
        weight = torch.ones_like(r)
    weight = check_float_tensor(weight, 'weight', r.shape)
    if bool((weight < 0).any()):
        raise ValueError("'weight' must be non-negative")

    info = LMInfo()
    cost = _objective(weight, r, loss)
    info.objective.append(float(cost.mean()))
    lam = torch.full((num, ), damping, dtype=x.dtype, device=x.device)
    active = torch.ones(num, dtype=torch.bool, device=x.device)
    eye = torch.eye(num_params, dtype=x.dtype, device=x.device)
    for _ in range(max_iter):
        if not bool(active.any()):
            info.converged = True
            break
        rows = active.nonzero().flatten()
        xa, ra = x[rows], r[rows]
        if jacobian is None:
            jac = _jacobian(residual, xa, rows)            # (n, R, P)
        else:
            jac = jacobian(xa, rows)[1].detach()
        w = weight[rows]
        if loss == 'l1':
            w = w / ra.abs().clamp_min(l1_epsilon)
        jw = jac * w.unsqueeze(-1)
        hessian = jw.transpose(1, 2) @ jac                 # (n, P, P)
        gradient = (jw * ra.unsqueeze(-1)).sum(1)          # (n, P)
        diagonal = torch.diagonal(hessian, dim1=1, dim2=2)
        scale = diagonal.amax(1, keepdim=True).clamp_min(1e-30)
        system = hessian + lam[rows, None, None] * torch.diag_embed(
            diagonal + 1e-9 * scale) + 1e-12 * scale.unsqueeze(-1) * eye
        # parameters on a bound that descent pushes outwards stay there;
        # the others are solved for without them (projected Newton)
        pinned = ((xa <= lower[rows]) & (gradient > 0)) \
            | ((xa >= upper[rows]) & (gradient < 0))
        free = (~pinned).to(x.dtype)
        system = system * free.unsqueeze(1) * free.unsqueeze(2) \
            + torch.diag_embed(1 - free)
        step = torch.linalg.solve(system, -(gradient * free).unsqueeze(-1)
                                  )[..., 0]
        if max_step is not None:
            longest = step.abs().amax(1, keepdim=True)
            step = step * (max_step / longest.clamp_min(max_step))
        trial = torch.minimum(torch.maximum(xa + step, lower[rows]),
                              upper[rows])
        with torch.no_grad():
            r_trial = _residual(residual, trial, rows)
        new_cost = _objective(weight[rows], r_trial, loss)
        better = torch.isfinite(new_cost) & (new_cost < cost[rows])
        gain = (cost[rows] - new_cost) / cost[rows].clamp_min(1e-300)
        take = rows[better]
        x[take], r[take], cost[take] = trial[better], r_trial[better], \
            new_cost[better]
        lam[rows] = torch.where(better, lam[rows] / 3, lam[rows] * 4)
        done = (better & (gain < tol)) | (lam[rows] > 1e8)
        active[rows[done]] = False
        info.iterations += 1
        info.objective.append(float(cost.mean()))
        info.active.append(int(active.sum()))
    else:
        info.converged = not bool(active.any())
    return x, info


def _objective(weight: Tensor, res: Tensor, loss: str) -> Tensor:
    """Per-row objective of weighted residuals."""
    return (weight * (res.abs() if loss == 'l1' else res * res)).sum(1)


def _bound(value, name: str, x: Tensor, default: float) -> Tensor:
    if value is None:
        return torch.full_like(x, default)
    value = torch.as_tensor(value, dtype=x.dtype, device=x.device)
    if value.shape not in (x.shape[1:], x.shape):
        raise ValueError(f"'{name}' must have shape [{x.size(1)}] or "
                         f"{list(x.shape)}, got {list(value.shape)}")
    if bool(torch.isnan(value).any()):
        raise ValueError(f"'{name}' contains NaN")
    return value.expand_as(x)


def _residual(residual, x: Tensor, rows: Tensor) -> Tensor:
    out = residual(x, rows)
    if not isinstance(out, Tensor) or out.dim() != 2 \
            or out.size(0) != rows.numel():
        raise ValueError(f"'residual' must return [n, R] residuals for the "
                         f"n = {rows.numel()} rows asked for, got "
                         f"{getattr(out, 'shape', type(out).__name__)}")
    return out.detach()


def _jacobian(residual, x: Tensor, rows: Tensor) -> Tensor:
    """(n, R, P) by forward-mode differentiation, all P directions in one
    evaluation of the residuals on P stacked copies of the rows."""
    n, num_params = x.shape
    stacked = x.repeat(num_params, 1)
    tangent = torch.eye(num_params, dtype=x.dtype, device=x.device
                        ).repeat_interleave(n, 0)
    with forward_ad.dual_level():
        out = residual(forward_ad.make_dual(stacked, tangent),
                       rows.repeat(num_params))
        derivative = forward_ad.unpack_dual(out).tangent
    if derivative is None:  # the residuals do not depend on x
        return x.new_zeros(n, out.size(1), num_params)
    return derivative.view(num_params, n, -1).permute(1, 2, 0)


def levenberg_marquardt_tv(jacobian: Callable[[Tensor], tuple], x0: Tensor,
                           weight: Tensor, edges: Tensor, edge_weight: float,
                           lower: Optional[Tensor] = None,
                           upper: Optional[Tensor] = None,
                           max_iter: int = 30, tol: float = 1e-6,
                           damping: float = 1e-3,
                           l1_epsilon: float = 1e-3,
                           tv_epsilon: float = 1e-2,
                           max_step: Optional[float] = None,
                           cg_iter: int = 50,
                           rows_per_call: Optional[int] = None) -> tuple:
    r"""Minimises the L1 fit of many small problems coupled by a total
    variation over a graph. It minimises

    .. math::
        E(x) = \sum_n \sum_k w_{nk} |r_{nk}(x_n)|
        + c \sum_{(i, j) \in \mathcal{E}} \sum_p |x_{ip} - x_{jp}|,
        \qquad \text{lower} \le x \le \text{upper},

    by Levenberg-Marquardt on all rows at once (the rows are no longer
    independent: one damping, one acceptance). Each iteration reweights
    both L1 terms (:math:`1 / \max(|r|, \epsilon)`, Huber-like below
    :math:`\epsilon`) and solves the damped normal equations, whose matrix
    is block diagonal (:math:`P \times P` per row) plus the weighted graph
    Laplacian of the variation, by conjugate gradients preconditioned with
    those blocks and the Laplacian's diagonal; the step is projected onto
    the bounds and kept where :math:`E` decreased. Where
    :func:`levenberg_marquardt` would pull each row towards its
    neighbours' old values (block Jacobi, which spreads information one
    edge per round), this solves for all rows together.

    Args:
        jacobian (callable): ``jacobian(x)`` returns the residuals
            :math:`(N, R)` of all rows and their Jacobian :math:`(N, R, P)`.
        x0 (torch.Tensor): Start :math:`(N, P)`, inside the bounds.
        weight (torch.Tensor): Non-negative weights :math:`(N, R)`.
        edges (torch.Tensor): Graph :math:`(2, E)`; each pair counted once
            per occurrence.
        edge_weight (float): :math:`c`.
        lower, upper (torch.Tensor, optional): Bounds :math:`(P)`.
            (default: :obj:`None`)
        max_iter (int, optional): Iterations. (default: :obj:`30`)
        tol (float, optional): Stop once an accepted step lowers :math:`E`
            by less than :obj:`tol` times its value. (default: :obj:`1e-6`)
        damping (float, optional): Initial :math:`\lambda`.
            (default: :obj:`1e-3`)
        l1_epsilon (float, optional): :math:`\epsilon` of the residuals.
            (default: :obj:`1e-3`)
        tv_epsilon (float, optional): :math:`\epsilon` of the variation,
            in parameter units. (default: :obj:`1e-2`)
        max_step (float, optional): Longest step of any parameter.
            (default: :obj:`None`)
        cg_iter (int, optional): Conjugate-gradient iterations per step.
            (default: :obj:`50`)
        rows_per_call (int, optional): Evaluate the residuals and their
            Jacobian this many rows at a time, ``jacobian(x[rows], rows)``
            with ``rows`` a long tensor of row indices, so that the whole
            :math:`(N, R, P)` Jacobian is never held (the same numbers:
            each row's terms are its own). :obj:`None`: all rows in one
            call, ``jacobian(x)``. (default: :obj:`None`)

    Returns:
        ``(x, info)``: the parameters :math:`(N, P)` and an
        :class:`LMInfo` (its objective is :math:`E` per row, averaged).
    """
    x = check_float_tensor(x0, 'x0', x0.shape).detach().clone()
    if x.dim() != 2:
        raise ValueError(f"'x0' must be [N, P] (one row per problem), got "
                         f"{list(x.shape)}")
    num, num_params = x.shape
    edges = torch.as_tensor(edges, device=x.device)
    if edges.dim() != 2 or edges.size(0) != 2 or edges.dtype != torch.long:
        raise ValueError(f"'edges' must be a [2, E] long tensor, got "
                         f"{list(edges.shape)} {edges.dtype}")
    if edges.numel() and (int(edges.min()) < 0 or int(edges.max()) >= num):
        raise ValueError(f"'edges' must index the {num} rows of 'x0'")
    edge_weight = check_positive_float(edge_weight, 'edge_weight',
                                       allow_zero=True)
    tv_epsilon = check_positive_float(tv_epsilon, 'tv_epsilon')
    max_iter = check_positive_int(max_iter, 'max_iter', minimum=0)
    cg_iter = check_positive_int(cg_iter, 'cg_iter')
    lam = check_positive_float(damping, 'damping')
    lower = _bound(lower, 'lower', x, -float('inf'))
    upper = _bound(upper, 'upper', x, float('inf'))
    if bool(((x < lower) | (x > upper)).any()):
        raise ValueError("'x0' lies outside the bounds; clamp it first")
    if rows_per_call is not None:
        rows_per_call = check_positive_int(rows_per_call, 'rows_per_call')
    i, j = edges

    def normal_equations(r, jac, row_weight):
        """The data term's blocks J^T W J and gradient J^T W r of some
        rows, W reweighted for the L1 norm at their residuals."""
        w = row_weight / r.abs().clamp_min(l1_epsilon)
        jw = jac * w.unsqueeze(-1)
        return jw.transpose(1, 2) @ jac, (jw * r.unsqueeze(-1)).sum(1)

    def evaluate(x):
        """Residuals, the data term's blocks and gradient, and E at x."""
        if rows_per_call is None:
            r, jac = (t.detach() for t in jacobian(x))
            parts = [(r, *normal_equations(r, jac, weight))]
        else:
            parts = []
            for start in range(0, num, rows_per_call):
                rows = torch.arange(start, min(start + rows_per_call, num),
                                    device=x.device)
                r, jac = (t.detach() for t in jacobian(x[rows], rows))
                parts.append((r, *normal_equations(r, jac, weight[rows])))
                del jac
        r, blocks, gradient = (torch.cat(column) for column in zip(*parts))
        data = (weight * r.abs()).sum()
        variation = edge_weight * (x[i] - x[j]).abs().sum()
        return r, blocks, gradient, float(data + variation)

    r, blocks, gradient, cost = evaluate(x)
    if not (torch.isfinite(r).all() and math.isfinite(cost)):
        raise ValueError("the residuals are NaN or infinite at 'x0'")
    info = LMInfo(objective=[cost / num])
    for _ in range(max_iter):
        diff = x[i] - x[j]
        we = edge_weight / diff.abs().clamp_min(tv_epsilon)   # (E, P)
        pull = we * diff
        gradient = gradient.index_add(0, i, pull).index_add(0, j, -pull)
        degree = torch.zeros_like(x).index_add(0, i, we).index_add(0, j, we)
        while True:
            diagonal = torch.diagonal(blocks, dim1=1, dim2=2) + degree
            scale = diagonal.amax(1, keepdim=True).clamp_min(1e-30)
            damp = lam * (diagonal + 1e-9 * scale) + 1e-12 * scale

            def apply(v):
                out = (blocks @ v.unsqueeze(-1))[..., 0] + damp * v
                dv = we * (v[i] - v[j])
                return out.index_add(0, i, dv).index_add(0, j, -dv)

            preconditioner = torch.linalg.inv(
                blocks + torch.diag_embed(degree + damp))
            step = _conjugate_gradients(apply, -gradient, preconditioner,
                                        cg_iter)
            if max_step is not None:
                longest = step.abs().amax(1, keepdim=True)
                step = step * (max_step / longest.clamp_min(max_step))
            trial = torch.minimum(torch.maximum(x + step, lower), upper)
            evaluated = evaluate(trial)
            new_cost = evaluated[-1]
            if math.isfinite(new_cost) and new_cost < cost:
                gain = (cost - new_cost) / max(cost, 1e-300)
                x = trial
                r, blocks, gradient, cost = evaluated
                lam /= 3
                break
            lam *= 4
            if lam > 1e8:
                gain = 0.0
                break
        info.iterations += 1
        info.objective.append(cost / num)
        if gain < tol:
            info.converged = True
            break
    return x, info


def _conjugate_gradients(apply, rhs: Tensor, preconditioner: Tensor,
                         iterations: int, rtol: float = 1e-4) -> Tensor:
    """Preconditioned CG on the flattened unknowns; ``preconditioner``
    holds the inverse of each row's block."""
    def precondition(v):
        return (preconditioner @ v.unsqueeze(-1))[..., 0]

    x = precondition(rhs)
    residual = rhs - apply(x)
    z = precondition(residual)
    direction = z
    rz = (residual * z).sum()
    target = rtol * float(rhs.norm())
    for _ in range(iterations):
        if float(residual.norm()) <= target:
            break
        ad = apply(direction)
        alpha = rz / (direction * ad).sum().clamp_min(1e-300)
        x = x + alpha * direction
        residual = residual - alpha * ad
        z = precondition(residual)
        rz_new = (residual * z).sum()
        direction = z + (rz_new / rz.clamp_min(1e-300)) * direction
        rz = rz_new
    return x
