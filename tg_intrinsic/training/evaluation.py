"""Evaluation: accuracy (per shape, per point, instance mIoU), the
recalibration of batch statistics and the gap it closes."""
import math
from typing import Dict, List

import torch

from tg_intrinsic import distributed
from tg_intrinsic.devices import autocast
from tg_intrinsic.nn.recalibrate_batch_norm import batch_statistics_copy


def instance_miou(pred: torch.Tensor, y: torch.Tensor,
                  parts: torch.Tensor) -> float:
    r"""Mean intersection over union of one shape's parts, as ShapeNet-Part
    is scored: over the parts :obj:`parts` (a boolean mask over labels) of
    its category, a part absent from both prediction and truth counting
    as 1. It computes

    .. math::
        \mathrm{mIoU} = \frac{1}{|P|} \sum_{p \in P}
        \frac{|\{\hat y = p\} \cap \{y = p\}|}
        {|\{\hat y = p\} \cup \{y = p\}|} .
    """
    labels = parts.nonzero().flatten()
    hit = pred.view(-1, 1) == labels.view(1, -1)
    true = y.view(-1, 1) == labels.view(1, -1)
    inter = (hit & true).sum(0).double()
    union = (hit | true).sum(0).double()
    iou = torch.where(union > 0, inter / union.clamp_min(1),
                      torch.ones_like(union))
    return float(iou.mean())


@torch.no_grad()
def evaluate(model, loader, device, part_mask=None,
             statistics: str = 'running', precision: str = '32-true'
             ) -> Dict:
    """Accuracy over shapes (classification) or points (segmentation); with
    a category-to-parts :obj:`part_mask` also the instance-averaged mIoU.
    In a data-parallel run every process scores its part of the test set
    (its :obj:`loader`) and the counts are summed over the processes.
    :obj:`statistics` is ``'running'`` (``model.eval()``, what inference
    gives) or ``'batch'`` (batch norms normalise with each test batch's own
    statistics, on a copy of the model: see
    :func:`batch_statistics_copy`); :obj:`precision` that of training
    (:data:`~tg_intrinsic.devices.PRECISIONS`)."""
    if statistics == 'batch':
        model = batch_statistics_copy(model)
    else:
        model.eval()
    correct = total = 0
    ious = []
    for batch in loader:
        batch = batch.to(device)
        with autocast(precision, device):
            pred = model(batch).argmax(dim=-1)
        correct += int((pred == batch.y.view(-1)).sum())
        total += pred.numel()
        if part_mask is not None:
            for b in range(batch.num_graphs):
                at = batch.batch == b
                ious.append(instance_miou(
                    pred[at], batch.y[at],
                    part_mask[int(batch.category[b])].to(device)))
    sums = distributed.all_reduce_sum(torch.tensor(
        [correct, total, math.fsum(ious), len(ious)], dtype=torch.float64,
        device=device))
    out = {'accuracy': int(sums[0]) / max(int(sums[1]), 1)}
    if int(sums[3]):
        out['miou'] = float(sums[2]) / int(sums[3])
    return out


# Training batches whose statistics replace batch norms' running ones
# before every evaluation (recalibrate_batch_norm).
RECALIBRATION_BATCHES = 200


def whole_batches(length: int, batch_size: int) -> List[List[int]]:
    """``range(length)`` in batches of :obj:`batch_size`, the remainder
    joined to the last batch: batch statistics need at least two shapes in
    every batch (when :obj:`length` is at least 2)."""
    count = max(1, length // batch_size)
    bounds = [b * batch_size for b in range(count)] + [length]
    return [list(range(bounds[b], bounds[b + 1])) for b in range(count)]


def statistics_gap(record: Dict, points: float = 1.0) -> str:
    """A note for the log when the test accuracy with batch statistics
    differs from the eval-mode one by more than :obj:`points` points."""
    other = record.get('test_accuracy_batch_statistics')
    if other is None or abs(other - record['test_accuracy']) * 100 <= points:
        return ''
    return (f" (with batch statistics {other:.3f}: eval-mode inference "
            f"differs by more than {points:g} point)")
