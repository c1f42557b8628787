import math
import re

import torch
from torch import Tensor
from torch_geometric.data import Data
from torch_geometric.data.datapipes import functional_transform

from tg_intrinsic.geometry.checks import check_points
from tg_intrinsic.transforms._batching import GraphTransform

_LEVEL_POS = re.compile(r'pos_[1-9][0-9]*')


@functional_transform('random_translation')
class RandomTranslation(GraphTransform):
    r"""Moves a whole shape by one random offset, uniform in a cube
    (functional name: :obj:`random_translation`). Unlike PyG's
    :class:`~torch_geometric.transforms.RandomJitter`, which moves every
    point on its own, the shape and everything intrinsic to it (normals,
    frames, operators) stay as they are; the points of coarser levels
    (``pos_1``, ``pos_2``, ... of :class:`MultiscaleSupports` or
    :class:`GravoHierarchy`) move with it:

    .. math::
        \mathbf{p}_i \mapsto \mathbf{p}_i + \mathbf{t}, \qquad
        \mathbf{t} \sim \mathcal{U}([-t_{\max}, t_{\max}]^3).

    On a collated :class:`~torch_geometric.data.Batch` every graph gets an
    offset of its own, as if moved before collation.

    Args:
        max_offset (float): :math:`t_{\max}`, finite and not negative.

    Shapes:
        - **input:** ``pos`` :math:`(N, 3)`
        - **output:** ``pos`` :math:`(N, 3)`
    """
    def __init__(self, max_offset: float):
        if not (max_offset >= 0 and math.isfinite(max_offset)):
            raise ValueError(f"max_offset must be finite and must not be "
                             f"negative, got {max_offset}")
        self.max_offset = float(max_offset)

    def forward(self, data: Data) -> Data:
        if getattr(data, 'pos', None) is None:
            raise ValueError("RandomTranslation needs 'data.pos'")
        pos = check_points(data.pos, 'data.pos', dim=None)
        data = data.clone()
        offset = torch.empty(pos.size(-1), dtype=pos.dtype)
        offset.uniform_(-self.max_offset, self.max_offset)
        offset = offset.to(pos.device)
        for key, value in data.to_dict().items():
            if key == 'pos' or (_LEVEL_POS.fullmatch(key)
                                and isinstance(value, Tensor)):
                data[key] = value + offset.to(value.dtype)
        return data

    def __repr__(self) -> str:
        return f'{self.__class__.__name__}(max_offset={self.max_offset:g})'
