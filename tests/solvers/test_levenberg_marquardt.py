"""Batched Levenberg-Marquardt against scipy, one row at a time: least
squares (scipy.optimize.least_squares, with and without bounds), L1
regression (the exact optimum by linear programming), rows that do not
influence each other, analytic and forward-mode Jacobians alike, and bad
input; and the solver whose rows are coupled by a total variation, against
the linear program of L1 regression plus total variation."""
import numpy as np
import pytest
import torch
from scipy.optimize import least_squares, linprog

from tg_intrinsic.solvers import (LMInfo, levenberg_marquardt,
                                  levenberg_marquardt_tv)

D64 = torch.float64


def decays(num=25, samples=30, seed=0):
    """Rows a e^{-b t} + noise, one (a, b) per row."""
    g = torch.Generator().manual_seed(seed)
    t = torch.linspace(0, 3, samples, dtype=D64)
    a = 1 + torch.rand(num, dtype=D64, generator=g)
    b = 0.5 + torch.rand(num, dtype=D64, generator=g)
    y = a[:, None] * torch.exp(-b[:, None] * t) \
        + 0.01 * torch.randn(num, samples, dtype=D64, generator=g)

    def residual(x, rows):
        return x[:, :1] * torch.exp(-x[:, 1:2] * t) - y[rows]

    def scipy_row(i, x0, **kwargs):
        return least_squares(lambda p: p[0] * np.exp(-p[1] * t.numpy())
                             - y[i].numpy(), x0, xtol=1e-15, ftol=1e-15,
                             gtol=1e-15, **kwargs).x
    return residual, scipy_row, num


def test_least_squares_matches_scipy_row_by_row():
    residual, scipy_row, num = decays()
    x, info = levenberg_marquardt(residual, torch.ones(num, 2, dtype=D64),
                                  tol=1e-12, max_iter=100)
    assert isinstance(info, LMInfo) and info.converged
    assert info.objective[-1] < info.objective[0]
    ref = np.stack([scipy_row(i, [1.0, 1.0]) for i in range(num)])
    np.testing.assert_allclose(x.numpy(), ref, atol=1e-7)


def test_bounds_match_scipy_and_hold():
    residual, scipy_row, num = decays(seed=1)
    lower = torch.tensor([0.0, 0.0], dtype=D64)
    upper = torch.tensor([1.3, 5.0], dtype=D64)
    x, _ = levenberg_marquardt(residual, torch.full((num, 2), 0.5,
                                                    dtype=D64),
                               lower=lower, upper=upper, tol=1e-14,
                               max_iter=200)
    assert bool(((x >= lower) & (x <= upper)).all())
    ref = np.stack([scipy_row(i, [0.5, 0.5], bounds=([0, 0], [1.3, 5.0]))
                    for i in range(num)])
    np.testing.assert_allclose(x.numpy(), ref, atol=1e-5)
    assert (x[:, 0] == 1.3).sum() > 0  # some rows sit on the bound


def test_l1_regression_reaches_the_linear_programming_optimum():
    g = torch.Generator().manual_seed(2)
    num, samples, params = 12, 40, 3
    A = torch.randn(num, samples, params, dtype=D64, generator=g)
    b = torch.randn(num, samples, dtype=D64, generator=g)
    b[:, :5] += 5  # outliers, which L1 ignores and L2 does not

    def residual(x, rows):
        return (A[rows] @ x.unsqueeze(-1)).squeeze(-1) - b[rows]

    x, _ = levenberg_marquardt(residual, torch.zeros(num, params, dtype=D64),
                               loss='l1', max_iter=300, tol=0,
                               l1_epsilon=1e-7)
    ours = (A @ x.unsqueeze(-1)).squeeze(-1).sub(b).abs().sum(1)
    for i in range(num):
        # min 1^T s  s.t.  -s <= A x - b <= s
        a, y = A[i].numpy(), b[i].numpy()
        eye = np.eye(samples)
        lp = linprog(np.r_[np.zeros(params), np.ones(samples)],
                     A_ub=np.block([[a, -eye], [-a, -eye]]),
                     b_ub=np.r_[y, -y],
                     bounds=[(None, None)] * params + [(0, None)] * samples)
        assert float(ours[i]) <= lp.fun * (1 + 1e-6) + 1e-9


def test_rows_are_independent_and_jacobians_agree():
    residual, _, num = decays(seed=3)
    x0 = torch.ones(num, 2, dtype=D64)
    x, _ = levenberg_marquardt(residual, x0, tol=1e-12, max_iter=100)
    # rows 3..7 alone give the same answer
    sub = torch.arange(3, 8)
    x_sub, _ = levenberg_marquardt(lambda v, rows: residual(v, sub[rows]),
                                   x0[sub], tol=1e-12, max_iter=100)
    torch.testing.assert_close(x_sub, x[sub], rtol=0, atol=1e-9)
    t = torch.linspace(0, 3, 30, dtype=D64)

    def jacobian(v, rows):
        e = torch.exp(-v[:, 1:2] * t)
        return residual(v, rows), torch.stack([e, -v[:, :1] * t * e], -1)

    x_analytic, _ = levenberg_marquardt(residual, x0, tol=1e-12,
                                        max_iter=100, jacobian=jacobian)
    torch.testing.assert_close(x_analytic, x, rtol=0, atol=1e-9)


def test_bad_input():
    residual, _, num = decays()
    x0 = torch.ones(num, 2, dtype=D64)
    cases = [
        (dict(x0=torch.ones(num, dtype=D64)), r"'x0' must be \[N, P\]"),
        (dict(x0=x0 * float('nan')), "'x0' contains NaN"),
        (dict(loss='huber'), "'loss' must be one of"),
        (dict(max_iter=-1), "'max_iter' must be at least 0"),
        (dict(lower=torch.tensor([2.0, 0.0])), "'x0' lies outside"),
        (dict(lower=torch.tensor([1.0, 1.0]),
              upper=torch.tensor([0.0, 2.0])), "'lower' must not exceed"),
        (dict(upper=torch.ones(3)), r"'upper' must have shape \[2\]"),
        (dict(weight=-torch.ones(num, 30, dtype=D64)), 'non-negative'),
        (dict(weight=torch.ones(num, 29, dtype=D64)), "'weight' must have"),
        (dict(residual=lambda v, rows: v.sum(1)), r"\[n, R\] residuals"),
        (dict(residual=lambda v, rows: residual(v, rows) / 0 * 0),
         'NaN or infinite'),
    ]
    for change, match in cases:
        kwargs = dict(residual=residual, x0=x0)
        kwargs.update(change)
        with pytest.raises(ValueError, match=match):
            levenberg_marquardt(**kwargs)


# ------------------------------------------------ coupled by total variation
def chain(num=12, samples=6, params=2, seed=0):
    """Linear rows r_n = A_n x_n - b_n along a path graph 0-1-...-(n-1)."""
    g = torch.Generator().manual_seed(seed)
    A = torch.randn(num, samples, params, dtype=D64, generator=g)
    truth = torch.cumsum(0.3 * torch.randn(num, params, dtype=D64,
                                           generator=g), 0)
    b = (A @ truth.unsqueeze(-1))[..., 0] \
        + 0.3 * torch.randn(num, samples, dtype=D64, generator=g)
    edges = torch.stack([torch.arange(num - 1), torch.arange(1, num)])

    def jacobian(x):
        return (A @ x.unsqueeze(-1))[..., 0] - b, A
    return A, b, edges, jacobian


def tv_linear_program(A, b, edges, c):
    """min sum |A x - b| + c sum_edges |x_i - x_j| as a linear program."""
    num, samples, params = A.shape
    unknowns = num * params
    rows, rhs = [], []
    blocks = np.zeros((num * samples, unknowns))
    for n in range(num):
        blocks[n * samples:(n + 1) * samples,
               n * params:(n + 1) * params] = A[n].numpy()
    diff = np.zeros((edges.size(1) * params, unknowns))
    for e, (i, j) in enumerate(edges.t().tolist()):
        for p in range(params):
            diff[e * params + p, i * params + p] = 1
            diff[e * params + p, j * params + p] = -1
    s_r, s_e = num * samples, len(diff)
    zeros = np.zeros
    rows = np.block([
        [blocks, -np.eye(s_r), zeros((s_r, s_e))],
        [-blocks, -np.eye(s_r), zeros((s_r, s_e))],
        [diff, zeros((s_e, s_r)), -np.eye(s_e)],
        [-diff, zeros((s_e, s_r)), -np.eye(s_e)]])
    y = b.numpy().ravel()
    rhs = np.r_[y, -y, zeros(2 * s_e)]
    cost = np.r_[zeros(unknowns), np.ones(s_r), c * np.ones(s_e)]
    return linprog(cost, A_ub=rows, b_ub=rhs, bounds=[(None, None)]
                   * unknowns + [(0, None)] * (s_r + s_e)).fun


@pytest.mark.parametrize('c', [0.0, 0.3, 3.0])
def test_total_variation_reaches_the_linear_programming_optimum(c):
    A, b, edges, jacobian = chain()
    x0 = torch.zeros(len(A), 2, dtype=D64)
    x, info = levenberg_marquardt_tv(
        jacobian, x0, torch.ones_like(b), edges, c, max_iter=300,
        tol=1e-13, l1_epsilon=1e-7, tv_epsilon=1e-7, cg_iter=200)
    objective = float((jacobian(x)[0].abs()).sum()
                      + c * (x[1:] - x[:-1]).abs().sum())
    optimum = tv_linear_program(A, b, edges, c)
    assert objective <= optimum * (1 + 1e-4)
    assert info.objective[-1] <= info.objective[0]


def test_total_variation_without_weight_is_the_row_by_row_solver():
    A, b, edges, jacobian = chain(seed=1)
    x0 = torch.zeros(len(A), 2, dtype=D64)
    coupled, _ = levenberg_marquardt_tv(jacobian, x0, torch.ones_like(b),
                                        edges, 0.0, max_iter=200, tol=1e-13,
                                        l1_epsilon=1e-7)
    separate, _ = levenberg_marquardt(
        lambda x, rows: (A[rows] @ x.unsqueeze(-1))[..., 0] - b[rows], x0,
        loss='l1', max_iter=200, tol=1e-13, l1_epsilon=1e-7)
    cost = [float(jacobian(x)[0].abs().sum()) for x in (coupled, separate)]
    assert cost[0] == pytest.approx(cost[1], rel=1e-6)


def test_total_variation_in_blocks_of_rows_is_the_same():
    """rows_per_call evaluates the Jacobian a block of rows at a time:
    the same iterates, bit for bit."""
    A, b, edges, jacobian = chain(seed=3)
    x0 = torch.zeros(len(A), 2, dtype=D64)
    calls = []

    def in_rows(x, rows):
        calls.append(rows.numel())
        return ((A[rows] @ x.unsqueeze(-1))[..., 0] - b[rows], A[rows])
    whole, info = levenberg_marquardt_tv(jacobian, x0, torch.ones_like(b),
                                         edges, 0.3, max_iter=20)
    blocked, blocked_info = levenberg_marquardt_tv(
        in_rows, x0, torch.ones_like(b), edges, 0.3, max_iter=20,
        rows_per_call=3)
    assert torch.equal(whole, blocked)
    assert info.objective == blocked_info.objective
    assert max(calls) == 3 and len(calls) > len(A) // 3


def test_total_variation_holds_bounds_and_step_limit():
    A, b, edges, jacobian = chain(seed=2)
    x0 = torch.zeros(len(A), 2, dtype=D64)
    lower, upper = torch.tensor([-0.2, -0.1]), torch.tensor([0.2, 0.3])
    x, _ = levenberg_marquardt_tv(jacobian, x0, torch.ones_like(b), edges,
                                  0.3, lower, upper, max_iter=50)
    assert bool((x >= lower.to(x)).all() and (x <= upper.to(x)).all())
    one, _ = levenberg_marquardt_tv(jacobian, x0, torch.ones_like(b), edges,
                                    0.3, max_iter=1, max_step=0.01)
    assert float((one - x0).abs().max()) <= 0.01 + 1e-15


def test_total_variation_bad_input():
    A, b, edges, jacobian = chain()
    x0 = torch.zeros(len(A), 2, dtype=D64)
    weight = torch.ones_like(b)
    cases = [
        (dict(edges=edges[0]), r"'edges' must be a \[2, E\] long"),
        (dict(edges=edges + 1), "'edges' must index the 12 rows"),
        (dict(edge_weight=-1.0), "'edge_weight'"),
        (dict(tv_epsilon=0.0), "'tv_epsilon'"),
        (dict(x0=torch.zeros(12, dtype=D64)), r"'x0' must be \[N, P\]"),
        (dict(lower=torch.tensor([0.5, 0.0])), "'x0' lies outside"),
        (dict(jacobian=lambda x: (jacobian(x)[0] / 0, A)), 'NaN or infinite'),
    ]
    for change, match in cases:
        kwargs = dict(jacobian=jacobian, x0=x0, weight=weight, edges=edges,
                      edge_weight=0.3)
        kwargs.update(change)
        with pytest.raises(ValueError, match=match):
            levenberg_marquardt_tv(**kwargs)
