import torch
from torch import Tensor

from tg_intrinsic.geometry.checks import (check_positive_int,
                                          check_vector_features)
from tg_intrinsic.geometry.pointcloud.operators import (interleaved, planar,
                                                        vector_norm)


class VectorNonLin(torch.nn.Module):
    r"""A nonlinearity on the norms of tangent vectors that keeps their
    directions (DeltaConv). It computes

    .. math::
        v'_{i, c} = \frac{\mathrm{ReLU}(\mathrm{BN}(\|v_{i, c}\|))}
        {\|v_{i, c}\|} \, v_{i, c},

    with batch norm over the norms of each channel (or a learned bias
    :math:`\|v\| + b_c` when :obj:`batch_norm=False`), which shifts the
    threshold of the ReLU. It is invariant to the choice of tangent frame.

    Args:
        channels (int): Vector channels.
        batch_norm (bool, optional): Normalise the norms with
            :class:`torch.nn.BatchNorm1d` instead of adding a bias.
            (default: :obj:`True`)
        eps (float, optional): Norms below this are treated as zero vectors.
            (default: :obj:`1e-8`)

    Shapes:
        - **input / output:** :math:`(N, C, 2)`
    """
    def __init__(self, channels: int, batch_norm: bool = True,
                 eps: float = 1e-8):
        super().__init__()
        self.channels = check_positive_int(channels, 'channels')
        self.eps = eps
        if batch_norm:
            self.norm = torch.nn.BatchNorm1d(channels)
            self.register_parameter('bias', None)
        else:
            self.norm = None
            self.bias = torch.nn.Parameter(torch.zeros(channels))
        self.reset_parameters()

    def reset_parameters(self):
        if self.norm is not None:
            self.norm.reset_parameters()
        else:
            torch.nn.init.zeros_(self.bias)

    def forward(self, v: Tensor) -> Tensor:
        r"""Rescales every vector of :obj:`v` by its activated norm.

        Args:
            v (torch.Tensor): Vector features :math:`(N, C, 2)` in the
                points' tangent frames.

        Returns:
            torch.Tensor: Vector features :math:`(N, C, 2)` with the
            directions of :obj:`v`, or zero where the ReLU is zero.
        """
        check_vector_features(v, 'v', self.channels)
        # The norm with an eps inside the root keeps gradients finite at 0.
        length = vector_norm(v, self.eps)
        shifted = self.norm(length) if self.norm is not None \
            else length + self.bias
        return interleaved(planar(v) * (torch.relu(shifted) / length))

    def __repr__(self) -> str:
        return (f'{self.__class__.__name__}({self.channels}, '
                f'batch_norm={self.norm is not None})')
