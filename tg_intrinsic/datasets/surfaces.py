r"""Generated test surfaces of any size, for solvers and scaling runs."""
import math

import numpy as np
import torch
from torch_geometric.data import Data

from tg_intrinsic.geometry.checks import check_positive_int

from .common import shape_rng
def bumpy_torus(num_vertices: int = 204800, seed: int = 0) -> Data:
    r"""A closed torus (major radius 1, tube radius about 0.35) with random
    smooth bumps on the tube, triangulated on a regular :math:`n_u \times
    n_v` grid with :math:`n_u = 2 n_v` and :math:`n_u n_v \geq`
    :obj:`num_vertices`. The surface is

    .. math::
        \mathbf{x}(u, v) = \big((1 + r \cos v) \cos u,\ (1 + r \cos v)
        \sin u,\ r \sin v\big), \quad r(u, v) = 0.35 + \sum_{k=1}^{4}
        a_k \sin(m_k u + \varphi_k) \sin(n_k v + \psi_k),

    with integer frequencies (so the surface closes up), amplitudes
    :math:`a_k \le 0.03` and random phases drawn from :obj:`seed`.
    Every vertex has six neighbours; the mesh is a closed manifold of
    genus one.

    Args:
        num_vertices (int, optional): Least number of vertices.
            (default: :obj:`204800`, a 640 x 320 grid)
        seed (int, optional): The bumps. (default: :obj:`0`)

    Returns:
        :class:`~torch_geometric.data.Data` with ``pos`` :math:`(N, 3)`
        float64, ``face`` :math:`(3, 2N)` and ``uv`` :math:`(N, 2)` (the
        grid angles).
    """
    num_vertices = check_positive_int(num_vertices, 'num_vertices', 32)
    seed = check_positive_int(seed, 'seed', 0)
    n_v = max(4, math.ceil(math.sqrt(num_vertices / 2)))
    n_u = 2 * n_v
    rng = shape_rng(seed, 0)
    u = np.linspace(0, 2 * np.pi, n_u, endpoint=False)
    v = np.linspace(0, 2 * np.pi, n_v, endpoint=False)
    U, V = np.meshgrid(u, v, indexing='ij')
    r = np.full_like(U, 0.35)
    for amplitude in (0.03, 0.02, 0.012, 0.008):
        m, n = rng.integers(2, 12), rng.integers(1, 8)
        phase = rng.uniform(0, 2 * np.pi, 2)
        r += amplitude * np.sin(m * U + phase[0]) * np.sin(n * V + phase[1])
    pos = np.stack([(1 + r * np.cos(V)) * np.cos(U),
                    (1 + r * np.cos(V)) * np.sin(U), r * np.sin(V)], -1)
    index = np.arange(n_u * n_v).reshape(n_u, n_v)
    right = np.roll(index, -1, 0)
    up = np.roll(index, -1, 1)
    diagonal = np.roll(right, -1, 1)
    face = np.concatenate([
        np.stack([index, right, diagonal], 0).reshape(3, -1),
        np.stack([index, diagonal, up], 0).reshape(3, -1)], 1)
    return Data(pos=torch.from_numpy(pos.reshape(-1, 3)),
                face=torch.from_numpy(face).long(),
                uv=torch.from_numpy(np.stack([U, V], -1).reshape(-1, 2)))
