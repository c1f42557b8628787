from typing import Tuple

import torch
from torch_geometric.data import Data
from torch_geometric.data.datapipes import functional_transform

from tg_intrinsic.transforms._batching import GraphTransform

# Attributes that a non-rigid change of the shape makes stale.
OPERATOR_KEYS = ('edge_index', 'frame', 'grad_weight', 'div_weight')


@functional_transform('random_axis_scale')
class RandomAxisScale(GraphTransform):
    r"""Scales a shape by an independent random factor along every axis,
    as DeltaConv's ModelNet40 and human-body augmentation does (functional
    name: :obj:`random_axis_scale`). It maps

    .. math::
        \mathbf{p}_i \mapsto S\,\mathbf{p}_i, \quad
        \mathbf{n}_i \mapsto \frac{S^{-1}\mathbf{n}_i}
        {\|S^{-1}\mathbf{n}_i\|}, \quad
        S = \operatorname{diag}(s_x, s_y, s_z), \;
        s_a \sim \mathcal{U}(\text{low}, \text{high}).

    Normals (``normal`` or ``norm``) follow the inverse transpose. Such a
    stretch changes the surface, so stored operators (``edge_index``,
    ``frame``, ``grad_weight``, ``div_weight``) are removed: DeltaNet then
    builds them for every batch. Use PyG's
    :class:`~torch_geometric.transforms.RandomScale` for one factor on all
    axes, which keeps them valid. On a collated
    :class:`~torch_geometric.data.Batch` every graph gets factors of its
    own, as if scaled before collation.

    Args:
        scales (tuple of float): The range :math:`(\text{low}, \text{high})`
            of the factors, both positive.

    Shapes:
        - **input:** ``pos`` :math:`(N, 3)`, optional ``normal`` :math:`(N, 3)`
        - **output:** the same attributes, scaled
    """
    def __init__(self, scales: Tuple[float, float]):
        low, high = scales
        if not 0 < low <= high:
            raise ValueError(f"scales must be (low, high) with 0 < low <= "
                             f"high, got {scales}")
        self.scales = (float(low), float(high))

    def forward(self, data: Data) -> Data:
        if getattr(data, 'pos', None) is None or data.pos.size(-1) != 3:
            raise ValueError("RandomAxisScale needs 'data.pos' of shape "
                             "[N, 3]")
        data = data.clone()
        low, high = self.scales
        factor = torch.empty(3, dtype=data.pos.dtype).uniform_(low, high)
        data.pos = data.pos * factor.to(data.pos.device)
        for key in ('normal', 'norm'):
            normal = getattr(data, key, None)
            if normal is not None:
                normal = normal / factor.to(normal.device, normal.dtype)
                data[key] = normal / normal.norm(dim=-1, keepdim=True)
        for key in OPERATOR_KEYS:
            if key in data:
                del data[key]
        return data

    def __repr__(self) -> str:
        return f'{self.__class__.__name__}(scales={self.scales})'
