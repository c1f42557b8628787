from typing import Optional

import torch
from torch import Tensor

from tg_intrinsic.geometry.checks import check_streams
from tg_intrinsic.nn.complex_batch_norm import ComplexBatchNorm


class SyncComplexBatchNorm(ComplexBatchNorm):
    r""":class:`ComplexBatchNorm` whose mean square magnitude is taken over
    the batches of all processes of a data-parallel run (`"Harmonic Surface
    Networks" <https://arxiv.org/abs/1909.07776>`_'s complex batch norm,
    synchronised as in :class:`torch.nn.SyncBatchNorm`). It computes

    .. math::
        z' = \gamma\, \frac{z}{\sqrt{\frac{1}{n} \sum_r \sum_{i \in B_r}
        |z_i|^2 + \epsilon}},

    with :math:`B_r` the points of process :math:`r` and :math:`n` their
    total count: the sums and counts are all-reduced with the
    autograd-aware :func:`torch.distributed.nn.functional.all_reduce`, so
    :math:`R` processes with a part of the batch each normalise (and
    differentiate) as one process with the whole batch. In evaluation
    mode, outside a process group or in a group of one it is
    :class:`ComplexBatchNorm`. Parameter and buffer names are those of
    :class:`ComplexBatchNorm`.

    Args:
        channels (int): Channels :math:`C`.
        streams (int): Streams :math:`S`.
        eps (float, optional): :math:`\epsilon`. (default: :obj:`1e-5`)
        momentum (float, optional): Running-statistics momentum.
            (default: :obj:`0.1`)
        process_group (optional): The processes to synchronise
            (default: :obj:`None`: all).

    Shapes:
        - **input / output:** complex :math:`(N, S, C)`
    """
    def __init__(self, channels: int, streams: int, eps: float = 1e-5,
                 momentum: float = 0.1,
                 process_group: Optional[object] = None):
        super().__init__(channels, streams, eps, momentum)
        self.process_group = process_group

    def forward(self, z: Tensor) -> Tensor:
        r"""Normalises the magnitudes of :obj:`z` with the mean square
        magnitude over the points of all processes.

        In evaluation mode, outside a process group of more than one
        process, or when no process has any point, this is
        :meth:`ComplexBatchNorm.forward`.

        Args:
            z (torch.Tensor): Complex features :math:`(N, S, C)`.

        Returns:
            torch.Tensor: Complex features :math:`(N, S, C)` with the phases
            of :obj:`z`.
        """
        group = active_group(self.process_group)
        if not self.training or group is None:
            return super().forward(z)
        check_streams(z, 'z')
        if tuple(z.shape[1:]) != (self.streams, self.channels):
            raise ValueError(f"expected complex features [N, {self.streams}, "
                             f"{self.channels}], got {list(z.shape)}")
        power = (z.real ** 2 + z.imag ** 2).sum(dim=0).flatten()
        local = torch.cat([power, power.new_full((1, ), float(z.size(0)))])
        total = all_reduce_sum(local, group)
        n = total[-1].detach()
        if float(n) < 1:
            return super().forward(z)   # no points anywhere: running value
        square = (total[:-1] / n).view(self.streams, self.channels)
        with torch.no_grad():
            self.running_square.lerp_(square.detach().to(
                self.running_square.dtype), self.momentum)
        return z * (self.weight * torch.rsqrt(square + self.eps))

    def __repr__(self) -> str:
        return (f'{self.__class__.__name__}({self.channels}, '
                f'streams={self.streams})')


def active_group(process_group=None):
    """The process group to synchronise over (the default one for
    :obj:`None`), or :obj:`None` when there is none or it holds a single
    process."""
    import torch.distributed as dist
    if not (dist.is_available() and dist.is_initialized()):
        return None
    group = dist.group.WORLD if process_group is None else process_group
    return group if dist.get_world_size(group) > 1 else None


def all_reduce_sum(tensor: Tensor, group) -> Tensor:
    """The sum of :obj:`tensor` over the processes of :obj:`group`,
    differentiable: the gradient is summed over them as well."""
    from torch.distributed.nn.functional import all_reduce
    return all_reduce(tensor, group=group)
