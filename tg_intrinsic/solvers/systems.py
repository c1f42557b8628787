r"""Laplace-type systems on the surface of a :class:`~torch_geometric.data.
Data` and their solution with :class:`GravoMG`: stiffness and mass
matrices, smoothing :math:`(M + \alpha S + \beta S M^{-1} S) x = M y` and
the screened Poisson problem :math:`(S + \eta M) x = M y`, the heat step
with a time per channel :math:`(M + t_c S) u_c = M y_c`, and the
conformalized mean curvature flow, whose matrix changes every step. The
first three are differentiable (adjoint solves on the same hierarchy)."""
import math
import numbers
import warnings
from functools import partial
from typing import Optional, Tuple, Union

import numpy as np
import scipy.sparse as sp
import torch
from scipy.sparse.linalg import splu
from torch import Tensor
from torch_geometric.data import Data

from tg_intrinsic.geometry import cotan_laplacian, lumped_mass, to_scipy
from tg_intrinsic.geometry.checks import (check_choice, check_points,
                                          check_positive_int, check_tensor)
from tg_intrinsic.geometry.mesh import edge_face_counts
from tg_intrinsic.solvers._adjoint import linear_solve
from tg_intrinsic.solvers.gravo_mg import GravoMG, SolveInfo
from tg_intrinsic.surface_attributes import surface_graph


def uses_robust_laplacian(data, robust: Optional[bool] = None) -> bool:
    """Whether :func:`stiffness_and_mass` takes the robust Laplacian for
    ``data``: :obj:`robust` when given, else for point clouds (no
    ``face``) and for meshes with an edge shared by more than two
    triangles."""
    if robust is not None:
        return bool(robust)
    face = getattr(data, 'face', None)
    if face is None:
        return True
    pos = check_points(data.pos)
    return bool((edge_face_counts(face, pos.size(0))[1] > 2).any())


def stiffness_and_mass(data, robust: Optional[bool] = None
                       ) -> Tuple[sp.csr_matrix, np.ndarray]:
    r"""The positive semi-definite stiffness matrix :math:`S` and lumped
    masses :math:`M` of ``data``: the cotan Laplacian of ``face`` for
    manifold meshes, else (point clouds, non-manifold meshes, or
    ``robust=True``) the robust Laplacian of Sharp and Crane (2020,
    package ``robust-laplacian``), which stays well behaved on obtuse and
    non-manifold triangles (see :func:`uses_robust_laplacian`)."""
    pos = check_points(data.pos)
    face = getattr(data, 'face', None)
    if not uses_robust_laplacian(data, robust):
        S = to_scipy(cotan_laplacian(pos.double().cpu(), face.cpu()))
        return S.tocsr(), lumped_mass(pos.double().cpu(), face.cpu()).numpy()
    try:
        import robust_laplacian
    except ImportError as error:  # pragma: no cover (a dependency)
        raise ImportError("the robust Laplacian needs the robust-laplacian "
                          "package: pip install robust-laplacian") from error
    p = pos.detach().double().cpu().numpy()
    if face is None:
        if len(p) <= POINT_CLOUD_NEIGHBOURS:
            raise ValueError(
                f"a point cloud of {len(p)} points is too small for the "
                f"robust Laplacian, which connects every point to its "
                f"{POINT_CLOUD_NEIGHBOURS} nearest neighbours; give at least "
                f"{POINT_CLOUD_NEIGHBOURS + 1} points, or a triangle mesh")
        S, M = robust_laplacian.point_cloud_laplacian(
            p, n_neighbors=POINT_CLOUD_NEIGHBOURS)
    else:
        S, M = robust_laplacian.mesh_laplacian(p, face.t().cpu().numpy())
    return sp.csr_matrix(S), M.diagonal()


def _default_solver(data, ratio: float, lower_bound: int) -> GravoMG:
    """The levels of ``data`` (GravoHierarchy) if present, else a
    hierarchy on its surface graph."""
    if 'prolong_index_1' in data:
        return GravoMG.from_data(data)
    return GravoMG.from_points(data.pos, surface_graph(data), ratio=ratio,
                               lower_bound=lower_bound)


def _product(matrix: sp.spmatrix):
    """X -> matrix @ X for float64 tensors (the product runs on the CPU,
    the result comes back to X's device)."""
    def apply(X: Tensor) -> Tensor:
        return torch.from_numpy(matrix @ X.cpu().numpy()).to(X.device)
    return apply


def _gravo_solve(solver: GravoMG, matrix: sp.csr_matrix, tol: float,
                 cycle: str, max_iter: int, method: str):
    """rhs -> the solution of ``matrix x = rhs`` by ``solver`` (all
    columns in one block solve, so ``solver.info`` describes it; not
    converging warns there), on the CPU, back on rhs's device. The
    matrices here are symmetric (:meth:`GravoMG.setup` refuses any
    other), so it is its own adjoint."""
    def solve(rhs: Tensor) -> Tensor:
        out = solver.solve(matrix, rhs.cpu().numpy(), tol=tol, cycle=cycle,
                           max_iter=max_iter, method=method)
        return torch.from_numpy(out).to(rhs.device)
    return solve


def _solve(data, matrix, mass, y, solver, tol, ratio, lower_bound, cycle,
           max_iter, method, weight=None, direction=None):
    """Solves ``matrix x = M y`` on the CPU, differentiable with respect
    to ``y`` and ``weight`` (``matrix = A_0 + weight * D``, ``direction``
    the product with D) when they require grad."""
    y = data.x if y is None else y
    if y is None:
        raise ValueError("nothing to solve for: pass y or set data.x")
    y = check_tensor(y, 'y')
    if y.dim() not in (1, 2) or y.size(0) != mass.size:
        raise ValueError(f"'y' has shape {tuple(y.shape)} (rows: "
                         f"{y.size(0) if y.dim() else 0}) but the "
                         f"surface has {mass.size} points; give (N) or "
                         f"(N, C) with one row per point")
    if not bool(torch.isfinite(y).all()):
        raise ValueError("'y' holds NaN or infinite values")
    if solver is None:
        solver = _default_solver(data, ratio, lower_bound)
    load = torch.from_numpy(mass).to(y.device)[:, None] * \
        y.double().reshape(mass.size, -1)
    solve = _gravo_solve(solver, matrix, tol, cycle, max_iter, method)
    out = linear_solve(load, solve, weight=weight, direction=direction)
    return out.reshape(y.shape).to(y.dtype)


# Neighbours of every point in the robust Laplacian of a point cloud (the
# package's default)
POINT_CLOUD_NEIGHBOURS = 30

# Rounding leaves S's row sums at ~1e-16 of its entries: a mass term below
# this share of the stiffness cannot be told from a singular matrix.
RESOLVABLE_MASS = 1e-12


def _check_scale(S: sp.csr_matrix, m: np.ndarray, parameter: str,
                 value: float, on_mass: bool):
    """The mass term must stand out of the stiffness term's rounding:
    ``value`` (named ``parameter``) weighs the mass term when ``on_mass``,
    else the stiffness term. Both are in absolute units, so a weight for
    another scale can make the system singular in float64; the message
    gives the usable bound and, for an extreme scale, the rescaling.
    The other way round, a Laplacian term below the mass term's rounding
    leaves the result the right-hand side: a warning with the bound."""
    ratio = m.max() / abs(S).max()
    share = value * ratio if on_mass else ratio / value
    area = m.sum()
    rescale = '' if 1e-6 <= area <= 1e6 else \
        ', or rescale the surface to about unit area (NormalizeArea)'
    if share * RESOLVABLE_MASS > 1:
        bound = 1 / (RESOLVABLE_MASS * ratio) if on_mass else \
            ratio * RESOLVABLE_MASS
        warnings.warn(
            f"'{parameter}' = {value:.3g} is so "
            f"{'large' if on_mass else 'small'} for this surface (total "
            f"area {area:.3g}) that the Laplacian term is {1 / share:.1e} "
            f"of the mass term, below float64 rounding: the result is the "
            f"right-hand side{' over eta' if on_mass else ''}, unsmoothed; "
            f"use '{parameter}' {'at most' if on_mass else 'at least'} "
            f"{bound:.2g} for an effect{rescale}", stacklevel=3)
        return
    if share >= RESOLVABLE_MASS:
        return
    bound = RESOLVABLE_MASS / ratio if on_mass else ratio / RESOLVABLE_MASS
    raise ValueError(
        f"'{parameter}' = {value:.3g} is too {'small' if on_mass else 'large'}"
        f" for this surface (total area {area:.3g}): the mass term is "
        f"{share:.1e} of the stiffness term, below float64 rounding, so the "
        f"system is singular in practice; use '{parameter}' "
        f"{'at least' if on_mass else 'at most'} {bound:.2g}{rescale}")


def _check_weight(value, name: str) -> float:
    """A finite number >= 0 (a Python number, or a one-element
    floating-point tensor), as a float."""
    number = value
    if isinstance(value, Tensor):
        if value.numel() != 1 or not value.is_floating_point():
            raise ValueError(f"'{name}' given as a tensor must hold one "
                             f"floating-point value, got {value.dtype} of "
                             f"shape {list(value.shape)}")
        number = float(value.detach())
    if isinstance(number, bool) or not isinstance(number, numbers.Real) or \
            not math.isfinite(number) or number < 0:
        raise ValueError(f"'{name}' must be a finite number >= 0, got "
                         f"{value!r}")
    return float(number)


def smooth(data, alpha: Union[float, Tensor], y: Optional[Tensor] = None,
           solver: Optional[GravoMG] = None, tol: float = 1e-8,
           robust: Optional[bool] = None, beta: float = 0.0,
           ratio: float = 8.0, lower_bound: int = 1000, cycle: str = 'V',
           max_iter: int = 100, method: str = 'cycles',
           split: Optional[bool] = None) -> Tensor:
    r"""Implicit smoothing of the signal :math:`y` (default ``data.x``,
    :math:`(N)` or :math:`(N, C)`) with Laplacian and, for
    :math:`\beta > 0`, bi-Laplacian terms. It solves

    .. math::
        (M + \alpha S + \beta S M^{-1} S)\, x = M y,

    with the stiffness matrix :math:`S` and lumped masses :math:`M` of
    :func:`stiffness_and_mass`. One implicit step of the heat flow for
    :math:`\beta = 0` (implicit fairing when :math:`y` is ``data.pos``);
    the bi-Laplacian term damps high frequencies like
    :math:`\beta \lambda^2` instead of :math:`\alpha \lambda`, keeping more
    of the low ones. When :math:`\alpha^2 \geq 4 \beta` the matrix factors
    exactly into two Laplace-type matrices,

    .. math::
        M + \alpha S + \beta S M^{-1} S = (M + a S)\, M^{-1} (M + b S),
        \quad a, b = \tfrac{1}{2}\big(\alpha \pm
        \sqrt{\alpha^2 - 4 \beta}\big),

    and :obj:`split` solves the two in turn, each with the sparsity and
    the fast multigrid convergence of the Laplacian, instead of the
    bi-Laplacian's wider stencil. All :math:`C` channels are solved as one block with
    Gravo MG on the hierarchy of ``data`` (the levels of
    :class:`~tg_intrinsic.transforms.GravoHierarchy` if present, else built
    on :func:`~tg_intrinsic.surface_attributes.surface_graph` with
    :obj:`ratio` and :obj:`lower_bound`) or with the given :obj:`solver`,
    whose :attr:`~GravoMG.info` then describes the whole solve. A solve
    that does not reach :obj:`tol` warns (:class:`ConvergenceWarning`).

    Differentiable with respect to :math:`y` when it requires grad, and
    with respect to :math:`\alpha` when it is given as a tensor that
    requires grad (a learned diffusion time, as in DiffusionNet): for
    :math:`A x = M y` the backward pass solves the adjoint system with the
    same solver and hierarchy (every matrix here is symmetric, so
    :math:`A^\top = A`),

    .. math::
        \lambda = A^{-\top} \frac{\partial L}{\partial x}, \qquad
        \frac{\partial L}{\partial y} = M \lambda, \qquad
        \frac{\partial L}{\partial \alpha} = -\lambda^\top S x,

    (through both factors when split). The gradients are as accurate as
    the solves: to the relative residual :obj:`tol` (take e.g.
    :obj:`1e-12` for a finite-difference check). The solves run on the
    CPU in float64; a :math:`y` on another device is moved there and the
    result and its gradients come back to its device. After a backward
    pass :attr:`~GravoMG.info` describes the last adjoint solve.

    Args:
        data (Data): ``pos`` :math:`(N, 3)`, ``face`` :math:`(3, F)` for a
            mesh (else a point cloud), optionally ``x`` and a hierarchy.
        alpha (float or Tensor): Laplacian weight :math:`\alpha \geq 0`
            (time step, in units of area: scale it with the surface); a
            one-element tensor that requires grad makes it learnable.
        y (Tensor, optional): The signal; default ``data.x``.
            Differentiable.
        solver (GravoMG, optional): A solver on the points of ``data``.
        tol (float, optional): Relative residual to reach in every
            channel. (default: :obj:`1e-8`)
        robust (bool, optional): Force (or forbid) the robust Laplacian;
            default: :func:`uses_robust_laplacian`.
        beta (float, optional): Bi-Laplacian weight :math:`\beta \geq 0`;
            :math:`\alpha` may be zero when it is positive.
            (default: :obj:`0.0`)
        ratio (float, optional): Hierarchy reduction per level, when it is
            built here. (default: :obj:`8.0`)
        lower_bound (int, optional): Smallest hierarchy level, when it is
            built here; fewer points are solved directly.
            (default: :obj:`1000`)
        cycle (str, optional): ``'V'``, ``'W'`` or ``'F'``.
            (default: :obj:`'V'`)
        max_iter (int, optional): Most cycles (or iterations).
            (default: :obj:`100`)
        method (str, optional): ``'cycles'``, or ``'pcg'`` for conjugate
            gradients preconditioned by one cycle per iteration (fewer
            iterations for the bi-Laplacian; CPU only), see
            :meth:`GravoMG.solve`. (default: :obj:`'cycles'`)
        split (bool, optional): Solve the bi-Laplacian system as two
            Laplace-type solves (each to :obj:`tol`; :attr:`GravoMG.info`
            then sums both); needs :math:`\alpha^2 \geq 4 \beta`. Default:
            whenever that holds.

    Shapes:
        - **input:** ``y`` :math:`(N)` or :math:`(N, C)`
        - **output:** :math:`x` of the shape, dtype and device of ``y``
    """
    time = alpha if isinstance(alpha, Tensor) else None
    alpha, beta = _check_weight(alpha, 'alpha'), _check_weight(beta, 'beta')
    if alpha == 0 and beta == 0:
        raise ValueError("'alpha' must be positive (or zero with a positive "
                         "'beta'), got 0")
    S, m = stiffness_and_mass(data, robust)
    if not (m > 0).all():
        raise ValueError(f"{int((m <= 0).sum())} point(s) have no area, so "
                         f"M is singular; remove unreferenced vertices and "
                         f"degenerate triangles")
    if alpha > 0:
        _check_scale(S, m, 'alpha', alpha, on_mass=False)
    # dA / dalpha = S for the full system and for each factor, whose
    # weights a, b follow alpha through the square root; at the double
    # root alpha^2 = 4 beta that root's derivative is infinite (the
    # product's is not), so a differentiable alpha takes the full system.
    learned = time is not None and time.requires_grad and \
        torch.is_grad_enabled()
    double_root = alpha * alpha == 4 * beta
    can_split = beta > 0 and alpha * alpha >= 4 * beta and \
        not (learned and double_root)
    if split and not can_split:
        raise ValueError(f"split=True needs alpha^2 >= 4 beta (and beta > "
                         f"0) for real factors, and alpha^2 > 4 beta for a "
                         f"differentiable alpha; got alpha={alpha:g}, "
                         f"beta={beta:g}: leave split unset")
    weight = None if time is None else time.reshape(()).double()
    if can_split and split is not False:
        root = math.sqrt(alpha * alpha - 4 * beta)
        factors = ((alpha + root) / 2, (alpha - root) / 2)
        weights = (None, None)
        if weight is not None:
            root_weight = torch.sqrt(weight * weight - 4 * beta)
            weights = ((weight + root_weight) / 2,
                       (weight - root_weight) / 2)
        if solver is None:
            solver = _default_solver(data, ratio, lower_bound)
        infos = []
        for factor, factor_weight in zip(factors, weights):
            # The second solve's load M z is the first's mass-weighted
            # solution; both matrices are Laplace-type.
            y = _solve(data, (sp.diags(m) + factor * S).tocsr(), m, y,
                       solver, tol, ratio, lower_bound, cycle, max_iter,
                       method, factor_weight, _product(S))
            infos.append(solver.info)
        solver.info = combined_info(infos)
        return y
    A = sp.diags(m) + alpha * S
    if beta > 0:
        A = A + beta * (S @ sp.diags(1.0 / m) @ S)
        A = 0.5 * (A + A.T)  # exactly symmetric despite rounding
    return _solve(data, A.tocsr(), m, y, solver, tol, ratio, lower_bound,
                  cycle, max_iter, method, weight, _product(S))


def combined_info(infos) -> SolveInfo:
    """One :class:`SolveInfo` for solves run one after the other."""
    out = SolveInfo(converged=all(i.converged for i in infos),
                    cached=all(i.cached for i in infos))
    offset = 0.0
    for info in infos:
        out.iterations += info.iterations
        out.residuals += info.residuals
        out.times += [offset + info.setup_time + t for t in info.times]
        out.setup_time += info.setup_time
        out.solve_time += info.solve_time
        offset += info.setup_time + info.solve_time
        out.direct = out.direct or info.direct
        out.reason = out.reason or info.reason
    return out


def poisson(data, eta: float, y: Optional[Tensor] = None,
            solver: Optional[GravoMG] = None, tol: float = 1e-8,
            robust: Optional[bool] = None, ratio: float = 8.0,
            lower_bound: int = 1000, cycle: str = 'V',
            max_iter: int = 100, method: str = 'cycles') -> Tensor:
    r"""The screened Poisson problem with right-hand side :math:`y`
    (default ``data.x``, :math:`(N)` or :math:`(N, C)`). It solves

    .. math::
        (S + \eta M)\, x = M y,

    with :math:`\eta > 0` (without it :math:`S` is singular), solved as
    one block as in :func:`smooth`, whose arguments :obj:`solver`,
    :obj:`tol`, :obj:`robust`, :obj:`ratio`, :obj:`lower_bound`,
    :obj:`cycle`, :obj:`max_iter` and :obj:`method` mean the same here.
    Differentiable with respect to :math:`y` when it requires grad, by the
    adjoint solve on the same solver and hierarchy (the matrix is
    symmetric), :math:`\partial L / \partial y = M (S + \eta M)^{-1}
    \partial L / \partial x`, as accurate as :obj:`tol`; the solves run
    on the CPU and the result and gradient come back to the device of
    :math:`y`.

    Args:
        data (Data): As in :func:`smooth`.
        eta (float): Screening weight :math:`\eta > 0`, in units of
            1 / area (scale it with the surface).
        y (Tensor, optional): The right-hand side; default ``data.x``.
            Differentiable.

    Shapes:
        - **input:** ``y`` :math:`(N)` or :math:`(N, C)`
        - **output:** :math:`x` of the shape, dtype and device of ``y``
    """
    if isinstance(eta, bool) or not isinstance(eta, numbers.Real) or \
            not math.isfinite(eta) or not eta > 0:
        raise ValueError(f"'eta' must be positive (S alone is singular), "
                         f"got {eta!r}")
    S, m = stiffness_and_mass(data, robust)
    if (m > 0).all():
        _check_scale(S, m, 'eta', eta, on_mass=True)
    return _solve(data, (S + eta * sp.diags(m)).tocsr(), m, y, solver, tol,
                  ratio, lower_bound, cycle, max_iter, method)


def _as_times(time, channels: int):
    """``time`` (a number, or a tensor of one value or one per channel)
    as float64 values per channel, and the tensor they follow (None for
    a number)."""
    if isinstance(time, Tensor):
        if not time.is_floating_point() or time.dim() > 1 or \
                time.numel() not in (1, channels):
            raise ValueError(f"'time' must be one number or one floating-"
                             f"point value per channel ({channels}), got "
                             f"{time.dtype} of shape {list(time.shape)}")
        values = time.detach().double().cpu().reshape(-1).expand(channels)
        weight = time.reshape(-1).double().expand(channels)
    else:
        values = torch.full((channels, ), _check_weight(time, 'time'),
                            dtype=torch.float64)
        weight = None
    if not bool(torch.isfinite(values).all()) or bool((values < 0).any()):
        raise ValueError(f"'time' must be finite and >= 0 in every channel, "
                         f"got {values.tolist()}; a learned time that went "
                         f"NaN needs a smaller learning rate")
    return values, weight


def diffuse(stiffness: sp.spmatrix, mass, y: Tensor, time,
            solver: Union[GravoMG, str], tol: float = 1e-8,
            cycle: str = 'V', max_iter: int = 100,
            method: str = 'cycles') -> Tensor:
    r"""One implicit step of the heat flow for every channel of
    :math:`y`, each with its own time :math:`t_c \geq 0`. It solves

    .. math::
        (M + t_c S)\, u_c = M y_c,

    with a stiffness matrix :math:`S` and lumped masses :math:`M` (e.g.
    :func:`stiffness_and_mass`), solved by :obj:`solver`: a
    :class:`GravoMG` on the same points, or ``'direct'`` for scipy's
    sparse LU (:func:`~scipy.sparse.linalg.splu`). Channels with equal
    times share one block solve (one matrix set-up); other channels get a
    matrix each, so a :class:`GravoMG` with a :obj:`cache_size` of at
    least the number of distinct times keeps them all for the backward
    pass.

    Differentiable with respect to :math:`y` and, when :obj:`time` is a
    tensor that requires grad, :math:`t`: with
    :math:`\lambda_c = (M + t_c S)^{-\top} \partial L / \partial u_c`,
    solved with the same hierarchy (or LU factors) as the forward solve,

    .. math::
        \frac{\partial L}{\partial y_c} = M \lambda_c, \qquad
        \frac{\partial L}{\partial t_c} = -\lambda_c^\top S u_c .

    The matrices are symmetric (Gravo MG checks), so the adjoint is the
    same solve; the LU's is its transposed solve. The gradients are as
    accurate as the solves, to the relative residual :obj:`tol` with
    Gravo MG (to rounding with the LU). The solves run on the CPU in
    float64; :math:`y` and :obj:`time` on another device are moved there,
    and the result and gradients come back to their devices.

    Args:
        stiffness (scipy.sparse matrix): :math:`S`, :math:`(N, N)`,
            symmetric positive semi-definite.
        mass (numpy.ndarray or Tensor): The lumped masses, :math:`(N)`,
            positive.
        y (Tensor): The signal. Differentiable.
        time (float or Tensor): :math:`t`, one number for every channel
            or a tensor of one value or one per channel, :math:`\geq 0`,
            in units of area. Differentiable as a tensor.
        solver (GravoMG or str): A :class:`GravoMG` on the points, or
            ``'direct'``.
        tol (float, optional): Relative residual of every Gravo MG solve.
            (default: :obj:`1e-8`)
        cycle (str, optional): ``'V'``, ``'W'`` or ``'F'``.
            (default: :obj:`'V'`)
        max_iter (int, optional): Most cycles (or iterations).
            (default: :obj:`100`)
        method (str, optional): ``'cycles'`` or ``'pcg'``, see
            :meth:`GravoMG.solve`. (default: :obj:`'cycles'`)

    Shapes:
        - **input:** ``y`` :math:`(N)` or :math:`(N, C)`, ``time``
          :math:`()`, :math:`(1)` or :math:`(C)`
        - **output:** :math:`u` of the shape, dtype and device of ``y``
    """
    if not sp.issparse(stiffness) or stiffness.ndim != 2 or \
            stiffness.shape[0] != stiffness.shape[1]:
        raise ValueError(f"'stiffness' must be a square scipy sparse "
                         f"matrix, e.g. from stiffness_and_mass(data), got "
                         f"{type(stiffness).__name__} of shape "
                         f"{getattr(stiffness, 'shape', None)}")
    S = sp.csr_matrix(stiffness, dtype=np.float64)
    n = S.shape[0]
    m = mass.detach().double().cpu().numpy() if isinstance(mass, Tensor) \
        else np.asarray(mass, dtype=np.float64)
    if m.shape != (n, ) or not np.isfinite(m).all() or not (m > 0).all():
        raise ValueError(f"'mass' must hold one finite positive value per "
                         f"point ({n}), got shape {m.shape} with "
                         f"{int((~(m > 0)).sum())} value(s) that are not "
                         f"positive; remove unreferenced vertices and "
                         f"degenerate triangles")
    y = check_tensor(y, 'y')
    if y.dim() not in (1, 2) or y.size(0) != n or not y.is_floating_point():
        raise ValueError(f"'y' must be a float tensor of shape ({n}) or "
                         f"({n}, C), one row per point of 'stiffness', got "
                         f"{y.dtype} of shape {tuple(y.shape)}")
    if not bool(torch.isfinite(y).all()):
        raise ValueError("'y' holds NaN or infinite values; repair them "
                         "first")
    if isinstance(solver, str):
        check_choice(solver, 'solver', ('direct', ))
    elif not isinstance(solver, GravoMG):
        raise ValueError(f"'solver' must be a GravoMG or 'direct', got "
                         f"{type(solver).__name__}")
    columns = y.reshape(n, -1)
    times, weights = _as_times(time, columns.size(1))
    if float(times.max()) > 0:
        _check_scale(S, m, 'time', float(times.max()), on_mass=False)
    load = torch.from_numpy(m).to(y.device)[:, None] * columns.double()
    values, group = torch.unique(times, return_inverse=True)
    parts, order, infos = [], [], []
    for k, value in enumerate(values.tolist()):
        chosen = (group == k).nonzero().flatten()
        A = (sp.diags(m) + value * S).tocsr()
        if isinstance(solver, GravoMG):
            solve = adjoint = _gravo_solve(solver, A, tol, cycle, max_iter,
                                           method)
        else:
            factors = splu(A.tocsc())

            def solve(rhs: Tensor, factors=factors, trans='N') -> Tensor:
                out = factors.solve(rhs.cpu().numpy(), trans=trans)
                return torch.from_numpy(out).to(rhs.device)
            adjoint = partial(solve, trans='T')
        weight = None if weights is None else \
            weights[chosen.to(weights.device)]
        parts.append(linear_solve(load[:, chosen.to(load.device)], solve,
                                  adjoint, weight, _product(S)))
        order.append(chosen)
        if isinstance(solver, GravoMG):
            infos.append(solver.info)
    if infos:
        solver.info = combined_info(infos)
    out = torch.cat(parts, 1)[:, torch.argsort(torch.cat(order)).to(
        y.device)]
    return out.reshape(y.shape).to(y.dtype)


def _flow_masses(data, robust: bool) -> np.ndarray:
    """Lumped masses of the current positions, from the same Laplacian
    family as the flow's stiffness matrix."""
    if robust:
        return stiffness_and_mass(data, robust=True)[1]
    return lumped_mass(data.pos, data.face.cpu()).numpy()


def conformal_flow(data, step: float, steps: int = 10,
                   solver: Optional[GravoMG] = None, tol: float = 1e-8,
                   robust: Optional[bool] = None, normalize: bool = True,
                   ratio: float = 8.0, lower_bound: int = 1000,
                   cycle: str = 'V', max_iter: int = 100,
                   method: str = 'pcg', callback=None) -> Tensor:
    r"""Conformalized mean curvature flow of a mesh (Kazhdan, Solomon and
    Ben-Chen, 2012) by implicit steps: the stiffness matrix :math:`S_0` of
    the initial surface is kept and only the masses :math:`M_t` follow the
    flow, so the flow stays regular where mean curvature flow pinches.
    Each step solves

    .. math::
        (M_t + h\, S_0)\, p_{t+1} = M_t\, p_t .

    The matrix changes every step, so a direct solver must factorise it
    again each time; Gravo MG keeps its hierarchy (built once, on the
    initial surface) and only redoes the Galerkin products. With
    :obj:`normalize` each step is followed by moving the area-weighted
    centroid back to where it was and rescaling to the initial area (as
    the paper does; without it the surface shrinks to a point). A genus-0
    surface flows towards a round sphere; a round sphere stays one.

    Args:
        data (Data): ``pos`` :math:`(N, 3)` and ``face`` :math:`(3, F)` of
            a triangle mesh, optionally a hierarchy (GravoHierarchy).
        step (float): Time step :math:`h > 0`, in units of area (scale it
            with the surface).
        steps (int, optional): Number of steps. (default: :obj:`10`)
        solver (GravoMG, optional): A solver on the points of ``data``.
        tol (float, optional): Relative residual of every step.
            (default: :obj:`1e-8`)
        robust (bool, optional): Force (or forbid) the robust Laplacian;
            default: :func:`uses_robust_laplacian`.
        normalize (bool, optional): Keep the centroid and the area.
            (default: :obj:`True`)
        ratio (float, optional): Hierarchy reduction per level, when it is
            built here. (default: :obj:`8.0`)
        lower_bound (int, optional): Smallest hierarchy level, when it is
            built here. (default: :obj:`1000`)
        cycle (str, optional): ``'V'``, ``'W'`` or ``'F'``.
            (default: :obj:`'V'`)
        max_iter (int, optional): Most iterations per step.
            (default: :obj:`100`)
        method (str, optional): ``'pcg'`` or ``'cycles'``, see
            :meth:`GravoMG.solve`. (default: :obj:`'pcg'`)
        callback (callable, optional): Called after every step with the
            step number (from 1) and the solver's :class:`SolveInfo`.

    Shapes:
        - **input:** ``data.pos`` :math:`(N, 3)`, ``data.face``
          :math:`(3, F)`
        - **output:** positions after every step, the initial ones first,
          :math:`(\text{steps} + 1, N, 3)`, dtype and device of ``pos``
    """
    if getattr(data, 'face', None) is None:
        raise ValueError("conformal_flow needs a triangle mesh: 'data' has "
                         "no 'face' (the flow moves a surface's vertices by "
                         "its mean curvature; a point cloud has none)")
    if isinstance(step, bool) or not isinstance(step, numbers.Real) or \
            not math.isfinite(step) or not step > 0:
        raise ValueError(f"'step' must be a positive time step, got "
                         f"{step!r}")
    steps = check_positive_int(steps, 'steps')
    pos = check_points(data.pos)
    robust = uses_robust_laplacian(data, robust)
    S, m = stiffness_and_mass(data, robust)
    _check_scale(S, m, 'step', step, on_mass=False)
    if solver is None:
        solver = _default_solver(data, ratio, lower_bound)
    face = data.face.cpu()
    current = pos.detach().double().cpu().numpy()
    area = m.sum()
    centroid = m @ current / area
    out = [current]
    for t in range(1, steps + 1):
        if not (m > 0).all():
            raise ValueError(
                f"after {t - 1} steps {int((m <= 0).sum())} vertices have "
                f"no area (the flow collapsed triangles); take a smaller "
                f"'step' or fewer steps")
        A = (sp.diags(m) + step * S).tocsr()
        current = solver.solve(A, m[:, None] * current, x0=current, tol=tol,
                               cycle=cycle, max_iter=max_iter,
                               method=method)
        flowed = Data(pos=torch.from_numpy(current), face=face)
        m = _flow_masses(flowed, robust)
        if normalize:
            scale = math.sqrt(area / m.sum())
            current = (current - m @ current / m.sum()) * scale + centroid
            m = m * scale ** 2
        out.append(current)
        if callback is not None:
            callback(t, solver.info)
    return torch.from_numpy(np.stack(out)).to(pos.dtype).to(pos.device)
