import torch
from torch import Tensor

from tg_intrinsic.geometry.checks import (check_float_tensor,
                                          check_positive_int,
                                          check_prolongation, check_tensor,
                                          check_vector_features)


class TangentVectorPool(torch.nn.Module):
    r"""Pooling of tangent vector features (DeltaConv's real pairs
    :math:`(N, C, 2)`, each in its point's own frame) onto coarse points:
    every pooling edge :math:`(j, c)` parallel transports the fine vector
    into the coarse point's frame, and the coarse point takes the weighted
    mean. It computes

    .. math::
        \mathbf{v}_c = \frac{\sum_{(j, c)} w_{jc}\, R(\phi_{j \to c})\,
        \mathbf{v}_j}{\sum_{(j, c)} w_{jc}},

    with :math:`R(\phi)` the rotation by the transport angle
    :math:`\phi_{j \to c}` (a vector at angle :math:`a` in :math:`j`'s
    frame arrives at angle :math:`a + \phi`, as in
    :func:`~tg_intrinsic.geometry.log_map`). With one edge and weight 1 per
    fine point (its nearest sample) this is the average over the sample's
    cluster used by the Delta-U-ResNet of the DeltaConv thesis; with the
    prolongation of a Gravo hierarchy it is the normalised restriction of
    :class:`GravoPool`. Built from ``pool_edge_index_l``,
    ``pool_weight_l`` and ``pool_transport_l`` of
    :class:`~tg_intrinsic.transforms.PoolingLevels`.

    Shapes:
        - **input:** v :math:`(N_l, C, 2)`, pool_edge_index :math:`(2, E)`
          (row 0 fine, row 1 coarse), pool_weight :math:`(E)`,
          pool_transport :math:`(E)`, num_coarse :math:`N_{l+1}`
        - **output:** :math:`(N_{l+1}, C, 2)`
    """
    def forward(self, v: Tensor, pool_edge_index: Tensor,
                pool_weight: Tensor, pool_transport: Tensor,
                num_coarse: int) -> Tensor:
        r"""Pools the tangent vector features :obj:`v` onto coarse points.

        Args:
            v (torch.Tensor): Vector features :math:`(N_l, C, 2)`, each in
                its fine point's frame.
            pool_edge_index (torch.Tensor): The pooling edges
                :math:`(2, E)`, row 0 fine, row 1 coarse.
            pool_weight (torch.Tensor): The weight :math:`w_{jc}` of every
                edge :math:`(E)`.
            pool_transport (torch.Tensor): The transport angle
                :math:`\phi_{j \to c}` of every edge :math:`(E)`.
            num_coarse (int): The number of coarse points :math:`N_{l+1}`.

        Returns:
            torch.Tensor: Vector features :math:`(N_{l+1}, C, 2)` in the
            coarse points' frames.
        """
        num_coarse = check_positive_int(num_coarse, 'num_coarse', minimum=0)
        v = check_tensor(v, 'v')
        check_vector_features(v, 'v', v.size(1) if v.dim() == 3 else -1)
        check_prolongation(v, pool_edge_index, pool_weight, v.size(0),
                           'fine', num_coarse)
        check_float_tensor(pool_transport, 'pool_transport',
                           (pool_edge_index.size(1), ))
        fine, coarse = pool_edge_index
        angle = pool_transport.to(v.dtype)
        c, s = torch.cos(angle).view(-1, 1), torch.sin(angle).view(-1, 1)
        a, b = v[fine, :, 0], v[fine, :, 1]
        weight = pool_weight.to(v.dtype).view(-1, 1, 1)
        moved = torch.stack([c * a - s * b, s * a + c * b], -1) * weight
        out = v.new_zeros((num_coarse, ) + v.shape[1:]).index_add_(
            0, coarse, moved)
        total = weight.new_zeros(num_coarse).index_add_(
            0, coarse, weight.view(-1))
        if bool((total <= 0).any()):
            raise ValueError("a coarse point receives no weight from any "
                             "fine point; the pooling levels are "
                             "inconsistent (rebuild them with "
                             "PoolingLevels)")
        return out / total.view(-1, 1, 1)

    def __repr__(self) -> str:
        return f'{self.__class__.__name__}()'
