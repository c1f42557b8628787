r"""Gradients of linear solves, the one place the solvers meet autograd.

:func:`linear_solve` returns :math:`x = A^{-1} b` for a matrix that
depends linearly on an optional weight, :math:`A = A_0 + w D`, through a
:class:`torch.autograd.Function` whose backward pass is the adjoint
solve

.. math::
    \lambda = A^{-\top} \bar x, \qquad \bar b = \lambda, \qquad
    \bar w = -\lambda^\top D x,

(:math:`\bar x` the incoming gradient), run by the caller's own
``adjoint`` callable, so that it reuses whatever the forward solve set up:
a Gravo MG hierarchy with its cached Galerkin levels, or a sparse LU. The
gradient is as accurate as that solve: a relative residual ``tol`` in
:math:`\lambda` gives about ``tol`` (times the condition number) in
:math:`\bar b` and :math:`\bar w`."""
from typing import Callable, Optional

import torch
from torch import Tensor
from torch.autograd.function import once_differentiable

Solve = Callable[[Tensor], Tensor]


class _LinearSolve(torch.autograd.Function):
    @staticmethod
    def forward(ctx, b: Tensor, weight: Optional[Tensor], solve: Solve,
                adjoint: Solve, direction: Optional[Solve]) -> Tensor:
        x = solve(b.detach())
        ctx.adjoint, ctx.direction = adjoint, direction
        ctx.save_for_backward(x, weight)
        return x

    @staticmethod
    @once_differentiable  # the solves are not recorded: no second order
    def backward(ctx, grad_x: Tensor):
        x, weight = ctx.saved_tensors
        grad_b = grad_weight = None
        multiplier = ctx.adjoint(grad_x.contiguous())
        if ctx.needs_input_grad[0]:
            grad_b = multiplier
        if ctx.needs_input_grad[1]:
            # -lambda^T D x per column; a weight shared by all columns
            # collects the sum.
            columns = x.reshape(x.size(0), -1)
            grad = -(multiplier.reshape(columns.shape) *
                     ctx.direction(columns)).sum(0)
            grad_weight = grad.sum() if weight.dim() == 0 else grad
            grad_weight = grad_weight.to(weight).reshape(weight.shape)
        return grad_b, grad_weight, None, None, None


def linear_solve(b: Tensor, solve: Solve, adjoint: Optional[Solve] = None,
                 weight: Optional[Tensor] = None,
                 direction: Optional[Solve] = None) -> Tensor:
    r"""Solves :math:`A x = b` with ``solve`` (a callable from the
    right-hand side to :math:`x`, same shape, device and dtype; it gets a
    tensor detached from the graph), differentiable with respect to
    :obj:`b` and :obj:`weight` when they require grad.

    Args:
        b (Tensor): The right-hand side, :math:`(N)` or :math:`(N, K)`.
        solve (callable): Solves with :math:`A`.
        adjoint (callable, optional): Solves with :math:`A^\top`; default
            :obj:`solve`, which is right only for a symmetric :math:`A`
            (the caller checks that).
        weight (Tensor, optional): :math:`w` in :math:`A = A_0 + w D`, a
            scalar shared by every column, or one value per column
            :math:`(K)` (then column :math:`k` was solved with
            :math:`A_0 + w_k D`).
        direction (callable, optional): :math:`X \mapsto D X` on
            :math:`(N, K)` tensors; needed with :obj:`weight`.
    """
    if adjoint is None:
        adjoint = solve
    if weight is not None and direction is None:
        raise ValueError("a 'weight' needs its 'direction' (the product "
                         "with dA / dweight) for its gradient")
    needs_grad = b.requires_grad or (weight is not None and
                                     weight.requires_grad)
    if not (torch.is_grad_enabled() and needs_grad):
        return solve(b.detach())
    return _LinearSolve.apply(b, weight, solve, adjoint, direction)
