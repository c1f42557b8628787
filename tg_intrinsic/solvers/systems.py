r"""Laplace-type systems on the surface of a :class:`~torch_geometric.data.
Data` and their solution with :class:`GravoMG`: stiffness and mass
matrices, smoothing :math:`(M + \alpha S) x = M y` and the screened Poisson
problem :math:`(S + \eta M) x = M y`."""
from typing import Optional, Tuple

import numpy as np
import scipy.sparse as sp
import torch
from torch import Tensor

from tg_intrinsic.geometry import cotan_laplacian, lumped_mass, to_scipy
from tg_intrinsic.geometry._checks import check_points
from tg_intrinsic.geometry.mesh import edge_face_counts
from tg_intrinsic.solvers.gravo_mg import GravoMG
from tg_intrinsic.transforms.gravo_hierarchy import GravoHierarchy


def stiffness_and_mass(data, robust: Optional[bool] = None
                       ) -> Tuple[sp.csr_matrix, np.ndarray]:
    r"""The positive semi-definite stiffness matrix :math:`S` and lumped
    masses :math:`M` of ``data``: the cotan Laplacian of ``face`` for
    manifold meshes, else (point clouds, non-manifold meshes, or
    ``robust=True``) the robust Laplacian of Sharp and Crane (2020,
    package ``robust-laplacian``), which stays well behaved on obtuse and
    non-manifold triangles."""
    pos = check_points(data.pos)
    face = getattr(data, 'face', None)
    if robust is None:
        robust = face is None or bool(
            (edge_face_counts(face, pos.size(0))[1] > 2).any())
    if not robust:
        S = to_scipy(cotan_laplacian(pos.double().cpu(), face.cpu()))
        return S.tocsr(), lumped_mass(pos.double().cpu(), face.cpu()).numpy()
    try:
        import robust_laplacian
    except ImportError as error:  # pragma: no cover (a dependency)
        raise ImportError("the robust Laplacian needs the robust-laplacian "
                          "package: pip install robust-laplacian") from error
    p = pos.detach().double().cpu().numpy()
    if face is None:
        S, M = robust_laplacian.point_cloud_laplacian(p)
    else:
        S, M = robust_laplacian.mesh_laplacian(p, face.t().cpu().numpy())
    return sp.csr_matrix(S), M.diagonal()


def _solve(data, matrix, mass, y, solver, tol):
    y = data.x if y is None else y
    if y is None:
        raise ValueError("nothing to solve for: pass y or set data.x")
    values = y.detach().double().cpu().numpy()
    if values.shape[0] != mass.size:
        raise ValueError(f"'y' has {values.shape[0]} rows but the surface "
                         f"has {mass.size} points")
    if solver is None:
        if 'prolong_index_1' not in data:
            data = GravoHierarchy()(data)
        solver = GravoMG.from_data(data)
    columns = values.reshape(mass.size, -1)
    out = np.stack([solver.solve(matrix, mass * column, tol=tol)
                    for column in columns.T], 1)  # a loop over channels
    return torch.from_numpy(out.reshape(values.shape)).to(y.dtype).to(
        y.device)


def smooth(data, alpha: float, y: Optional[Tensor] = None,
           solver: Optional[GravoMG] = None, tol: float = 1e-8,
           robust: Optional[bool] = None) -> Tensor:
    r"""Implicit smoothing of the signal :math:`y` (default ``data.x``,
    :math:`(N)` or :math:`(N, C)`):

    .. math::
        (M + \alpha S)\, x = M y,

    solved with Gravo MG on the hierarchy of ``data`` (built with
    :class:`~tg_intrinsic.transforms.GravoHierarchy` when absent) or with
    the given :obj:`solver`."""
    if not alpha > 0:
        raise ValueError(f"'alpha' must be positive, got {alpha!r}")
    S, m = stiffness_and_mass(data, robust)
    return _solve(data, (sp.diags(m) + alpha * S).tocsr(), m, y, solver,
                  tol)


def poisson(data, eta: float, y: Optional[Tensor] = None,
            solver: Optional[GravoMG] = None, tol: float = 1e-8,
            robust: Optional[bool] = None) -> Tensor:
    r"""The screened Poisson problem with right-hand side :math:`y`
    (default ``data.x``):

    .. math::
        (S + \eta M)\, x = M y,

    with :math:`\eta > 0` (without it :math:`S` is singular), solved as in
    :func:`smooth`."""
    if not eta > 0:
        raise ValueError(f"'eta' must be positive (S alone is singular), "
                         f"got {eta!r}")
    S, m = stiffness_and_mass(data, robust)
    return _solve(data, (S + eta * sp.diags(m)).tocsr(), m, y, solver, tol)
