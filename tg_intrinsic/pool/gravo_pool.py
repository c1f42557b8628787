import torch
from torch import Tensor

from tg_intrinsic.geometry.checks import (check_positive_int,
                                          check_prolongation)


class GravoPool(torch.nn.Module):
    r"""Pooling to the next level of a Gravo MG hierarchy by the normalised
    restriction: every coarse point takes the average of the fine points
    that interpolate from it, weighted by the prolongation. It computes

    .. math::
        x^{(l+1)}_c = \frac{\sum_i P_{ic}\, x^{(l)}_i}{\sum_i P_{ic}},

    so constants stay constant. Built from ``prolong_index_l`` /
    ``prolong_weight_l`` of :class:`~tg_intrinsic.transforms.GravoHierarchy`
    (batches are block diagonal, so no batch vector is needed).

    Shapes:
        - **input:** x :math:`(N_l, *)`, prolong_index :math:`(2, nnz)`
          (fine, coarse), prolong_weight :math:`(nnz)`, num_coarse
          :math:`N_{l+1}`
        - **output:** :math:`(N_{l+1}, *)`
    """
    def forward(self, x: Tensor, prolong_index: Tensor,
                prolong_weight: Tensor, num_coarse: int) -> Tensor:
        r"""Pools the features :obj:`x` to the next, coarser level.

        Args:
            x (torch.Tensor): Features :math:`(N_l, *)` of the fine level.
            prolong_index (torch.Tensor): The nonzeros of the prolongation
                :math:`P` :math:`(2, nnz)`, row 0 fine, row 1 coarse
                (``prolong_index_l``).
            prolong_weight (torch.Tensor): Their weights :math:`(nnz)`
                (``prolong_weight_l``).
            num_coarse (int): The number of coarse points :math:`N_{l+1}`.

        Returns:
            torch.Tensor: Features :math:`(N_{l+1}, *)`.
        """
        num_coarse = check_positive_int(num_coarse, 'num_coarse', minimum=0)
        check_prolongation(x, prolong_index, prolong_weight, x.size(0),
                           'fine', num_coarse)
        fine, coarse = prolong_index
        weight = prolong_weight.to(x.dtype)
        shape = (-1, ) + (1, ) * (x.dim() - 1)
        out = x.new_zeros((num_coarse, ) + x.shape[1:]).index_add_(
            0, coarse, x[fine] * weight.view(shape))
        total = weight.new_zeros(num_coarse).index_add_(0, coarse, weight)
        if bool((total <= 0).any()):
            raise ValueError("a coarse point receives no weight from any "
                             "fine point; the hierarchy is inconsistent")
        return out / total.view(shape)

    def __repr__(self) -> str:
        return f'{self.__class__.__name__}()'
