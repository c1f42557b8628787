import torch
from torch import Tensor

from tg_intrinsic.geometry.geodesics.harmonic import transport_features


class ParallelTransportUnpool(torch.nn.Module):
    r"""Unpooling of complex stream features (Harmonic Surface Networks):
    every fine point copies its cluster's feature, transported back from
    the sample's frame into its own,

    .. math::
        x_j^M = e^{-iM\phi_{j \to c(j)}}\, x_{c(j)}^M .

    Shapes:
        - **input:** x complex :math:`(N_c, S, C)`, cluster :math:`(N)`,
          transport :math:`(N)` (the pooling angles
          :math:`\phi_{j \to c(j)}`)
        - **output:** complex :math:`(N, S, C)`
    """
    def forward(self, x: Tensor, cluster: Tensor, transport: Tensor
                ) -> Tensor:
        if cluster.shape != transport.shape or cluster.dim() != 1:
            raise ValueError("'cluster' and 'transport' must be [N] with one "
                             "entry per fine point")
        if cluster.numel() and int(cluster.max()) >= x.size(0):
            raise ValueError(f"'cluster' refers to coarse point "
                             f"{int(cluster.max())} but x has {x.size(0)}")
        return transport_features(x[cluster], -transport)

    def __repr__(self) -> str:
        return f'{self.__class__.__name__}()'
