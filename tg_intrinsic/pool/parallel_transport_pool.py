from typing import Optional

import torch
from torch import Tensor

from tg_intrinsic.geometry.checks import (check_float_tensor, check_index,
                                          check_positive_int, check_streams,
                                          same_device)
from tg_intrinsic.geometry.geodesics.harmonic import transport_features


class ParallelTransportPool(torch.nn.Module):
    r"""Pooling of complex stream features onto coarse points (Harmonic
    Surface Networks): every fine point :math:`j` belongs to the cluster of
    its geodesically nearest sample :math:`c(j)`, and a cluster takes the
    mean of its points' features after parallel transport into the
    sample's frame. It computes

    .. math::
        x_c^M = \frac{1}{|\{j : c(j) = c\}|} \sum_{j : c(j) = c}
        e^{iM\phi_{j \to c}}\, x_j^M .

    Args:
        reduce (str, optional): :obj:`'mean'` or :obj:`'sum'`.
            (default: :obj:`'mean'`)

    Shapes:
        - **input:** x complex :math:`(N, S, C)`, cluster :math:`(N)`,
          transport :math:`(N)` (angle :math:`\phi_{j \to c(j)}`, e.g.
          ``data.pool_transport_1``)
        - **output:** complex :math:`(N_c, S, C)`
    """
    def __init__(self, reduce: str = 'mean'):
        super().__init__()
        if reduce not in ('mean', 'sum'):
            raise ValueError(f"reduce must be 'mean' or 'sum', got "
                             f"{reduce!r}")
        self.reduce = reduce

    def forward(self, x: Tensor, cluster: Tensor, transport: Tensor,
                num_clusters: Optional[int] = None) -> Tensor:
        r"""Pools the complex stream features :obj:`x` onto the clusters.

        Args:
            x (torch.Tensor): Complex features :math:`(N, S, C)` of the fine
                points.
            cluster (torch.Tensor): The cluster :math:`c(j)` of every fine
                point :math:`(N)`, e.g. ``data.cluster_1``.
            transport (torch.Tensor): The transport angle
                :math:`\phi_{j \to c(j)}` of every fine point :math:`(N)`,
                e.g. ``data.pool_transport_1``.
            num_clusters (int, optional): The number of coarse points
                :math:`N_c`; :obj:`None` takes the largest index of
                :obj:`cluster` plus one. (default: :obj:`None`)

        Returns:
            torch.Tensor: Complex features :math:`(N_c, S, C)`, zero for an
            empty cluster.
        """
        # Checked first: index_add_ and bincount fail late or silently.
        x = check_streams(x, 'x')
        n = x.size(0)
        if num_clusters is not None:
            num_clusters = check_positive_int(num_clusters, 'num_clusters',
                                              minimum=0)
        cluster = check_index(cluster, 'cluster', num_clusters, x, size=n,
                              what=f'clusters (num_clusters={num_clusters})')
        check_float_tensor(transport, 'transport', (n, ))
        same_device(transport, 'transport', x, 'x')
        if num_clusters is None:
            num_clusters = int(cluster.max()) + 1 if cluster.numel() else 0
        moved = transport_features(x, transport)
        out = moved.new_zeros((num_clusters,) + tuple(x.shape[1:]))
        out = out.index_add(0, cluster, moved)
        if self.reduce == 'mean':
            # index_add, not bincount: its size is known to torch.compile
            count = out.real.new_zeros(num_clusters).index_add(
                0, cluster, out.real.new_ones(n))
            out = out / count.clamp(min=1).view(-1, 1, 1)
        return out

    def __repr__(self) -> str:
        return f'{self.__class__.__name__}(reduce={self.reduce!r})'
