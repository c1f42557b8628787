from typing import List

import torch
from torch import Tensor

from tg_intrinsic.geometry.checks import check_channels
from tg_intrinsic.nn.vector_linear import VectorLinear
from tg_intrinsic.nn.vector_nonlin import VectorNonLin


class VectorMLP(torch.nn.Module):
    r"""A multi-layer perceptron on tangent vector features, alternating
    :class:`VectorLinear` and :class:`VectorNonLin` layers. Each layer
    computes

    .. math::
        v^{(l + 1)} = \sigma_{\|\cdot\|}\big(W^{(l)} v^{(l)}\big).

    Args:
        channels (List[int]): Channels of every layer, input first.
        batch_norm (bool, optional): Batch norm on the norms inside every
            :class:`VectorNonLin`. (default: :obj:`True`)

    Shapes:
        - **input:** :math:`(N, C_0, 2)`
        - **output:** :math:`(N, C_L, 2)`
    """
    def __init__(self, channels: List[int], batch_norm: bool = True):
        super().__init__()
        # An input and an output size at least.
        channels = check_channels(channels, 'channels', min_length=2)
        self.channels = list(channels)
        layers = []
        for c_in, c_out in zip(channels[:-1], channels[1:]):
            layers += [VectorLinear(c_in, c_out),
                       VectorNonLin(c_out, batch_norm=batch_norm)]
        self.layers = torch.nn.Sequential(*layers)

    def reset_parameters(self):
        for layer in self.layers:
            layer.reset_parameters()

    def forward(self, v: Tensor) -> Tensor:
        r"""Applies the layers to the tangent vector features :obj:`v`.

        Args:
            v (torch.Tensor): Vector features :math:`(N, C_0, 2)` in the
                points' tangent frames.

        Returns:
            torch.Tensor: Vector features :math:`(N, C_L, 2)` in the same
            frames.
        """
        return self.layers(v)

    def __repr__(self) -> str:
        return f'{self.__class__.__name__}({self.channels})'
