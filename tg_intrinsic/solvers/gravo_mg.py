import numbers
import time
import warnings
from dataclasses import dataclass, field
from typing import Callable, Dict, List, Optional, Sequence, Union

import numpy as np
import scipy.sparse as sp
import torch
from pyamg.relaxation.relaxation import gauss_seidel
from scipy.sparse.linalg import LinearOperator, splu
from torch import Tensor

from tg_intrinsic.geometry.checks import (check_choice, check_edge_index,
                                          check_faces, check_points,
                                          check_positive_float,
                                          check_positive_int)
from tg_intrinsic.geometry.multigrid.gravo import gravo_hierarchy
from tg_intrinsic.solvers._adjoint import linear_solve
from tg_intrinsic.solvers._kernels import (check_matrix, fingerprint,
                                           galerkin, matvec)
from tg_intrinsic.solvers._torch_levels import TorchLevels

CYCLES = ('V', 'W', 'F')
CRITERIA = ('relative', 'mass')
METHODS = ('cycles', 'pcg')


class ConvergenceWarning(UserWarning):
    """A :meth:`GravoMG.solve` stopped at ``max_iter`` cycles above its
    tolerance (``strict=True`` raises instead).

    Its attributes say where it stopped: ``max_iter``, ``method``
    (``'cycles'`` or ``'pcg'``), ``criterion``, ``residual`` (the last
    one) and ``tol``. :meth:`reason` words it with the arguments that
    change the outcome; an interface with other names for them (the
    command line's options) passes its own wording of a setting."""

    def __init__(self, message: str = '', max_iter: Optional[int] = None,
                 method: str = 'cycles', criterion: str = 'relative',
                 residual: float = float('nan'), tol: float = float('nan')):
        self.max_iter, self.method, self.criterion = max_iter, method, \
            criterion
        self.residual, self.tol = residual, tol
        super().__init__(message or (
            f'GravoMG.solve did not converge: {self.reason()}'
            if max_iter is not None else ''))

    def __reduce__(self):
        return (self.__class__, (str(self), self.max_iter, self.method,
                                 self.criterion, self.residual, self.tol))

    def reason(self, setting: Optional[Callable[..., str]] = None) -> str:
        """Why the solve stopped and what to change, e.g. ``stopped at
        max_iter=5 cycles with relative residual 0.0012 above
        tol=1e-08; raise max_iter, or use method='pcg'``.
        ``setting(name, value)`` words the argument ``name`` (one of
        ``'max_iter'``, ``'tol'``, ``'method'``) set to ``value``, and
        ``setting(name)`` the argument alone; by default as in Python."""
        setting = setting or _python_setting
        unit = 'cycles' if self.method == 'cycles' else 'PCG iterations'
        return (f"stopped at {setting('max_iter', self.max_iter)} {unit} "
                f"with {self.criterion} residual {self.residual:.3g} above "
                f"{setting('tol', self.tol)}; raise {setting('max_iter')}"
                + (f", or use {setting('method', 'pcg')}"
                   if self.method == 'cycles' else ''))


def _python_setting(name: str, value=None) -> str:
    """A keyword argument as written in Python: ``name=value``."""
    if value is None:
        return name
    if isinstance(value, str):
        return f'{name}={value!r}'
    if isinstance(value, numbers.Integral):
        return f'{name}={int(value)}'
    return f'{name}={value:g}'


@dataclass
class SolveInfo:
    """What a :meth:`GravoMG.solve` did: the iterations (cycles), the
    largest residual over the columns after each (relative, or
    mass-weighted) and the seconds since the solve began at each, whether
    it reached the tolerance and, if not, ``reason`` why; the setup time
    (only the cache lookup when the matrix was seen before: ``cached``)
    and the solve time in seconds, and ``direct`` with the reason when
    there was no hierarchy to cycle on."""
    iterations: int = 0
    residuals: List[float] = field(default_factory=list)
    times: List[float] = field(default_factory=list)
    converged: bool = False
    setup_time: float = 0.0
    solve_time: float = 0.0
    cached: bool = False
    direct: Optional[str] = None
    reason: Optional[str] = None


class _Levels:
    """Galerkin operators of one matrix, the coarsest factorisation, and
    the torch copies made per device and dtype on demand."""

    def __init__(self, A: sp.csr_matrix, prolongations, restrictions):
        self.A = [A]
        for P, R in zip(prolongations, restrictions):
            self.A.append(galerkin(R, self.A[-1], P))
        # Rows of P sum to 1, so a matrix that annihilates constants makes
        # every Galerkin level do so. Tested on the coarsest, whose size is
        # bounded: S + 1e-6 M on a unit-area mesh leaves 1e-10 of the row
        # scale there, rounding 1e-16.
        coarse = self.A[-1]
        row_scale = float(abs(coarse).sum(1).max())
        ones = np.ones(coarse.shape[0])
        if np.linalg.norm(coarse @ ones) <= 1e-13 * row_scale * np.sqrt(
                coarse.shape[0]):
            raise ValueError("'A' annihilates constants, so it is singular "
                             "(a pure Laplacian?); add a mass term, e.g. "
                             "S + eta * M, or fix a value")
        self.coarse = splu(self.A[-1].tocsc(), permc_spec='MMD_AT_PLUS_A',
                           diag_pivot_thresh=0.0,
                           options={'SymmetricMode': True})
        self.torch: Dict[tuple, TorchLevels] = {}


class _ConjugateGradients:
    """Preconditioned conjugate gradients on the columns of B at once
    (each column has its own step lengths), one :meth:`step` at a time."""

    def __init__(self, A: sp.csr_matrix, B: np.ndarray, X: np.ndarray,
                 precondition):
        self.A, self.precondition = A, precondition
        self.R = B - self._apply(X)
        self.Z = precondition(self.R)
        self.P = self.Z.copy()
        self.rz = (self.R * self.Z).sum(0)

    def _apply(self, X: np.ndarray) -> np.ndarray:
        return np.stack([matvec(self.A, np.ascontiguousarray(X[:, k]))
                         for k in range(X.shape[1])], 1)

    def step(self, X: np.ndarray) -> np.ndarray:
        AP = self._apply(self.P)
        curvature = (self.P * AP).sum(0)
        # A column that is already solved exactly has P = 0: it stays.
        alpha = np.divide(self.rz, curvature, out=np.zeros_like(self.rz),
                          where=curvature > 0)
        X += alpha * self.P
        self.R -= alpha * AP
        self.Z = self.precondition(self.R)
        rz = (self.R * self.Z).sum(0)
        beta = np.divide(rz, self.rz, out=np.zeros_like(rz),
                         where=self.rz > 0)
        self.P = self.Z + beta * self.P
        self.rz = rz
        return X


class GravoMG:
    r"""Geometric multigrid solver for sparse symmetric positive definite
    systems :math:`A x = b` on surfaces (Gravo MG; Wiersma et al., SIGGRAPH
    2023), on a graph-Voronoi hierarchy with prolongations
    :math:`P_0, \dots, P_{L-1}`. The coarse operators are Galerkin
    products,

    .. math::
        A_{l+1} = P_l^\top A_l P_l,

    and one cycle smooths with forward Gauss-Seidel sweeps (pyamg's
    compiled kernel) before and after the coarse correction, as the
    original does, restricts the residual with
    :math:`P_l^\top`, corrects recursively, and solves the coarsest level
    directly. As a preconditioner the post-smoothing runs backward, which
    makes the cycle a symmetric operator, as conjugate gradients need. A
    torch right-hand side runs the torch backend instead (Chebyshev
    smoothing, see :meth:`solve`) on its device. The
    Galerkin operators and the coarse factorisation are cached per matrix,
    so later solves with the same :math:`A` cost only cycles.

    Args:
        prolongations (list of scipy.sparse matrices): :math:`P_l`, fine to
            coarse, shapes :math:`(n_l, n_{l+1})`. Build them with
            :meth:`from_data` (a :class:`~tg_intrinsic.transforms.
            GravoHierarchy` result), :meth:`from_mesh` or
            :meth:`from_points`.
        cache_size (int, optional): Matrices whose setup is kept.
            (default: :obj:`4`)

    Shapes:
        - **input:** :math:`A` :math:`(n_0, n_0)` (scipy sparse), right-hand
          sides :math:`b` :math:`(n_0)` or :math:`(n_0, C)` (numpy, or torch
          on any device for the torch backend), optional :math:`x_0` like
          :math:`b`
        - **output:** :math:`x` like :math:`b`; :attr:`info` a
          :class:`SolveInfo`
    """
    def __init__(self, prolongations: Sequence[sp.spmatrix],
                 cache_size: int = 4):
        self.prolongations = [sp.csr_matrix(P, dtype=np.float64)
                              for P in prolongations]
        for level, P in enumerate(self.prolongations):
            if not np.isfinite(P.data).all():
                raise ValueError(f"prolongation {level} holds NaN or "
                                 f"infinite weights; rebuild the hierarchy")
        self.restrictions = [P.T.tocsr() for P in self.prolongations]
        for fine, coarse in zip(self.prolongations, self.prolongations[1:]):
            if fine.shape[1] != coarse.shape[0]:
                raise ValueError(f"prolongations do not chain: "
                                 f"{fine.shape} then {coarse.shape}")
        self.cache_size = cache_size
        self._cache: Dict[str, _Levels] = {}
        self.info = SolveInfo()

    @classmethod
    def from_points(cls, pos: Union[Tensor, np.ndarray],
                    edge_index: Union[Tensor, np.ndarray],
                    **hierarchy) -> 'GravoMG':
        """Builds the hierarchy of points :math:`(N, 3)` with the neighbour
        graph ``edge_index`` :math:`(2, E)` (tensors or arrays); keyword
        arguments (``ratio``, ``lower_bound``, ...) go to
        :func:`~tg_intrinsic.geometry.multigrid.gravo.gravo_hierarchy`."""
        pos = check_points(torch.as_tensor(pos)).detach().double().cpu()
        edge_index = torch.as_tensor(edge_index)
        if not edge_index.is_floating_point():
            edge_index = edge_index.long()
        edge_index = check_edge_index(edge_index, pos.size(0), pos)
        levels = gravo_hierarchy(pos, edge_index, **hierarchy)
        n = pos.size(0)
        out = []
        for level in levels:
            m = level.sample.numel()
            out.append(sp.csr_matrix(
                (level.prolong_weight.numpy(),
                 tuple(level.prolong_index.numpy())), shape=(n, m)))
            n = m
        return cls(out)

    @classmethod
    def from_mesh(cls, pos: Union[Tensor, np.ndarray],
                  face: Union[Tensor, np.ndarray], **hierarchy) -> 'GravoMG':
        """Builds the hierarchy of a triangle mesh, ``pos`` :math:`(N, 3)`
        and ``face`` :math:`(3, F)` like every function of the library
        (tensors or arrays), on its edges; keyword arguments as in
        :meth:`from_points`."""
        pos = check_points(torch.as_tensor(pos)).detach().double().cpu()
        face = torch.as_tensor(face)
        if not face.is_floating_point():
            face = face.long()
        face = check_faces(face, pos.size(0), pos)
        edges = torch.cat([face[[0, 1]], face[[1, 2]], face[[2, 0]]], 1)
        return cls.from_points(pos, edges, **hierarchy)

    @classmethod
    def from_data(cls, data) -> 'GravoMG':
        """Reads ``prolong_index_l`` / ``prolong_weight_l`` of a (possibly
        batched) :class:`~tg_intrinsic.transforms.GravoHierarchy` result."""
        out = []
        n = data.pos.size(0)
        level = 1
        while f'prolong_index_{level}' in data:
            m = data[f'pos_{level}'].size(0)
            rows, cols = data[f'prolong_index_{level}'].cpu().numpy()
            out.append(sp.csr_matrix(
                (data[f'prolong_weight_{level}'].cpu().double().numpy(),
                 (rows, cols)), shape=(n, m)))
            n, level = m, level + 1
        return cls(out)

    @property
    def num_points(self) -> Optional[int]:
        return self.prolongations[0].shape[0] if self.prolongations else None

    # ------------------------------------------------------------------
    def _as_matrix(self, A) -> sp.csr_matrix:
        if not sp.issparse(A):
            raise ValueError(f"'A' must be a scipy sparse matrix, got "
                             f"{type(A).__name__}")
        A = sp.csr_matrix(A, dtype=np.float64)
        if A.shape[0] != A.shape[1]:
            raise ValueError(f"'A' must be square, got shape {A.shape}")
        if self.num_points is not None and A.shape[0] != self.num_points:
            raise ValueError(f"'A' is {A.shape[0]} x {A.shape[1]} but the "
                             f"hierarchy has {self.num_points} points")
        return A

    @staticmethod
    def _check(A: sp.csr_matrix):
        finite, scale, asymmetry = check_matrix(A)
        if not finite:
            raise ValueError("'A' holds NaN or infinite entries")
        if scale == 0:
            raise ValueError("'A' is zero")
        if asymmetry > 1e-10:
            raise ValueError("'A' is not symmetric; Gravo MG (Galerkin "
                             "coarsening, Gauss-Seidel smoothing) needs a "
                             "symmetric positive definite matrix")
        bad = np.flatnonzero(A.diagonal() <= 0)
        if bad.size:
            raise ValueError(f"'A' has {bad.size} zero or negative diagonal "
                             f"entries (first rows: {bad[:5].tolist()}), so "
                             f"it is not positive definite (a row without "
                             f"a mass or stiffness term?)")

    def setup(self, A) -> _Levels:
        """The cached Galerkin operators and coarse factorisation of A,
        found by a hash of its exact bits; a new matrix is checked (finite,
        symmetric, not annihilating constants) and set up."""
        A = self._as_matrix(A)
        start = time.perf_counter()
        key = fingerprint(A)
        levels = self._cache.get(key)
        self.info = SolveInfo(cached=levels is not None)
        if levels is None:
            self._check(A)
            levels = _Levels(A, self.prolongations, self.restrictions)
            if len(self._cache) >= self.cache_size:
                self._cache.pop(next(iter(self._cache)))
            self._cache[key] = levels
        self.info.setup_time = time.perf_counter() - start
        return levels

    def _cycle(self, levels: _Levels, level: int, b, x, kind: str, pre: int,
               post: int, post_sweep: str = 'forward'):
        A = levels.A[level]
        if level == len(levels.A) - 1:
            return levels.coarse.solve(b)
        gauss_seidel(A, x, b, iterations=pre, sweep='forward')
        P = self.prolongations[level]
        coarse_b = self.restrictions[level] @ (b - matvec(A, x))
        coarse_x = np.zeros_like(coarse_b)
        visits = 2 if kind == 'W' else 1
        for _ in range(visits):
            coarse_x = self._cycle(levels, level + 1, coarse_b, coarse_x,
                                   kind, pre, post, post_sweep)
        if kind == 'F':
            coarse_x = self._cycle(levels, level + 1, coarse_b, coarse_x,
                                   'V', pre, post, post_sweep)
        x += P @ coarse_x
        gauss_seidel(A, x, b, iterations=post, sweep=post_sweep)
        return x

    def solve(self, A, b, x0=None, tol: float = 1e-4, max_iter: int = 100,
              criterion: str = 'relative', mass=None, pre: int = 2,
              post: int = 2, cycle: str = 'V', strict: bool = False,
              method: str = 'cycles'):
        r"""Cycles until the residual :math:`r = b - A x` is small:
        ``'relative'``: :math:`\|r\| / \|b\|`, ``'mass'``:
        :math:`\|r\|_{M^{-1}} / \|b\|_{M^{-1}}` with the lumped masses
        :obj:`mass` (the norm of a load vector), below :obj:`tol` for every
        column of :obj:`b`, or :obj:`max_iter` cycles. :obj:`cycle` is
        ``'V'``, ``'W'`` or ``'F'``.

        A numpy :obj:`b` of shape :math:`(N)` or :math:`(N, K)` runs on the
        CPU with Gauss-Seidel smoothing (pyamg's compiled sweeps,
        :obj:`pre` and :obj:`post` sweeps). A torch :obj:`b` runs with the
        torch backend on its device and dtype (float32 or float64), all
        :math:`K` columns at once: Chebyshev smoothing of degree
        :obj:`pre` / :obj:`post` preconditioned by the diagonal, sparse
        CSR products, and the coarsest level solved by the sparse LU on
        the CPU. Cycles that diverge raise a RuntimeError (float32 does on
        nearly singular systems such as :math:`S + 10^{-6} M`).

        Without a hierarchy (fewer points than its lower bound) the system
        is solved directly (on the CPU) and :attr:`info` says so. Returns
        :math:`x` of the type, shape, device and dtype of :obj:`b`;
        :attr:`info` holds a :class:`SolveInfo`. A solve that stops at
        :obj:`max_iter` cycles above :obj:`tol` returns its last iterate,
        sets ``info.reason`` and warns (:class:`ConvergenceWarning`), or
        raises a :class:`RuntimeError` with :obj:`strict=True`.

        A torch :obj:`b` that requires grad gives an :math:`x` that is
        differentiable with respect to :obj:`b` (not :obj:`A`, a scipy
        matrix, nor :obj:`x0`): the backward pass solves the adjoint
        system :math:`A^\top \lambda = \partial L / \partial x`, which
        is this system again, since :meth:`setup` accepts only a symmetric
        :math:`A`, with the same backend, device and options (:obj:`tol`,
        :obj:`cycle`, ...) on the same cached levels (set up again only if
        :obj:`cache_size` other matrices were solved in between), and
        returns
        :math:`\partial L / \partial b = \lambda`. The gradient is as
        accurate as the solve: to the relative residual :obj:`tol`.
        :attr:`info` then describes the adjoint solve."""
        if isinstance(b, torch.Tensor) and b.requires_grad and \
                torch.is_grad_enabled():
            options = dict(tol=tol, max_iter=max_iter, criterion=criterion,
                           mass=mass, pre=pre, post=post, cycle=cycle,
                           strict=strict, method=method)
            if isinstance(x0, torch.Tensor):
                x0 = x0.detach()
            return linear_solve(
                b, lambda rhs: self.solve(A, rhs, x0=x0, **options),
                lambda grad: self.solve(A, grad, **options))
        check_choice(cycle, 'cycle', CYCLES)
        check_choice(criterion, 'criterion', CRITERIA)
        check_choice(method, 'method', METHODS)
        tol = check_positive_float(tol, 'tol')
        max_iter = check_positive_int(max_iter, 'max_iter')
        pre = check_positive_int(pre, 'pre', minimum=0)
        post = check_positive_int(post, 'post', minimum=0)
        if pre + post == 0:
            raise ValueError("'pre' and 'post' are both 0: a cycle needs at "
                             "least one smoothing sweep")
        levels = self.setup(A)
        n = levels.A[0].shape[0]
        use_torch = isinstance(b, torch.Tensor)
        if use_torch and method == 'pcg':
            raise ValueError("method='pcg' runs on the CPU with numpy "
                             "arrays; pass b as a numpy array, or use "
                             "method='cycles' for the torch backend")
        if use_torch:
            if b.dtype not in (torch.float32, torch.float64):
                raise ValueError(f"'b' must be float32 or float64, got "
                                 f"{b.dtype}")
            finite = bool(torch.isfinite(b).all())
        else:
            b = np.asarray(b, dtype=np.float64)
            finite = bool(np.isfinite(b).all())
        if b.ndim not in (1, 2) or b.shape[0] != n:
            raise ValueError(f"'b' must have shape ({n},) or ({n}, K), got "
                             f"{tuple(b.shape)}")
        if not finite:
            raise ValueError("'b' holds NaN or infinite entries")
        weight = np.ones(n)
        if criterion == 'mass':
            if mass is None:
                raise ValueError("criterion='mass' needs the lumped "
                                 "masses: pass mass=...")
            mass = np.asarray(mass, dtype=np.float64).reshape(-1)
            if mass.shape != (n, ) or not (mass > 0).all():
                raise ValueError("'mass' must hold one positive value per "
                                 "point")
            weight = 1.0 / mass
        if x0 is not None:
            x0 = x0 if isinstance(x0, torch.Tensor) else \
                np.asarray(x0, dtype=np.float64)
            if tuple(x0.shape) != tuple(b.shape):
                raise ValueError(f"'x0' must have the shape of 'b', "
                                 f"{tuple(b.shape)}, got {tuple(x0.shape)}")
            if not bool((torch.isfinite(x0) if isinstance(x0, torch.Tensor)
                         else np.isfinite(x0)).all()):
                raise ValueError("'x0' holds NaN or infinite entries")
        start = time.perf_counter()
        info = self.info
        B = b.reshape(n, -1)
        if len(levels.A) == 1:
            info.direct = ('no coarse level (fewer points than the '
                           'hierarchy lower bound): one direct solve')
            values = B.detach().cpu().double().numpy() if use_torch else B
            x = levels.coarse.solve(np.ascontiguousarray(values))
            if use_torch:
                x = torch.from_numpy(x).to(b.device, b.dtype)
            info.converged = True
            info.solve_time = time.perf_counter() - start
            return x.reshape(b.shape)
        if use_torch:
            backend = self._torch_levels(levels, b.device, b.dtype)
            weight = torch.from_numpy(weight).to(b.device, b.dtype)[:, None]
            A0 = backend.A[0]
            X = torch.zeros_like(B) if x0 is None else \
                torch.as_tensor(x0).to(B).reshape(n, -1).clone()

            def step(X):
                return backend.cycle(0, B, X, cycle, pre, post)

            def norms(R):
                return (weight * R * R).sum(0).sqrt().cpu().double().numpy()

            def residual(X):
                return B - A0 @ X
        else:
            A0 = levels.A[0]
            weight = weight[:, None]
            X = np.zeros_like(B) if x0 is None else \
                np.array(x0, dtype=np.float64).reshape(n, -1)

            def step(X):
                if method == 'pcg':
                    return pcg.step(X)
                for k in range(X.shape[1]):  # columns: a few at most
                    X[:, k] = self._cycle(levels, 0, B[:, k],
                                          np.ascontiguousarray(X[:, k]),
                                          cycle, pre, post)
                return X

            def norms(R):
                return np.sqrt((weight * R * R).sum(0))

            def residual(X):
                if X.shape[1] == 1:
                    return (B[:, 0] - matvec(A0, X[:, 0]))[:, None]
                return np.stack([B[:, k] - matvec(A0, X[:, k])
                                 for k in range(X.shape[1])], 1)
            if method == 'pcg':
                pcg = _ConjugateGradients(
                    A0, B, X, lambda R: np.stack([self._cycle(
                        levels, 0, np.ascontiguousarray(R[:, k]),
                        np.zeros(n), cycle, pre, post, 'backward')
                        for k in range(R.shape[1])], 1))
        b_norm = norms(B)
        b_norm[b_norm == 0] = 1.0  # a zero column stays zero
        for _ in range(max_iter):
            X = step(X)
            info.iterations += 1
            info.residuals.append(float((norms(residual(X)) / b_norm).max()))
            info.times.append(time.perf_counter() - start)
            if not np.isfinite(info.residuals[-1]) or \
                    info.residuals[-1] > 1e3 * max(info.residuals[0], 1.0):
                raise RuntimeError(
                    f"the cycles diverge (relative residual "
                    f"{info.residuals[-1]:.3g} after {info.iterations} "
                    f"iterations, {info.residuals[0]:.3g} after the "
                    f"first). "
                    f"In float32 this happens for nearly singular systems "
                    f"such as S + 1e-6 M, whose rounding errors the coarse "
                    f"solve amplifies; solve in float64")
            if info.residuals[-1] < tol:
                info.converged = True
                break
        info.solve_time = time.perf_counter() - start
        if not info.converged:
            warning = ConvergenceWarning(
                max_iter=max_iter, method=method, criterion=criterion,
                residual=info.residuals[-1], tol=float(tol))
            info.reason = warning.reason()
            if strict:
                raise RuntimeError(str(warning))
            warnings.warn(warning, stacklevel=2)
        return X.reshape(b.shape)

    def _torch_levels(self, levels: _Levels, device, dtype) -> TorchLevels:
        key = (str(device), dtype)
        if key not in levels.torch:
            start = time.perf_counter()
            levels.torch[key] = TorchLevels(
                levels.A, self.prolongations, self.restrictions,
                levels.coarse, device, dtype)
            self.info.setup_time += time.perf_counter() - start
        return levels.torch[key]

    def as_preconditioner(self, A, cycle: str = 'V', pre: int = 2,
                          post: int = 2) -> LinearOperator:
        """One symmetric cycle from a zero guess, as a scipy
        :class:`~scipy.sparse.linalg.LinearOperator` for conjugate
        gradients (``scipy.sparse.linalg.cg(A, b, M=...)``)."""
        check_choice(cycle, 'cycle', CYCLES)
        levels = self.setup(A)
        n = levels.A[0].shape[0]

        def apply(r):
            r = np.asarray(r, dtype=np.float64).reshape(-1)
            if len(levels.A) == 1:
                return levels.coarse.solve(r)
            return self._cycle(levels, 0, r, np.zeros(n), cycle, pre, post,
                               post_sweep='backward')

        return LinearOperator((n, n), matvec=apply, dtype=np.float64)

    def __repr__(self) -> str:
        sizes = [self.num_points] + [P.shape[1] for P in self.prolongations]
        return f'{self.__class__.__name__}(levels={sizes})'
