"""A :class:`~torch_geometric.data.Data` subclass for multi-level surface data."""
import re
from typing import Any, Dict, Optional, Tuple

import torch
from torch import Tensor
from torch_geometric.data import Data

_LEVEL_KEY = re.compile(r'^(?P<name>.+)_(?P<level>[1-9][0-9]*)$')


class IntrinsicData(Data):
    r"""A :class:`torch_geometric.data.Data` that batches multi-level
    structures (pooling levels, multigrid hierarchies) correctly.

    Level :math:`l \geq 1` attributes carry the suffix ``_l``; level 0 is the
    input itself (``pos``, ``edge_index``, ...). The size :math:`n_l` of level
    :math:`l` is read from ``pos_l`` (or ``num_nodes_l`` when a level has no
    positions). When examples are concatenated by
    :meth:`~torch_geometric.data.Batch.from_data_list`, index attributes are
    offset by the size of the level they point into:

    .. list-table::
        :header-rows: 1

        * - key
          - meaning
          - offset added per example
        * - ``edge_index_l``, ``face_l``
          - graph / triangles on level :math:`l`
          - :math:`n_l`
        * - ``prolong_index_l`` ``[2, nnz]``
          - row 0: fine point (level :math:`l-1`), row 1: coarse point
            (level :math:`l`) of the prolongation :math:`P_{l-1}`
          - :math:`(n_{l-1}, n_l)`
        * - ``cluster_l`` ``[n_{l-1}]``
          - level-:math:`l` point (cell) of every level-:math:`(l-1)` point
          - :math:`n_l`
        * - ``sample_index_l`` ``[n_l]``
          - the level-:math:`(l-1)` point every level-:math:`l` point was
            sampled from
          - :math:`n_{l-1}`
        * - ``pool_edge_index_l`` ``[2, E]``
          - row 0: level-:math:`(l-1)` point, row 1: level-:math:`l` point
          - :math:`(n_{l-1}, n_l)`

    Per-edge attributes (``grad_weight``, ``logmap``, ``prolong_weight_l``,
    ...) contain no index and are concatenated along dimension 0 without
    offsets, which is correct because they follow the row order of their
    index tensor. Keys ending in ``index`` (or ``face``) are concatenated along
    the last dimension, as in PyG. New level-index keys can be declared with
    :meth:`register_level_index`.

    Example:

    .. code-block:: python

        data = IntrinsicData(pos=pos, edge_index=ei, pos_1=pos[idx],
                             sample_index_1=idx, edge_index_1=ei1)
        batch = Batch.from_data_list([data, data])
        batch.level_batch(1)  # example index of every level-1 point
    """

    #: Level offsets of every row of a level-index key, relative to the
    #: key's own level :math:`l`: ``0`` offsets by :math:`n_l`, ``-1`` by
    #: :math:`n_{l-1}`.
    level_index_keys: Dict[str, Tuple[int, ...]] = {
        'edge_index': (0, ),
        'face': (0, ),
        'cluster': (0, ),
        'sample_index': (-1, ),
        'prolong_index': (-1, 0),
        'pool_edge_index': (-1, 0),
    }

    @classmethod
    def register_level_index(cls, name: str, row_levels: Tuple[int, ...]):
        r"""Declares ``name_l`` as an index key whose rows point into the
        levels ``l + row_levels[r]``."""
        if not all(r in (-1, 0) for r in row_levels) or not row_levels:
            raise ValueError("'row_levels' must be a non-empty tuple of 0 "
                             "(same level) and -1 (finer level) entries")
        cls.level_index_keys = {**cls.level_index_keys, name: tuple(row_levels)}

    @staticmethod
    def split_level_key(key: str) -> Optional[Tuple[str, int]]:
        """Returns ``(name, level)`` for a level key ``name_level``."""
        match = _LEVEL_KEY.match(key)
        if match is None:
            return None
        return match.group('name'), int(match.group('level'))

    def level_size(self, level: int) -> int:
        """Number of points :math:`n_l` on level ``level`` (0: the input)."""
        if level == 0:
            num_nodes = self.num_nodes
            if num_nodes is None:
                raise ValueError("cannot infer the number of points of level "
                                 "0; set 'pos' or 'num_nodes'")
            return num_nodes
        pos = getattr(self, f'pos_{level}', None)
        if isinstance(pos, Tensor):
            return pos.size(0)
        num = getattr(self, f'num_nodes_{level}', None)
        if num is not None:  # a Batch holds one count per example
            return int(torch.as_tensor(num).sum())
        raise ValueError(f"level {level} has neither 'pos_{level}' nor "
                         f"'num_nodes_{level}'; set one of them so that its "
                         f"indices can be offset when batching")

    def __inc__(self, key: str, value: Any, *args, **kwargs) -> Any:
        parsed = self.split_level_key(key)
        if parsed is not None and parsed[0] in self.level_index_keys:
            name, level = parsed
            rows = self.level_index_keys[name]
            sizes = [self.level_size(level + r) for r in rows]
            if len(sizes) == 1:
                return sizes[0]
            return torch.tensor(sizes, dtype=torch.long).view(-1, 1)
        if parsed is not None and parsed[0] == 'num_nodes':
            return 0
        return super().__inc__(key, value, *args, **kwargs)

    def __cat_dim__(self, key: str, value: Any, *args, **kwargs) -> Any:
        parsed = self.split_level_key(key)
        if parsed is not None and parsed[0] in self.level_index_keys:
            # 1-D index vectors (cluster, sample_index) concatenate on dim 0.
            return -1 if value.dim() > 1 else 0
        return super().__cat_dim__(key, value, *args, **kwargs)

    def level_batch(self, level: int) -> Tensor:
        """The example index of every point on ``level`` (like ``batch``)."""
        if level == 0 and getattr(self, 'batch', None) is not None:
            return self.batch
        device = next((v.device for _, v in self if isinstance(v, Tensor)),
                      torch.device('cpu'))
        slices = getattr(self, '_slice_dict', None)
        key = 'pos' if level == 0 else f'pos_{level}'
        if slices is not None and key in slices:
            counts = slices[key].diff()
        elif slices is not None and f'num_nodes_{level}' in slices:
            counts = torch.as_tensor(getattr(self, f'num_nodes_{level}'))
        else:  # a single example
            counts = torch.tensor([self.level_size(level)])
        counts = counts.to(device)
        return torch.repeat_interleave(
            torch.arange(counts.numel(), device=device), counts)


# Allow `torch.load(weights_only=True)` (used by InMemoryDataset.load) to
# rebuild this class without falling back to unsafe unpickling.
torch.serialization.add_safe_globals([IntrinsicData])
