import hashlib
from collections import OrderedDict
from typing import Optional, Tuple

import numpy as np
import scipy.sparse as sp
import torch
from torch import Tensor
from torch.nn import Parameter
from torch_geometric.data import Data

from tg_intrinsic.geometry import knn
from tg_intrinsic.geometry.checks import (check_batch, check_choice,
                                          check_float_tensor, check_points,
                                          check_positive_float,
                                          check_positive_int, check_rows,
                                          check_tensor)
from tg_intrinsic.solvers import GravoMG, diffuse, stiffness_and_mass
from tg_intrinsic.surface_attributes import surface_graph

SOLVERS = ('gravo', 'direct')

# Neighbours per point of the graph a point cloud's hierarchy is built on
# (surface_graph's default, here also per example of a batch).
HIERARCHY_NEIGHBOURS = 8


class GravoDiffusion(torch.nn.Module):
    r"""Learned heat diffusion with one time per channel, solved by Gravo
    MG. It is the learned diffusion layer of DiffusionNet (Sharp et al.,
    "DiffusionNet: Discretization Agnostic Learning on Surfaces", TOG 2022)
    in its implicit form, on the multigrid solver of Wiersma et al.
    ("A Fast Geometric Multigrid Method for Curved Surfaces", SIGGRAPH
    2023) instead of a dense or spectral solve. Every channel :math:`c` of
    :math:`x` is diffused for its own learned time :math:`t_c \geq 0`:

    .. math::
        (M + t_c S)\, u_c = M x_c, \qquad t_c = |\theta_c|,

    with the stiffness matrix :math:`S` and lumped masses :math:`M` of
    :func:`~tg_intrinsic.solvers.stiffness_and_mass` (cotan Laplacian for
    manifold meshes, the robust Laplacian for point clouds and
    non-manifold meshes). :math:`\theta` is the parameter
    ``diffusion_time``, initialised to :obj:`init_time` (DiffusionNet's
    0), its absolute value taken with derivative :math:`+1` at 0 so a
    time that starts at 0 can grow (a checkpoint of DiffusionNet's
    ``LearnedTimeDiffusion``, whose times are clamped to be positive,
    loads as it is). Times are in units of area: normalise the surfaces
    (e.g. :class:`~tg_intrinsic.transforms.NormalizeArea`).

    The output is differentiable with respect to :math:`x` and
    :math:`\theta`: the backward pass solves the adjoint systems (the
    matrices are symmetric) with the same hierarchy, see
    :func:`~tg_intrinsic.solvers.diffuse`; the gradients are as accurate
    as the solves, to the relative residual :obj:`tol`. With
    :obj:`solver='direct'` the systems are factorised by scipy's sparse LU
    instead (the peer; exact to rounding). The solves run on the CPU in
    float64; inputs on another device are moved there and the output and
    gradients come back to theirs.

    The operators of ``data`` (and its hierarchy, built on its mesh edges
    or :math:`k`-nearest-neighbour graph, or read from the levels of
    :class:`~tg_intrinsic.transforms.GravoHierarchy` if present) are built
    on first use and kept for the last :obj:`cache_size` surfaces, found
    again by a hash of their positions and connectivity. Batches of meshes
    and of point clouds work as they are (a point cloud's Laplacian is
    built per example). Precomputed ``stiffness`` and ``mass`` (and a
    ``gravo`` solver on the same points) may be passed instead.

    Args:
        channels (int): Number of channels :math:`C`, each with its own
            time.
        solver (str, optional): ``'gravo'`` (Gravo MG) or ``'direct'``
            (sparse LU). (default: :obj:`'gravo'`)
        init_time (float, optional): Initial diffusion time of every
            channel, :math:`\geq 0`. (default: :obj:`0.0`)
        tol (float, optional): Relative residual of every Gravo MG solve,
            forward and backward. (default: :obj:`1e-8`)
        robust (bool, optional): Force (or forbid) the robust Laplacian;
            default: :func:`~tg_intrinsic.solvers.systems.
            uses_robust_laplacian`. (default: :obj:`None`)
        ratio (float, optional): Hierarchy reduction per level, when it is
            built here. (default: :obj:`8.0`)
        lower_bound (int, optional): Smallest hierarchy level, when it is
            built here; smaller surfaces are solved directly.
            (default: :obj:`1000`)
        cache_size (int, optional): Surfaces whose operators are kept.
            (default: :obj:`8`)

    Shapes:
        - **input:** features :math:`(N, C)`, ``data`` with ``pos``
          :math:`(N, 3)` and optionally ``face`` :math:`(3, F)` and
          ``batch`` :math:`(N)`, or ``stiffness`` :math:`(N, N)` (scipy
          sparse) and ``mass`` :math:`(N)`
        - **output:** :math:`(N, C)`, dtype and device of the features
    """
    def __init__(self, channels: int, solver: str = 'gravo',
                 init_time: float = 0.0, tol: float = 1e-8,
                 robust: Optional[bool] = None, ratio: float = 8.0,
                 lower_bound: int = 1000, cache_size: int = 8):
        super().__init__()
        self.channels = check_positive_int(channels, 'channels')
        self.solver = check_choice(solver, 'solver', SOLVERS)
        self.init_time = check_positive_float(init_time, 'init_time',
                                              allow_zero=True)
        self.tol = check_positive_float(tol, 'tol')
        self.robust = robust
        self.ratio = check_positive_float(ratio, 'ratio')
        self.lower_bound = check_positive_int(lower_bound, 'lower_bound')
        self.cache_size = check_positive_int(cache_size, 'cache_size')
        self.diffusion_time = Parameter(torch.empty(self.channels))
        self._surfaces: 'OrderedDict[str, list]' = OrderedDict()
        self.reset_parameters()

    def reset_parameters(self):
        torch.nn.init.constant_(self.diffusion_time, self.init_time)

    @property
    def time(self) -> Tensor:
        r"""The diffusion times :math:`t = |\theta|`, :math:`(C)`, with
        derivative :math:`+1` at :math:`\theta = 0`."""
        theta = self.diffusion_time
        return torch.where(theta < 0, -theta, theta)

    def forward(self, x: Tensor, data: Optional[Data] = None,
                stiffness: Optional[sp.spmatrix] = None,
                mass=None, gravo: Optional[GravoMG] = None) -> Tensor:
        r"""Diffuses every channel of :obj:`x` for its own learned time.

        The surface is that of :obj:`data`, or given by :obj:`stiffness`
        and :obj:`mass` (and, for Gravo MG, the :obj:`gravo` solver or the
        hierarchy of :obj:`data`).

        Args:
            x (torch.Tensor): Features :math:`(N, C)`, one row per point.
            data (torch_geometric.data.Data, optional): The surface, with
                ``pos`` :math:`(N, 3)` and optionally ``face``
                :math:`(3, F)` and ``batch`` :math:`(N)`; its operators and
                hierarchy are built on first use and cached.
                (default: :obj:`None`)
            stiffness (scipy.sparse.spmatrix, optional): A precomputed
                stiffness matrix :math:`S` :math:`(N, N)`, passed together
                with :obj:`mass`. (default: :obj:`None`)
            mass (numpy.ndarray or torch.Tensor, optional): The lumped
                masses :math:`M` :math:`(N)`. (default: :obj:`None`)
            gravo (GravoMG, optional): A Gravo MG solver on the same points;
                without it, the hierarchy of :obj:`data` is used. Not
                allowed with :obj:`solver='direct'`. (default: :obj:`None`)

        Returns:
            torch.Tensor: The diffused features :math:`(N, C)`, in the dtype
            and on the device of :obj:`x`.
        """
        x = check_tensor(x, 'x')
        if x.dim() != 2:
            raise ValueError(
                f"'x' must have shape [N, C] = [N, {self.channels}] (one "
                f"row per point, one column per channel), got "
                f"{list(x.shape)}; for a single signal pass x.unsqueeze(1) "
                f"to a layer with channels=1")
        if x.size(1) != self.channels:
            raise ValueError(
                f"'x' has {x.size(1)} channels but the layer was built "
                f"with channels={self.channels}; build it with "
                f"GravoDiffusion({x.size(1)}), or map the features to "
                f"{self.channels} channels first (e.g. with a Linear)")
        check_float_tensor(x, 'x', x.shape)
        if gravo is not None and self.solver == 'direct':
            raise ValueError("a 'gravo' solver was passed to a layer with "
                             "solver='direct'; build the layer with "
                             "solver='gravo', or leave 'gravo' out")
        if (stiffness is None) != (mass is None):
            raise ValueError("pass both 'stiffness' and 'mass' (e.g. from "
                             "stiffness_and_mass(data)), or neither and "
                             "'data'")
        if stiffness is None:
            if data is None:
                raise ValueError("nothing to diffuse on: pass 'data' (with "
                                 "pos, and face for a mesh), or "
                                 "'stiffness' and 'mass'")
            stiffness, mass, built = self.operators(data)
            gravo = built if gravo is None else gravo
        elif self.solver == 'gravo' and gravo is None:
            if data is None:
                raise ValueError("solver='gravo' needs a hierarchy: pass "
                                 "'data' (its points), or a prebuilt "
                                 "'gravo' (GravoMG.from_mesh / from_points)"
                                 ", or build the layer with "
                                 "solver='direct'")
            gravo = self._solver(self._entry(data), data)
        rows = stiffness.shape[0] if sp.issparse(stiffness) else x.size(0)
        check_rows(x, 'x', rows, "'data'" if data is not None
                   else "'stiffness'")
        return diffuse(stiffness, mass, x, self.time,
                       'direct' if self.solver == 'direct' else gravo,
                       tol=self.tol)

    def operators(self, data: Data) -> Tuple[sp.csr_matrix, np.ndarray,
                                             Optional[GravoMG]]:
        """The stiffness matrix, lumped masses and (for
        :obj:`solver='gravo'`, else None) the Gravo MG solver of ``data``,
        built on first use and cached (see above)."""
        entry = self._entry(data)
        if entry[0] is None:
            entry[0], entry[1] = _stiffness_and_mass(data, self.robust)
        gravo = self._solver(entry, data) if self.solver == 'gravo' \
            else None
        return entry[0], entry[1], gravo

    def _entry(self, data: Data) -> list:
        """The cache entry ``[stiffness, mass, gravo]`` of ``data`` (None
        until built), found by a hash of its points and connectivity."""
        check_points(data.pos)
        key = hashlib.blake2b(digest_size=16)
        for name in ('pos', 'face', 'edge_index', 'batch',
                     'prolong_index_1'):
            value = getattr(data, name, None)
            key.update(name.encode())
            if value is not None:
                key.update(np.ascontiguousarray(
                    value.detach().cpu().numpy()).tobytes())
        key.update(repr(self.robust).encode())
        key = key.hexdigest()
        if key in self._surfaces:
            self._surfaces.move_to_end(key)
        else:
            if len(self._surfaces) >= self.cache_size:
                self._surfaces.popitem(last=False)
            self._surfaces[key] = [None, None, None]
        return self._surfaces[key]

    def _solver(self, entry: list, data: Data) -> GravoMG:
        if entry[2] is None:
            if 'prolong_index_1' in data:
                gravo = GravoMG.from_data(data)
            else:
                gravo = GravoMG.from_points(
                    data.pos, _hierarchy_graph(data), ratio=self.ratio,
                    lower_bound=self.lower_bound)
            # one set-up per distinct time, all kept for the backward pass
            gravo.cache_size = max(gravo.cache_size, self.channels)
            entry[2] = gravo
        return entry[2]

    def __getstate__(self):
        # the cached operators and hierarchies (scipy and GravoMG objects)
        # stay out of a pickle; they are rebuilt on first use
        state = self.__dict__.copy()
        state['_surfaces'] = OrderedDict()
        return state

    def __repr__(self) -> str:
        return (f'{self.__class__.__name__}({self.channels}, '
                f'solver={self.solver!r}, tol={self.tol:g})')


def _examples(data: Data):
    """The sizes of the examples of a batched point cloud, or None."""
    batch = getattr(data, 'batch', None)
    if getattr(data, 'face', None) is not None or batch is None:
        return None
    batch = check_batch(batch, data.pos.size(0), data.pos)
    sizes = torch.bincount(batch.cpu())
    return sizes.tolist() if sizes.numel() > 1 else None


def _stiffness_and_mass(data: Data, robust: Optional[bool]):
    """:func:`stiffness_and_mass`, per example for a batch of point
    clouds: their k-nearest-neighbour Laplacians would join examples that
    overlap in space."""
    sizes = _examples(data)
    if sizes is None:
        return stiffness_and_mass(data, robust)
    parts = [stiffness_and_mass(Data(pos=pos), robust)
             for pos in torch.split(data.pos, sizes)]
    return (sp.block_diag([S for S, _ in parts], format='csr'),
            np.concatenate([m for _, m in parts]))


def _hierarchy_graph(data: Data) -> Tensor:
    """The graph the hierarchy is built on: :func:`surface_graph`, with
    the nearest neighbours searched per example for batched clouds."""
    if _examples(data) is None or \
            getattr(data, 'edge_index', None) is not None:
        return surface_graph(data, k=HIERARCHY_NEIGHBOURS)
    return knn(data.pos, HIERARCHY_NEIGHBOURS, data.batch)
