import copy
from typing import Iterable, List, Optional

import torch
from torch.nn.modules.batchnorm import _BatchNorm

from tg_intrinsic.nn.complex_batch_norm import ComplexBatchNorm
from tg_intrinsic.nn.sync_batch_norm import SyncBatchNorm
from tg_intrinsic.nn.sync_complex_batch_norm import (SyncComplexBatchNorm,
                                                     active_group)


def batch_norms(model: torch.nn.Module) -> List[torch.nn.Module]:
    """The batch norms of :obj:`model` that keep running statistics:
    :class:`torch.nn.BatchNorm1d` (``2d``, ``3d``, ``SyncBatchNorm`` and
    this package's :class:`SyncBatchNorm`) and :class:`ComplexBatchNorm`
    (and :class:`SyncComplexBatchNorm`)."""
    return [m for m in model.modules()
            if (isinstance(m, _BatchNorm) and m.track_running_stats)
            or isinstance(m, ComplexBatchNorm)]


def batch_statistics_copy(model: torch.nn.Module) -> torch.nn.Module:
    """A copy of :obj:`model` in evaluation mode but for its batch norms
    (real and complex), which normalise with the statistics of the batch
    they are given, each process its own (synchronised ones are made plain
    so that processes with different batch counts never wait for each
    other): the per-batch figure (per shape, with one shape per batch) that
    ``train`` compares eval mode with. Running statistics of the copy
    change; :obj:`model`'s do not."""
    clone = copy.deepcopy(model).eval()
    for module in batch_norms(clone):
        if isinstance(module, SyncComplexBatchNorm):
            module.__class__ = ComplexBatchNorm
        elif isinstance(module, (SyncBatchNorm, torch.nn.SyncBatchNorm)):
            module.__class__ = torch.nn.BatchNorm1d
        module.train()
    return clone


@torch.no_grad()
def recalibrate_batch_norm(model: torch.nn.Module, batches: Iterable,
                           device: Optional[torch.device] = None,
                           process_group: Optional[object] = None) -> int:
    r"""Replaces the running statistics of every batch norm of
    :obj:`model` by their average over :obj:`batches` under the final
    weights ("precise batch norm", `Wu and Johnson, "Rethinking 'Batch' in
    BatchNorm" <https://arxiv.org/abs/2105.07576>`_). It sets

    .. math::
        \mu = \frac{1}{B} \sum_{b=1}^{B} \mu_b, \qquad
        \sigma^2 = \frac{1}{B} \sum_{b=1}^{B} \sigma_b^2,

    with :math:`\mu_b, \sigma_b^2` the statistics of batch :math:`b` (the
    mean square magnitude for :class:`ComplexBatchNorm`). During training
    the running statistics are an exponential average over batches
    computed with older weights; while the weights still move (a high
    learning rate, few steps per epoch) they lag behind the network, and
    evaluation mode then scores far below what the same weights score with
    batch statistics (``benchmarks/normalisation.py`` measures it).
    Dropout stays off; the model's mode is restored afterwards. In a
    data-parallel run (:obj:`process_group`, or the default group when
    one is initialised) every process passes its own batches, the same
    number on each, and the averages are taken over all processes.

    Args:
        model (torch.nn.Module): The model; changed in place.
        batches (Iterable): Batches as the model takes them, drawn as in
            training: shuffled, in the training batch size (the training
            examples without augmentation). Batches that each hold one
            class or category would average within-class statistics,
            which normalise the test set wrongly.
        device (torch.device, optional): Where to move each batch (the
            batches given stay where they are).
            (default: :obj:`None`: used where they are)
        process_group (optional): See above. (default: :obj:`None`)

    Returns the number of batches used (0: :obj:`model` has no batch
    norm, nothing was run). On an error (no batches, a failing forward)
    the running statistics are left as they were.
    """
    norms = batch_norms(model)
    if not norms:
        return 0
    saved = {m: m.training for m in model.modules()}
    saved_momentum = {m: m.momentum for m in norms}
    # restored if no recalibration comes of it (no batches, an error)
    saved_buffers = [(buffer, buffer.clone()) for m in norms
                     for buffer in m.buffers(recurse=False)]
    squares = {m: None for m in norms if isinstance(m, ComplexBatchNorm)}
    count = 0
    try:
        model.eval()
        for m in norms:
            m.train()
            if isinstance(m, _BatchNorm):
                m.reset_running_stats()
                m.momentum = None   # cumulative average over the batches
            else:
                m.momentum = 1.0    # running_square <- this batch's value
        for batch in batches:
            if device is not None:   # a shallow copy: the caller's stays
                batch = copy.copy(batch).to(device)
            model(batch)
            count += 1
            for m in squares:
                value = m.running_square.detach().clone()
                squares[m] = value if squares[m] is None \
                    else squares[m] + value
        if count == 0:
            raise ValueError("recalibrate_batch_norm needs at least one "
                             "batch; 'batches' is empty")
        for m, total in squares.items():
            m.running_square.copy_(total / count)
        _average_over_processes(norms, process_group)
    except BaseException:
        for buffer, value in saved_buffers:
            buffer.copy_(value)
        raise
    finally:
        for m, momentum in saved_momentum.items():
            m.momentum = momentum
        for m, training in saved.items():
            m.training = training
    return count


def _average_over_processes(norms, process_group):
    import torch.distributed as dist
    group = active_group(process_group)
    if group is None:
        return
    world = dist.get_world_size(group)
    for m in norms:
        names = ('running_square', ) if isinstance(m, ComplexBatchNorm) \
            else ('running_mean', 'running_var')
        for name in names:
            buffer = getattr(m, name)
            dist.all_reduce(buffer, group=group)
            buffer.div_(world)
