r"""Vector calculus on point clouds from per-edge gradient and divergence
weights (see :mod:`tg_intrinsic.geometry.mls`).

Scalar fields are ``[N, C]``; tangent vector fields are ``[N, C, 2]``, the
coordinates of every vector in its point's own frame :math:`(e_u, e_v)`.
Edges follow PyG's flow: ``edge_index[0]`` is the neighbour :math:`j`,
``edge_index[1]`` the centre :math:`i`.

Two interchangeable back ends apply the operators:

* :class:`SurfaceOperators` assembles :math:`G` and :math:`D` once as sparse
  CSR matrices and applies them with :func:`torch.sparse.mm` (the fast path,
  used by the layers);
* the functions :func:`grad`, :func:`div`, ... gather and scatter along the
  edges directly (the reference the tests compare against).

With :math:`J` the rotation by 90 degrees in every tangent plane, the
derived operators are

.. math::
    \operatorname{curl} = -D J, \qquad \Delta = -D G, \qquad
    \Delta_H = -(G D - J G D J).
"""
import warnings
from typing import Tuple

import torch
from torch import Tensor

# CSR matrix products are stable for what is used here (mm with a dense
# matrix, and its backward); the generic "beta" notice is noise for users.
warnings.filterwarnings('ignore', message='Sparse CSR tensor support is in '
                        'beta state')


def rotate_j(v: Tensor) -> Tensor:
    r"""Rotates every tangent vector by +90 degrees,
    :math:`J (a, b) = (-b, a)`.

    Shapes:
        - **input / output:** :math:`(N, C, 2)`
    """
    return torch.stack([-v[..., 1], v[..., 0]], dim=-1)


def grad(x: Tensor, edge_index: Tensor, grad_weight: Tensor) -> Tensor:
    r"""Gradient :math:`(G x)_i = \sum_j x_j \, G_{ij}` by scatter.

    Shapes:
        - **input:** x :math:`(N, C)`, edge_index :math:`(2, E)`,
          grad_weight :math:`(E, 2)`
        - **output:** :math:`(N, C, 2)`
    """
    j, i = edge_index
    msg = x[j].unsqueeze(-1) * grad_weight.unsqueeze(1)
    out = x.new_zeros(x.size(0), x.size(1), 2)
    return out.index_add_(0, i, msg)


def div(v: Tensor, edge_index: Tensor, div_weight: Tensor) -> Tensor:
    r"""Divergence :math:`(D v)_i = \sum_j D_{ij} \cdot v_j` by scatter.

    Shapes:
        - **input:** v :math:`(N, C, 2)`, edge_index :math:`(2, E)`,
          div_weight :math:`(E, 2)`
        - **output:** :math:`(N, C)`
    """
    j, i = edge_index
    msg = (v[j] * div_weight.unsqueeze(1)).sum(-1)
    out = v.new_zeros(v.size(0), v.size(1))
    return out.index_add_(0, i, msg)


def curl(v: Tensor, edge_index: Tensor, div_weight: Tensor) -> Tensor:
    r"""Curl :math:`-D J v` (scalar, :math:`(N, C)`)."""
    return -div(rotate_j(v), edge_index, div_weight)


def laplacian(x: Tensor, edge_index: Tensor, grad_weight: Tensor,
              div_weight: Tensor) -> Tensor:
    r"""Laplace-Beltrami :math:`-D G x` (positive semi-definite sign)."""
    return -div(grad(x, edge_index, grad_weight), edge_index, div_weight)


def hodge_laplacian(v: Tensor, edge_index: Tensor, grad_weight: Tensor,
                    div_weight: Tensor) -> Tensor:
    r"""Hodge Laplacian :math:`-(G D - J G D J) v` on tangent fields."""
    gd = grad(div(v, edge_index, div_weight), edge_index, grad_weight)
    jgdj = rotate_j(grad(div(rotate_j(v), edge_index, div_weight),
                         edge_index, grad_weight))
    return -(gd - jgdj)


class SurfaceOperators:
    r"""Gradient and divergence of a (batched) point cloud as sparse CSR
    matrices, built once and shared by every layer of a network.

    :math:`G` is stored as a :math:`(2N, N)` matrix whose rows :math:`2i` and
    :math:`2i + 1` give the :math:`e_u` and :math:`e_v` components at
    :math:`i`; :math:`D` as :math:`(N, 2N)`. Vector fields are converted
    from and to ``[N, C, 2]`` at the boundary.

    Args:
        edge_index (torch.Tensor): Graph the weights live on
            (``edge_index[0]`` neighbour :math:`j`, ``edge_index[1]`` centre
            :math:`i`).
        grad_weight (torch.Tensor): :math:`(E, 2)` gradient weights.
        div_weight (torch.Tensor): :math:`(E, 2)` divergence weights.
        num_nodes (int): Number of points :math:`N`.
    """
    def __init__(self, edge_index: Tensor, grad_weight: Tensor,
                 div_weight: Tensor, num_nodes: int):
        j, i = edge_index
        n = num_nodes
        two = torch.arange(2, device=j.device)
        g_row = (2 * i).unsqueeze(1) + two  # [E, 2]
        g_col = j.unsqueeze(1).expand(-1, 2)
        self.G = _csr(g_row.reshape(-1), g_col.reshape(-1),
                      grad_weight.reshape(-1), (2 * n, n))
        d_row = i.unsqueeze(1).expand(-1, 2)
        d_col = (2 * j).unsqueeze(1) + two
        self.D = _csr(d_row.reshape(-1), d_col.reshape(-1),
                      div_weight.reshape(-1), (n, 2 * n))
        self.num_nodes = n

    def grad(self, x: Tensor) -> Tensor:
        """:math:`G x`: ``[N, C]`` -> ``[N, C, 2]``."""
        out = torch.sparse.mm(self.G, x)  # [2N, C]
        return out.view(self.num_nodes, 2, -1).transpose(1, 2)

    def div(self, v: Tensor) -> Tensor:
        """:math:`D v`: ``[N, C, 2]`` -> ``[N, C]``."""
        flat = v.transpose(1, 2).reshape(2 * self.num_nodes, -1)
        return torch.sparse.mm(self.D, flat)

    def curl(self, v: Tensor) -> Tensor:
        """:math:`-D J v`: ``[N, C, 2]`` -> ``[N, C]``."""
        return -self.div(rotate_j(v))

    def laplacian(self, x: Tensor) -> Tensor:
        """:math:`-D G x`: ``[N, C]`` -> ``[N, C]``."""
        return -self.div(self.grad(x))

    def hodge_laplacian(self, v: Tensor) -> Tensor:
        """:math:`-(G D - J G D J) v`: ``[N, C, 2]`` -> ``[N, C, 2]``."""
        # Both terms share G: stack D v and D J v along channels.
        c = v.size(1)
        both = self.grad(torch.cat([self.div(v), self.div(rotate_j(v))], 1))
        return rotate_j(both[:, c:]) - both[:, :c]

    def to(self, device) -> 'SurfaceOperators':
        self.G, self.D = self.G.to(device), self.D.to(device)
        return self

    def __repr__(self) -> str:
        return (f'{self.__class__.__name__}(num_nodes={self.num_nodes}, '
                f'nnz={self.G._nnz()})')


def _csr(row: Tensor, col: Tensor, value: Tensor,
         size: Tuple[int, int]) -> Tensor:
    coo = torch.sparse_coo_tensor(torch.stack([row, col]), value, size,
                                  check_invariants=False).coalesce()
    return coo.to_sparse_csr()
