from typing import Optional, Tuple

import torch
from torch import Tensor
from torch_geometric.nn import MLP, MessagePassing

from tg_intrinsic.geometry.operators import SurfaceOperators, rotate_j
from tg_intrinsic.nn.vector_mlp import VectorMLP


def scalar_mlp(channels, plain_last: bool = False) -> MLP:
    """DeltaConv's scalar MLP: bias-free linear, batch norm, LeakyReLU(0.2)."""
    return MLP(channels, act='leaky_relu', act_kwargs={'negative_slope': 0.2},
               norm='batch_norm', bias=False, plain_last=plain_last)


def vector_norm(v: Tensor, eps: float = 1e-8) -> Tensor:
    """Length of every tangent vector, smooth at zero."""
    return (v.pow(2).sum(-1) + eps ** 2).sqrt()


class DeltaConv(MessagePassing):
    r"""The DeltaConv operator from the `"DeltaConv: Anisotropic Operators
    for Geometric Deep Learning on Point Clouds"
    <https://arxiv.org/abs/2111.08799>`_ paper (SIGGRAPH 2022), with a scalar
    and a vector stream:

    .. math::
        \mathbf{v}'_i &= h_0\big(\mathbf{v}, G\mathbf{x}, \Delta_H
        \mathbf{v}\big)_i

        \mathbf{x}'_i &= h_1\big(\mathbf{x}, D\mathbf{v}',
        \operatorname{curl} \mathbf{v}', \|\mathbf{v}'\|\big)_i +
        \max_{j \in \mathcal{N}(i)} h_2(\mathbf{x}_j),

    where :math:`G`, :math:`D` are the MLS gradient and divergence,
    :math:`\operatorname{curl} = -DJ`,
    :math:`\Delta_H = -(GD - JGDJ)` the Hodge Laplacian, :math:`h_1, h_2`
    scalar MLPs and :math:`h_0` a :class:`VectorMLP` applied to the inputs and
    their 90-degree rotations :math:`J(\cdot)`. Scalar outputs do not depend
    on the choice of tangent frames; vector outputs rotate with them.

    Edges follow PyG's flow: ``edge_index[0]`` is the neighbour :math:`j`,
    ``edge_index[1]`` the centre :math:`i`.

    Args:
        in_channels (int): Input channels (scalar and vector).
        out_channels (int): Output channels (scalar and vector).
        depth (int, optional): Layers of every MLP. (default: :obj:`1`)
        centralized (bool, optional): Use :math:`h_2(\mathbf{x}_j -
            \mathbf{x}_i)` in the maximum (a per-edge MLP).
            (default: :obj:`False`)
        vector (bool, optional): Compute the vector stream; set
            :obj:`False` in a last layer that only feeds scalars on; then the
            scalar stream reads the incoming :math:`\mathbf{v}`.
            (default: :obj:`True`)
        aggr (str, optional): Aggregation of :math:`h_2`.
            (default: :obj:`"max"`)
        vector_input (bool, optional): Whether the layer receives a vector
            stream. :obj:`False` (with :obj:`vector=False`) gives the
            scalar-only ablation of the paper,
            :math:`\mathbf{x}' = h_1(\mathbf{x}) + \max_j h_2(\mathbf{x}_j)`,
            called with :obj:`v=None`. (default: :obj:`True`)

    Shapes:
        - **input:** scalars :math:`(N, C_{in})`, vectors
          :math:`(N, C_{in}, 2)`, edge_index :math:`(2, E)`, operators built
          on the same points (:class:`SurfaceOperators`)
        - **output:** scalars :math:`(N, C_{out})`, vectors
          :math:`(N, C_{out}, 2)` (or :obj:`None` if :obj:`vector=False`)
    """
    def __init__(self, in_channels: int, out_channels: int, depth: int = 1,
                 centralized: bool = False, vector: bool = True,
                 aggr: str = 'max', vector_input: bool = True):
        super().__init__(aggr=aggr, flow='source_to_target')
        self.in_channels = in_channels
        self.out_channels = out_channels
        self.depth = depth
        self.centralized = centralized
        if vector and not vector_input:
            raise ValueError("a layer without vector input cannot produce "
                             "vector output; pass vector=False")
        self.vector = vector
        self.vector_input = vector_input
        hidden = [out_channels] * depth
        self.mlp_neighbors = scalar_mlp([in_channels] + hidden)
        vec_channels = 0 if not vector_input else (
            out_channels if vector else in_channels)
        self.mlp_scalar = scalar_mlp([in_channels + 3 * vec_channels] + hidden)
        self.mlp_vector = VectorMLP([6 * in_channels] + hidden) \
            if vector else None
        self.reset_parameters()

    def reset_parameters(self):
        super().reset_parameters()
        self.mlp_neighbors.reset_parameters()
        self.mlp_scalar.reset_parameters()
        if self.mlp_vector is not None:
            self.mlp_vector.reset_parameters()

    def forward(self, x: Tensor, v: Optional[Tensor], edge_index: Tensor,
                operators: Optional[SurfaceOperators]
                ) -> Tuple[Tensor, Optional[Tensor]]:
        if self.mlp_vector is not None:
            v_in = torch.cat([v, operators.grad(x),
                              operators.hodge_laplacian(v)], dim=1)
            v = self.mlp_vector(torch.cat([v_in, rotate_j(v_in)], dim=1))
        if self.vector_input:
            # D v and curl v = -D J v share one sparse product.
            c = v.size(1)
            div_curl = operators.div(torch.cat([v, -rotate_j(v)], dim=1))
            x_ops = torch.cat([x, div_curl[:, :c], div_curl[:, c:],
                               vector_norm(v)], dim=1)
        else:
            x_ops = x
        if self.centralized:  # a per-edge MLP, then the aggregation
            j, i = edge_index
            x_max = self.aggr_module(self.mlp_neighbors(x[j] - x[i]), i,
                                     dim_size=x.size(0))
        elif operators is not None and \
                edge_index is operators.source_edge_index:
            x_max = operators.neighbor_max(self.mlp_neighbors(x))
        else:
            x_max = self.propagate(edge_index, x=self.mlp_neighbors(x))
        out = self.mlp_scalar(x_ops) + x_max
        return out, (v if self.mlp_vector is not None else None)

    def message(self, x_j: Tensor) -> Tensor:
        return x_j

    def __repr__(self) -> str:
        return (f'{self.__class__.__name__}({self.in_channels}, '
                f'{self.out_channels}, depth={self.depth}, '
                f'centralized={self.centralized}, vector={self.vector}, '
                f'vector_input={self.vector_input})')
