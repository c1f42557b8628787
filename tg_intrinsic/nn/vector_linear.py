import math

import torch
from torch import Tensor

from tg_intrinsic.geometry.checks import (check_positive_int,
                                          check_vector_features)
from tg_intrinsic.geometry.pointcloud.operators import interleaved, planar


class VectorLinear(torch.nn.Module):
    r"""A bias-free linear map between channels of tangent vector features.
    It computes

    .. math::
        v'_{i, o} = \sum_c W_{oc} \, v_{i, c},

    applied to both coordinates alike, so it commutes with rotations of the
    tangent frames (a bias would not).

    Args:
        in_channels (int): Input vector channels.
        out_channels (int): Output vector channels.

    Shapes:
        - **input:** :math:`(N, C_{in}, 2)`
        - **output:** :math:`(N, C_{out}, 2)`
    """
    def __init__(self, in_channels: int, out_channels: int):
        super().__init__()
        check_positive_int(in_channels, 'in_channels')
        check_positive_int(out_channels, 'out_channels')
        self.in_channels = in_channels
        self.out_channels = out_channels
        self.weight = torch.nn.Parameter(torch.empty(out_channels,
                                                     in_channels))
        self.reset_parameters()

    def reset_parameters(self):
        torch.nn.init.kaiming_uniform_(self.weight, a=math.sqrt(5))

    def forward(self, v: Tensor) -> Tensor:
        r"""Maps the channels of the tangent vector features :obj:`v`.

        Args:
            v (torch.Tensor): Vector features :math:`(N, C_{in}, 2)`, the two
                coordinates of every channel in its point's tangent frame.

        Returns:
            torch.Tensor: Vector features :math:`(N, C_{out}, 2)` in the
            same frames.
        """
        check_vector_features(v, 'v', self.in_channels)
        # On the [2, N, C] planes this is one matrix product, no copies.
        return interleaved(torch.nn.functional.linear(planar(v), self.weight))

    def __repr__(self) -> str:
        return (f'{self.__class__.__name__}({self.in_channels}, '
                f'{self.out_channels})')
