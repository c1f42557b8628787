"""Batched Levenberg-Marquardt against scipy, one row at a time: least
squares (scipy.optimize.least_squares, with and without bounds), L1
regression (the exact optimum by linear programming), rows that do not
influence each other, analytic and forward-mode Jacobians alike, and bad
input."""
import numpy as np
import pytest
import torch
from scipy.optimize import least_squares, linprog

from tg_intrinsic.solvers import LMInfo, levenberg_marquardt

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
