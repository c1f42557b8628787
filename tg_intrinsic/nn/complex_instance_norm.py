from typing import Optional

import torch
from torch import Tensor
from torch.nn import Parameter
from torch_geometric.utils import scatter

from tg_intrinsic.geometry.checks import (check_batch, check_positive_int,
                                          check_streams)


class ComplexInstanceNorm(torch.nn.Module):
    r"""Instance normalisation of complex stream features on their
    magnitudes: every channel of every stream of every shape is divided by
    the root mean square of its magnitude over that shape's points and
    scaled by a learned :math:`\gamma`; the phase is kept. It computes

    .. math::
        z_i' = \gamma\, \frac{z_i}{\sqrt{\frac{1}{|V_g|} \sum_{j \in V_g}
        |z_j|^2 + \epsilon}}, \qquad i \in V_g,

    with :math:`V_g` the points of shape :math:`g` (as PyG's
    :class:`~torch_geometric.nn.norm.InstanceNorm`, on magnitudes). The
    statistics never mix shapes, so training and evaluation compute the
    same function, whatever the batch size: the normalisation Harmonic
    Surface Networks need when a protocol trains on one mesh per batch,
    where :class:`ComplexBatchNorm`'s running average fits no single mesh
    (``benchmarks/normalisation.py`` measures it). It commutes with every
    gauge change, and it makes a shape's features independent of their
    overall scale.

    Args:
        channels (int): Channels :math:`C`.
        streams (int): Streams :math:`S` (statistics per stream and
            channel).
        eps (float, optional): :math:`\epsilon`. (default: :obj:`1e-5`)

    Shapes:
        - **input:** complex :math:`(N, S, C)`, optionally the shape index
          of every point :math:`(N)` (PyG's ``batch``; :obj:`None`: one
          shape)
        - **output:** complex :math:`(N, S, C)`
    """
    def __init__(self, channels: int, streams: int, eps: float = 1e-5):
        super().__init__()
        self.channels = check_positive_int(channels, 'channels')
        self.streams = check_positive_int(streams, 'streams')
        self.eps = eps
        self.weight = Parameter(torch.empty(streams, channels))
        self.reset_parameters()

    def reset_parameters(self):
        torch.nn.init.ones_(self.weight)

    def forward(self, z: Tensor, batch: Optional[Tensor] = None,
                num_shapes: Optional[int] = None) -> Tensor:
        r"""Normalises the magnitudes of :obj:`z` per shape.

        Args:
            z (torch.Tensor): Complex features :math:`(N, S, C)`.
            batch (torch.Tensor, optional): The shape index of every point
                :math:`(N)` (PyG's ``batch`` vector); :obj:`None` treats all
                points as one shape. (default: :obj:`None`)
            num_shapes (int, optional): The number of shapes; computed from
                :obj:`batch` if not given. (default: :obj:`None`)

        Returns:
            torch.Tensor: Complex features :math:`(N, S, C)` with the phases
            of :obj:`z`.
        """
        check_streams(z, 'z')
        if tuple(z.shape[1:]) != (self.streams, self.channels):
            raise ValueError(f"expected complex features [N, {self.streams}, "
                             f"{self.channels}], got {list(z.shape)}")
        if z.size(0) == 0:
            return z
        power = z.real ** 2 + z.imag ** 2
        if check_batch(batch, z.size(0), z) is None:
            square = power.mean(dim=0, keepdim=True)
            return z * (self.weight * torch.rsqrt(square + self.eps))
        square = scatter(power, batch, 0, dim_size=num_shapes, reduce='mean')
        scale = self.weight * torch.rsqrt(square + self.eps)
        return z * scale.index_select(0, batch)

    def __repr__(self) -> str:
        return (f'{self.__class__.__name__}({self.channels}, '
                f'streams={self.streams})')
