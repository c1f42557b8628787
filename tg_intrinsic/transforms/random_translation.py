import torch
from torch_geometric.data import Data
from torch_geometric.data.datapipes import functional_transform
from torch_geometric.transforms import BaseTransform


@functional_transform('random_translation')
class RandomTranslation(BaseTransform):
    r"""Moves a whole shape by one random offset (functional name:
    :obj:`random_translation`), uniform in a cube; unlike PyG's
    :class:`~torch_geometric.transforms.RandomJitter`, which moves every
    point on its own, the shape and everything intrinsic to it (normals,
    frames, operators) stay as they are:

    .. math::
        \mathbf{p}_i \mapsto \mathbf{p}_i + \mathbf{t}, \qquad
        \mathbf{t} \sim \mathcal{U}([-t_{\max}, t_{\max}]^3).

    Args:
        max_offset (float): :math:`t_{\max}`, not negative.

    Shapes:
        - **input:** ``pos`` :math:`(N, 3)`
        - **output:** ``pos`` :math:`(N, 3)`
    """
    def __init__(self, max_offset: float):
        if not max_offset >= 0:
            raise ValueError(f"max_offset must not be negative, got "
                             f"{max_offset}")
        self.max_offset = float(max_offset)

    def forward(self, data: Data) -> Data:
        if getattr(data, 'pos', None) is None:
            raise ValueError("RandomTranslation needs 'data.pos'")
        data = data.clone()
        offset = torch.empty(data.pos.size(-1), dtype=data.pos.dtype)
        offset.uniform_(-self.max_offset, self.max_offset)
        data.pos = data.pos + offset.to(data.pos.device)
        return data

    def __repr__(self) -> str:
        return f'{self.__class__.__name__}(max_offset={self.max_offset:g})'
