from typing import Optional

import torch
from torch import Tensor
from torch.nn.modules.batchnorm import _BatchNorm

from tg_intrinsic.geometry.checks import check_tensor
from tg_intrinsic.nn.complex_batch_norm import ComplexBatchNorm
from tg_intrinsic.nn.sync_complex_batch_norm import (SyncComplexBatchNorm,
                                                     active_group,
                                                     all_reduce_sum)

_REAL_BATCH_NORMS = (torch.nn.BatchNorm1d, torch.nn.BatchNorm2d,
                     torch.nn.BatchNorm3d, torch.nn.SyncBatchNorm)


class SyncBatchNorm(_BatchNorm):
    r"""Batch normalisation whose statistics are taken over the batches of
    all processes of a data-parallel run, on the CPU as well as on GPUs
    (`"Batch Normalization: Accelerating Deep Network Training by Reducing
    Internal Covariate Shift" <https://arxiv.org/abs/1502.03167>`_; the
    cross-process statistics as in :class:`torch.nn.SyncBatchNorm`). It
    computes

    .. math::
        \mu = \frac{1}{n} \sum_{r} \sum_{i \in B_r} x_i, \quad
        \sigma^2 = \frac{1}{n} \sum_{r} \sum_{i \in B_r} (x_i - \mu)^2,
        \quad y_i = \gamma \frac{x_i - \mu}{\sqrt{\sigma^2 + \epsilon}}
        + \beta,

    with :math:`B_r` the batch of process :math:`r` and :math:`n` the
    total count, so :math:`R` processes with a part of the batch each
    normalise (and differentiate) exactly as one process with the whole
    batch. The sums are all-reduced with the autograd-aware
    :func:`torch.distributed.nn.functional.all_reduce` (two reductions:
    the mean, then the centred squares, the two-pass variance of one
    process). :class:`torch.nn.SyncBatchNorm` (torch 2.13) runs on GPUs
    only, and :class:`~torch.nn.parallel.DistributedDataParallel` refuses
    it in CPU models; this layer runs on any device and backend. In
    evaluation mode, outside a process group or in a group of one it is
    the ordinary batch norm. Build it from a model with
    :func:`convert_sync_batch_norm`; it keeps the parameter and buffer
    names of :class:`torch.nn.BatchNorm1d`, so checkpoints load both ways.

    Args:
        num_features (int): Channels :math:`C`.
        eps (float, optional): :math:`\epsilon`. (default: :obj:`1e-5`)
        momentum (float, optional): Running-statistics momentum
            (:obj:`None`: cumulative average). (default: :obj:`0.1`)
        affine (bool, optional): Learn :math:`\gamma, \beta`.
            (default: :obj:`True`)
        track_running_stats (bool, optional): Keep running statistics.
            (default: :obj:`True`)
        process_group (optional): The processes to synchronise
            (default: :obj:`None`: all).

    Shapes:
        - **input / output:** :math:`(N, C)` or :math:`(N, C, *)`
    """
    def __init__(self, num_features: int, eps: float = 1e-5,
                 momentum: Optional[float] = 0.1, affine: bool = True,
                 track_running_stats: bool = True,
                 process_group: Optional[object] = None):
        super().__init__(num_features, eps, momentum, affine,
                         track_running_stats)
        self.process_group = process_group

    def _check_input_dim(self, input: Tensor):
        if input.dim() < 2 or input.size(1) != self.num_features:
            raise ValueError(f"expected features [N, {self.num_features}] "
                             f"or [N, {self.num_features}, L], got "
                             f"{list(input.shape)}")

    def all_reduce(self, sums: Tensor) -> Tensor:
        """:obj:`sums` summed over the processes this layer synchronises
        (differentiable; unchanged outside a group or in evaluation mode):
        for layers that compute the statistics of this batch norm
        themselves, as DeltaConv's neighbour maximum does."""
        group = active_group(self.process_group)
        if not self.training or group is None:
            return sums
        return all_reduce_sum(sums, group)

    def forward(self, input: Tensor) -> Tensor:
        r"""Normalises :obj:`input` with the statistics of all processes.

        In training mode inside a process group of more than one process the
        statistics are all-reduced over the group; otherwise this is the
        batch norm of :class:`torch.nn.BatchNorm1d`.

        Args:
            input (torch.Tensor): Features :math:`(N, C)` or
                :math:`(N, C, *)`.

        Returns:
            torch.Tensor: Normalised features of the shape of :obj:`input`.
        """
        check_tensor(input, 'input')
        self._check_input_dim(input)
        group = active_group(self.process_group)
        if not self.training or group is None:
            return super().forward(input)
        momentum = 0.0 if self.momentum is None else self.momentum
        if self.track_running_stats:
            self.num_batches_tracked.add_(1)
            if self.momentum is None:
                momentum = 1.0 / float(self.num_batches_tracked)
        dims = [0] + list(range(2, input.dim()))
        shape = [1, -1] + [1] * (input.dim() - 2)
        count = input.numel() // max(input.size(1), 1)
        local = torch.cat([input.sum(dims),
                           input.new_full((1, ), float(count))])
        total = all_reduce_sum(local, group)
        n = total[-1].detach()
        if float(n) < 1:
            raise ValueError("the batch is empty on every process: batch "
                             "norm needs at least one sample")
        mean = total[:-1] / n
        centred = input - mean.view(shape)
        var = all_reduce_sum((centred * centred).sum(dims), group) / n
        out = centred * torch.rsqrt(var + self.eps).view(shape)
        if self.affine:
            out = out * self.weight.view(shape) + self.bias.view(shape)
        if self.track_running_stats:
            with torch.no_grad():
                unbiased = var.detach() * (n / (n - 1).clamp_min(1))
                self.running_mean.lerp_(mean.detach().to(
                    self.running_mean.dtype), momentum)
                self.running_var.lerp_(unbiased.to(
                    self.running_var.dtype), momentum)
        return out

    def __repr__(self) -> str:
        return (f'{self.__class__.__name__}({self.num_features}, '
                f'eps={self.eps}, momentum={self.momentum}, '
                f'affine={self.affine})')


def convert_sync_batch_norm(module: torch.nn.Module,
                            process_group: Optional[object] = None
                            ) -> torch.nn.Module:
    r"""Replaces every batch norm of :obj:`module` (``BatchNorm1d/2d/3d``,
    :class:`torch.nn.SyncBatchNorm` and :class:`ComplexBatchNorm`, also
    inside PyG's :class:`~torch_geometric.nn.norm.BatchNorm`) by
    :class:`SyncBatchNorm` or :class:`SyncComplexBatchNorm`, which share
    its parameters and buffers (same names: a state dict loads into either
    model). Returns the module (a new one if :obj:`module` is itself a
    batch norm)."""
    out = module
    if isinstance(module, _REAL_BATCH_NORMS) and \
            not isinstance(module, SyncBatchNorm):
        out = SyncBatchNorm(module.num_features, module.eps, module.momentum,
                            module.affine, module.track_running_stats,
                            process_group)
        _share_state(module, out, ('weight', 'bias', 'running_mean',
                                   'running_var', 'num_batches_tracked'))
    elif isinstance(module, ComplexBatchNorm) and \
            not isinstance(module, SyncComplexBatchNorm):
        out = SyncComplexBatchNorm(module.channels, module.streams,
                                   module.eps, module.momentum,
                                   process_group)
        _share_state(module, out, ('weight', 'running_square'))
    for name, child in module.named_children():
        out.add_module(name, convert_sync_batch_norm(child, process_group))
    return out


def _share_state(source, target, names):
    for name in names:
        value = getattr(source, name, None)
        if isinstance(value, torch.nn.Parameter):
            setattr(target, name, value)
        elif name in target._buffers:
            target._buffers[name] = value
    target.train(source.training)
