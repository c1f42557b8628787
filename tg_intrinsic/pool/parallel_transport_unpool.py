import torch
from torch import Tensor

from tg_intrinsic.geometry.checks import (check_float_tensor, check_index,
                                          check_streams, same_device)
from tg_intrinsic.geometry.geodesics.harmonic import transport_features


class ParallelTransportUnpool(torch.nn.Module):
    r"""Unpooling of complex stream features (Harmonic Surface Networks):
    every fine point copies its cluster's feature, transported back from
    the sample's frame into its own. It computes

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
        r"""Copies the features of every cluster back to its fine points.

        Args:
            x (torch.Tensor): Complex features :math:`(N_c, S, C)` of the
                coarse points.
            cluster (torch.Tensor): The cluster :math:`c(j)` of every fine
                point :math:`(N)`, as for :class:`ParallelTransportPool`.
            transport (torch.Tensor): The pooling angles
                :math:`\phi_{j \to c(j)}` :math:`(N)`.

        Returns:
            torch.Tensor: Complex features :math:`(N, S, C)` in the fine
            points' frames.
        """
        x = check_streams(x, 'x')
        cluster = check_index(cluster, 'cluster', x.size(0), x,
                              what="rows in 'x' (coarse points)")
        check_float_tensor(transport, 'transport', cluster.shape)
        same_device(transport, 'transport', x, 'x')
        return transport_features(x[cluster], -transport)

    def __repr__(self) -> str:
        return f'{self.__class__.__name__}()'
