import torch
from torch import Tensor
from torch.nn import Parameter

from tg_intrinsic.geometry.checks import check_positive_int, check_streams


class ComplexReLU(torch.nn.Module):
    r"""The C-ReLU of Harmonic Surface Networks: a ReLU on the magnitude of
    complex features with a learned bias, keeping their phase. It computes

    .. math::
        \sigma(z) = \operatorname{ReLU}(|z| + b)\, \frac{z}{|z|},

    with :math:`\sigma(0) = 0`. Magnitudes do not change when a tangent frame
    turns, so the nonlinearity commutes with every gauge change.

    Args:
        channels (int): Channels :math:`C` (one bias per channel, shared by
            all streams).

    Shapes:
        - **input / output:** complex :math:`(N, S, C)`
    """
    def __init__(self, channels: int):
        super().__init__()
        self.channels = check_positive_int(channels, 'channels')
        self.bias = Parameter(torch.empty(channels))
        self.reset_parameters()

    def reset_parameters(self):
        torch.nn.init.zeros_(self.bias)

    def forward(self, z: Tensor) -> Tensor:
        r"""Applies the C-ReLU to the complex stream features :obj:`z`.

        Args:
            z (torch.Tensor): Complex features :math:`(N, S, C)`.

        Returns:
            torch.Tensor: Complex features :math:`(N, S, C)` with the phases
            of :obj:`z` (zero where :math:`|z| + b \leq 0` or :math:`z = 0`).
        """
        check_streams(z, 'z')
        if z.size(-1) != self.channels:
            raise ValueError(f"expected complex features [N, streams, "
                             f"{self.channels}], got {list(z.shape)}")
        magnitude = z.abs()
        # Where |z| = 0 the phase is undefined; the output is 0 there and the
        # division is kept away from 0 so that no NaN reaches the gradient.
        safe = torch.where(magnitude > 0, magnitude, 1.0)
        scale = torch.relu(magnitude + self.bias) / safe
        return z * torch.where(magnitude > 0, scale, 0.0)

    def __repr__(self) -> str:
        return f'{self.__class__.__name__}({self.channels})'
