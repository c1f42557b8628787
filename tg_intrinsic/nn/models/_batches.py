"""Which example every point of a (batched) data object belongs to, shared
by the DeltaNet and HSN models."""
from typing import Tuple

import torch
from torch import Tensor
from torch_geometric.data import Data


def graph_batch(data: Data, x: Tensor) -> Tuple[Tensor, int]:
    """The example index of every point of ``x`` and the number of
    examples (from a :class:`~torch_geometric.data.Batch`'s own count
    where it has one, so that ``torch.compile`` reads no tensor value):
    zeros and 1 for a single example."""
    batch = getattr(data, 'batch', None)
    if batch is None:
        return torch.zeros(x.size(0), dtype=torch.long, device=x.device), 1
    size = getattr(data, 'num_graphs', None)
    return batch, int(batch.max()) + 1 if size is None else size
