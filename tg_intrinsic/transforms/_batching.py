r"""Transforms on collated batches: every transform of this package reads
one graph, so on a :class:`~torch_geometric.data.Batch` it runs on each
graph alone and the results are collated again, exactly what applying it
to every sample and collating them gives (with the batch's
``follow_batch`` vectors). Random transforms therefore draw their
randomness per graph, one draw after the other in the batch's order: the
semantics of a per-sample augmentation."""
from typing import Any, Callable, List, Optional

from torch import Tensor
from torch_geometric.data import Batch, Data
from torch_geometric.transforms import BaseTransform

SAMPLE_ADVICE = ("apply it to every sample alone, as the dataset's "
                 "pre_transform or transform")


def follow_batch_keys(batch: Batch, name: str) -> List[str]:
    """The keys that ``batch`` was collated with ``follow_batch`` for,
    after checking that :meth:`~torch_geometric.data.Batch.to_data_list`
    can split it into its graphs: the batch came from
    :meth:`~torch_geometric.data.Batch.from_data_list` and no attribute was
    added or resized since (``to_data_list`` would drop or mis-slice it
    without a word)."""
    slices = getattr(batch, '_slice_dict', None)
    if slices is None:
        raise ValueError(f"{name} got a Batch that was not made by "
                         f"Batch.from_data_list, so it cannot be split into "
                         f"its graphs; {SAMPLE_ADVICE}")
    followed = [key for key in slices if f'{key}_batch' in batch]
    collated = set(slices) | {'batch', 'ptr'} | {
        f'{key}_{suffix}' for key in followed for suffix in ('batch', 'ptr')}
    added = sorted(set(batch.keys()) - collated)
    resized = []
    for key in slices:
        value = batch[key] if key in batch else None
        dim = batch.__cat_dim__(key, value) if isinstance(value, Tensor) \
            else None
        if isinstance(dim, int) and int(slices[key][-1]) != value.size(dim):
            resized.append(key)
    if added or resized:
        raise ValueError(f"{name} cannot split this Batch into its graphs: "
                         f"{added + resized} changed after collation (set "
                         f"them on the graphs before collating), or "
                         f"{SAMPLE_ADVICE}")
    return followed


def map_graphs(function: Callable[[Data], Data], batch: Batch,
               name: str) -> Batch:
    r"""Applies :obj:`function` to every graph of a collated
    :obj:`batch` alone, in order, and collates the results:
    ``Batch.from_data_list([function(g) for g in batch.to_data_list()])``
    with the batch's ``follow_batch`` keys, so ``ptr``, ``batch`` and
    every index offset are those of the new graphs. Raises a
    :class:`ValueError` that names :obj:`name` if the results cannot be
    collated (different keys, or shapes that do not concatenate)."""
    followed = follow_batch_keys(batch, name)
    results = [function(graph) for graph in batch.to_data_list()]
    first = set(results[0].keys())
    for index, result in enumerate(results[1:], start=1):
        if set(result.keys()) != first:
            differ = sorted(first ^ set(result.keys()))
            raise ValueError(f"{name} gave graph 0 and graph {index} of the "
                             f"batch different attributes {differ}, which "
                             f"cannot be collated into one Batch; choose "
                             f"settings that give every graph the same "
                             f"attributes, or {SAMPLE_ADVICE}")
    try:
        return Batch.from_data_list(results, follow_batch=followed)
    except RuntimeError as error:  # torch.cat of mismatched shapes
        raise ValueError(f"{name} gave the graphs of the batch results that "
                         f"cannot be collated into one Batch ({error}); "
                         f"{SAMPLE_ADVICE}") from error


class GraphTransform(BaseTransform):
    r"""A :class:`~torch_geometric.transforms.BaseTransform` whose
    :meth:`forward` reads a single graph. Called on a collated
    :class:`~torch_geometric.data.Batch`, it runs on every graph alone and
    collates the results (:func:`map_graphs`): ``ptr`` and ``batch`` stay
    valid, :meth:`~torch_geometric.data.Batch.to_data_list` returns what
    the transform gives each graph, and random transforms draw one sample
    of their randomness per graph. A transform whose results cannot be
    collated back sets :attr:`batch_refusal` and refuses batches with a
    :class:`ValueError`."""

    #: Why the transform refuses a collated batch; ``None`` if it runs on
    #: each of its graphs.
    batch_refusal: Optional[str] = None

    def __call__(self, data: Any) -> Any:
        if isinstance(data, Batch):
            name = self.__class__.__name__
            if self.batch_refusal is not None:
                raise ValueError(f"{name} does not run on a collated Batch "
                                 f"({self.batch_refusal}); {SAMPLE_ADVICE}")
            return map_graphs(self.forward, data, name)
        return super().__call__(data)
