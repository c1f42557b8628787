r"""Anisotropic (Perona-Malik) diffusion of signals on point clouds, built
from the MLS gradient and divergence of :mod:`.mls` and :mod:`.operators`:
the target of DeltaConv's anisotropic-filter experiment (thesis Fig. 3.2)."""
import math
from typing import Optional

import torch
from torch import Tensor

from ..checks import (check_choice, check_points, check_positive_float,
                      check_positive_int)
from .mls import build_mls_operators
from .operators import SurfaceOperators, vector_norm

CONDUCTANCES = ('rational', 'exp', 'none')


def conductance(s: Tensor, kappa: float, kind: str = 'rational') -> Tensor:
    r"""The edge-stopping function :math:`g` of Perona and Malik:
    :math:`1 / (1 + (s/\kappa)^2)` (:obj:`'rational'`),
    :math:`\exp(-(s/\kappa)^2)` (:obj:`'exp'`) or :math:`1`
    (:obj:`'none'`, heat diffusion)."""
    if kind == 'rational':
        return 1 / (1 + (s / kappa) ** 2)
    if kind == 'exp':
        return torch.exp(-(s / kappa) ** 2)
    return torch.ones_like(s)


def spectral_radius(operators: SurfaceOperators, iterations: int = 60,
                    seed: int = 0) -> float:
    r"""The largest magnitude :math:`\rho` of an eigenvalue of the point
    cloud Laplacian :math:`-DG`, by power iteration from a random start
    (a few percent low at worst after 60 iterations; the Laplacian of MLS
    operators is not symmetric, so this is an estimate)."""
    n = operators.num_nodes
    dtype = operators.G.values.dtype
    device = operators.G.values.device
    gen = torch.Generator().manual_seed(seed)
    x = torch.randn(n, 1, generator=gen, dtype=dtype).to(device)
    x = x / x.norm()
    rho = 0.0
    for _ in range(iterations):
        y = operators.laplacian(x)
        rho = float(y.norm())
        if rho == 0:
            return 0.0
        x = y / rho
    return rho


def perona_malik_step(u: Tensor, operators: SurfaceOperators, dt: float,
                      kappa: float, kind: str = 'rational') -> Tensor:
    r"""One explicit step of :func:`perona_malik`,
    :math:`u + \delta t\, D\big(g(\|Gu\|)\, Gu\big)`, for ``u``
    :math:`(N, C)` (every channel diffuses on its own)."""
    g_u = operators.grad(u)  # [N, C, 2]
    flux = conductance(vector_norm(g_u, eps=0.0), kappa, kind)[..., None] \
        * g_u
    return u + dt * operators.div(flux)


def perona_malik(pos: Tensor, signal: Tensor, steps: int = 20,
                 dt: Optional[float] = None, kappa: float = 0.5,
                 kind: str = 'rational', k: int = 20,
                 normal: Optional[Tensor] = None,
                 batch: Optional[Tensor] = None,
                 operators: Optional[SurfaceOperators] = None) -> Tensor:
    r"""Anisotropic diffusion of Perona and Malik ("Scale-space and edge
    detection using anisotropic diffusion", 1990) of a signal on a point
    cloud, by explicit steps. Each step is

    .. math::
        u^{t+1} = u^t + \delta t\, \operatorname{div}\big(
        g(\|\nabla u^t\|)\, \nabla u^t\big), \qquad
        g(s) = \frac{1}{1 + (s/\kappa)^2}\ \text{or}\ e^{-(s/\kappa)^2},

    with the MLS gradient :math:`G` and divergence :math:`D` of
    :func:`~tg_intrinsic.geometry.pointcloud.build_mls_operators`
    (:obj:`k` neighbours, :obj:`normalized=False`: true derivatives per
    unit length). Where the gradient is large (an edge) the
    conductance is small and the edge stays; flat regions are smoothed as
    by the heat equation (:obj:`kind='none'` is exactly the heat step
    :math:`u + \delta t\, DGu`).

    Explicit steps are stable only while :math:`\delta t\, \rho < 2`, with
    :math:`\rho` the spectral radius of :math:`-DG` (as :math:`g \le 1`,
    the heat step's bound holds for every :math:`g`); :math:`\rho` is
    estimated by power iteration (:func:`spectral_radius`) and a larger
    :obj:`dt` is refused with the bound. :obj:`dt=None` takes
    :math:`\delta t = 1 / \rho`.

    Args:
        pos (Tensor): Points :math:`(N, 3)`.
        signal (Tensor): Values :math:`(N)` or :math:`(N, C)`.
        steps (int, optional): Number of steps. (default: :obj:`20`)
        dt (float, optional): Step size. (default: :obj:`None`)
        kappa (float, optional): Edge threshold :math:`\kappa` of
            :math:`g`, in units of the signal per unit length.
            (default: :obj:`0.5`)
        kind (str, optional): :obj:`'rational'`, :obj:`'exp'` or
            :obj:`'none'`. (default: :obj:`'rational'`)
        k (int, optional): Neighbours of the MLS operators.
            (default: :obj:`20`)
        normal (Tensor, optional): Normals :math:`(N, 3)`; estimated if not
            given. (default: :obj:`None`)
        batch (Tensor, optional): Example of every point.
            (default: :obj:`None`)
        operators (SurfaceOperators, optional): Operators built on ``pos``
            already (then :obj:`k`, :obj:`normal` and :obj:`batch` are not
            used). (default: :obj:`None`)

    Returns:
        The diffused signal, shaped like ``signal``.
    """
    pos = check_points(pos)
    steps = check_positive_int(steps, 'steps', minimum=0)
    kappa = check_positive_float(kappa, 'kappa')
    kind = check_choice(kind, 'kind', CONDUCTANCES)
    if not isinstance(signal, Tensor) or signal.dim() not in (1, 2) \
            or signal.size(0) != pos.size(0):
        raise ValueError(f"'signal' must be a tensor [N] or [N, C] with "
                         f"N = {pos.size(0)} (one row per point), got "
                         f"{getattr(signal, 'shape', type(signal))}")
    if not signal.is_floating_point() \
            or not bool(torch.isfinite(signal).all()):
        raise ValueError("'signal' must be a finite floating point tensor")
    u = signal.to(pos.dtype)
    u = u[:, None] if u.dim() == 1 else u
    if operators is None:
        edge_index, _, gw, dw = build_mls_operators(
            pos, k, batch, normal, normalized=False)
        operators = SurfaceOperators(edge_index, gw, dw, pos.size(0))
    elif not isinstance(operators, SurfaceOperators) \
            or operators.num_nodes != pos.size(0):
        raise ValueError("'operators' must be SurfaceOperators built on "
                         "'pos'")
    rho = spectral_radius(operators)
    bound = 2 / rho if rho > 0 else math.inf
    if dt is None:
        dt = 0.5 * bound if math.isfinite(bound) else 1.0
    dt = check_positive_float(dt, 'dt')
    if dt >= bound:
        raise ValueError(f"'dt' = {dt:.4g} is too large for explicit steps: "
                         f"they are stable only below 2 / rho = "
                         f"{bound:.4g} (rho = {rho:.4g}, the spectral radius "
                         f"of the point cloud Laplacian); take a smaller dt "
                         f"and more steps")
    for _ in range(steps):
        u = perona_malik_step(u, operators, dt, kappa, kind)
    return u[:, 0] if signal.dim() == 1 else u


__all__ = ['perona_malik', 'perona_malik_step', 'spectral_radius',
           'conductance']
