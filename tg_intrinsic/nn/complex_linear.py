import math

import torch
from torch import Tensor
from torch.nn import Parameter

from tg_intrinsic.geometry.checks import check_positive_int, check_streams
from tg_intrinsic.geometry.precision import (complex_from, full_precision,
                                             refuse_low_precision)


class ComplexLinear(torch.nn.Module):
    r"""A linear map of complex stream features with real weights, applied
    alike to the real and imaginary parts of every stream (Harmonic Surface
    Networks). It computes

    .. math::
        \mathbf{z}'^{M} = \mathbf{z}^{M} W + [M = 0]\, \mathbf{b} .

    A real linear combination of features of one order commutes with the
    rotation :math:`e^{iM\varphi}`; a bias would not, so only stream 0 gets
    one.

    Args:
        in_channels (int): Input channels per stream.
        out_channels (int): Output channels per stream.
        bias (bool, optional): Learn a bias for stream 0.
            (default: :obj:`True`)

    Shapes:
        - **input:** complex :math:`(N, S, C_{in})`
        - **output:** complex :math:`(N, S, C_{out})`
    """
    def __init__(self, in_channels: int, out_channels: int,
                 bias: bool = True):
        super().__init__()
        check_positive_int(in_channels, 'in_channels')
        check_positive_int(out_channels, 'out_channels')
        self.in_channels = in_channels
        self.out_channels = out_channels
        self.weight = Parameter(torch.empty(in_channels, out_channels))
        if bias:
            self.bias = Parameter(torch.empty(out_channels))
        else:
            self.register_parameter('bias', None)
        self.reset_parameters()

    def reset_parameters(self):
        bound = 1 / math.sqrt(self.in_channels)
        torch.nn.init.uniform_(self.weight, -bound, bound)
        if self.bias is not None:
            torch.nn.init.zeros_(self.bias)

    def forward(self, z: Tensor) -> Tensor:
        r"""Maps the channels of every stream of :obj:`z`.

        Args:
            z (torch.Tensor): Complex features :math:`(N, S, C_{in})`.

        Returns:
            torch.Tensor: Complex features :math:`(N, S, C_{out})`, with the
            bias added to stream 0 only.
        """
        check_streams(z, 'z')
        refuse_low_precision(self.weight, 'weights', 'ComplexLinear')
        if z.size(-1) != self.in_channels:
            raise ValueError(f"expected complex features [N, streams, "
                             f"{self.in_channels}], got {list(z.shape)}")
        with full_precision(z.device.type):  # complex maths in float32
            out = complex_from(z.real @ self.weight, z.imag @ self.weight)
        if self.bias is None:
            return out
        first = out[:, :1] + self.bias
        return torch.cat([first, out[:, 1:]], dim=1)

    def __repr__(self) -> str:
        return (f'{self.__class__.__name__}({self.in_channels}, '
                f'{self.out_channels}, bias={self.bias is not None})')
