import torch
from torch import Tensor
from torch.nn import Parameter

from tg_intrinsic.geometry.checks import check_positive_int, check_streams


class ComplexBatchNorm(torch.nn.Module):
    r"""Batch normalisation of complex stream features on their magnitudes:
    every channel of every stream is divided by the root mean square of its
    magnitude over all points of the batch and scaled by a learned
    :math:`\gamma`; the phase is kept. It computes

    .. math::
        z' = \gamma\, \frac{z}{\sqrt{\mathrm{E}[|z|^2] + \epsilon}} .

    Centring would change phases, so the magnitudes are only rescaled,
    which commutes with every gauge change. The statistics are means over
    points, so a batch of many small shapes and one of a single large shape
    are treated alike; in eval mode the running mean square is used. With
    one shape per batch (the HSN papers' protocols) that running average
    fits no single shape and eval mode scores far below training:
    :class:`ComplexInstanceNorm`, the HSN models' default, normalises per
    shape in both modes.

    Args:
        channels (int): Channels :math:`C`.
        streams (int): Streams :math:`S` (statistics per stream and
            channel).
        eps (float, optional): :math:`\epsilon`. (default: :obj:`1e-5`)
        momentum (float, optional): Running-statistics momentum.
            (default: :obj:`0.1`)

    Shapes:
        - **input / output:** complex :math:`(N, S, C)`
    """
    def __init__(self, channels: int, streams: int, eps: float = 1e-5,
                 momentum: float = 0.1):
        super().__init__()
        self.channels = check_positive_int(channels, 'channels')
        self.streams = check_positive_int(streams, 'streams')
        self.eps = eps
        self.momentum = momentum
        self.weight = Parameter(torch.empty(streams, channels))
        self.register_buffer('running_square', torch.ones(streams, channels))
        self.reset_parameters()

    def reset_parameters(self):
        torch.nn.init.ones_(self.weight)
        self.running_square.fill_(1.0)

    def forward(self, z: Tensor) -> Tensor:
        r"""Normalises the magnitudes of the complex stream features
        :obj:`z`.

        In training mode the mean square magnitude is taken over the
        :math:`N` points of :obj:`z` and updates the running value; in
        evaluation mode (or for an empty batch) the running value is used.

        Args:
            z (torch.Tensor): Complex features :math:`(N, S, C)`.

        Returns:
            torch.Tensor: Complex features :math:`(N, S, C)` with the phases
            of :obj:`z`.
        """
        check_streams(z, 'z')
        if tuple(z.shape[1:]) != (self.streams, self.channels):
            raise ValueError(f"expected complex features [N, {self.streams}, "
                             f"{self.channels}], got {list(z.shape)}")
        if self.training and z.size(0) > 0:
            square = (z.real ** 2 + z.imag ** 2).mean(dim=0)
            with torch.no_grad():
                self.running_square.lerp_(square.detach().to(
                    self.running_square.dtype), self.momentum)
        else:
            square = self.running_square.to(z.real.dtype)
        return z * (self.weight * torch.rsqrt(square + self.eps))

    def __repr__(self) -> str:
        return (f'{self.__class__.__name__}({self.channels}, '
                f'streams={self.streams})')
