import torch
from torch import Tensor

from tg_intrinsic.geometry.checks import (check_positive_int,
                                          check_prolongation)


class GravoUnpool(torch.nn.Module):
    r"""Unpooling from level :math:`l+1` to level :math:`l` of a Gravo MG
    hierarchy by the prolongation. It computes

    .. math::
        x^{(l)}_i = \sum_c P_{ic}\, x^{(l+1)}_c .

    Shapes:
        - **input:** x :math:`(N_{l+1}, *)`, prolong_index :math:`(2, nnz)`,
          prolong_weight :math:`(nnz)`, num_fine :math:`N_l`
        - **output:** :math:`(N_l, *)`
    """
    def forward(self, x: Tensor, prolong_index: Tensor,
                prolong_weight: Tensor, num_fine: int) -> Tensor:
        r"""Interpolates the features :obj:`x` to the next, finer level.

        Args:
            x (torch.Tensor): Features :math:`(N_{l+1}, *)` of the coarse
                level.
            prolong_index (torch.Tensor): The nonzeros of the prolongation
                :math:`P` :math:`(2, nnz)`, row 0 fine, row 1 coarse.
            prolong_weight (torch.Tensor): Their weights :math:`(nnz)`.
            num_fine (int): The number of fine points :math:`N_l`.

        Returns:
            torch.Tensor: Features :math:`(N_l, *)`.
        """
        num_fine = check_positive_int(num_fine, 'num_fine', minimum=0)
        check_prolongation(x, prolong_index, prolong_weight, x.size(0),
                           'coarse', num_fine)
        fine, coarse = prolong_index
        shape = (-1, ) + (1, ) * (x.dim() - 1)
        return x.new_zeros((num_fine, ) + x.shape[1:]).index_add_(
            0, fine, x[coarse] * prolong_weight.to(x.dtype).view(shape))

    def __repr__(self) -> str:
        return f'{self.__class__.__name__}()'
