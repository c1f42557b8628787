"""Precomputed examples in an on-disk database (PyG's OnDiskDataset)."""
import hashlib
import io
import json
import os
import os.path as osp
import re
import warnings
from typing import Any, Callable, Dict, List, Optional, Sequence

import torch
from torch_geometric.data import OnDiskDataset
from torch_geometric.data.data import BaseData

from tg_intrinsic.geometry.checks import check_positive_int
from tg_intrinsic.parallel import check_picklable, parallel_map

from .common import check_workers


def _plain(value) -> str:
    """``repr`` without memory addresses (stable from run to run)."""
    return re.sub(r' at 0x[0-9a-fA-F]+', '', repr(value))


def _digest(value, h) -> None:
    """Feeds ``value`` (tensors, Data, containers, plain values) into the
    hash ``h``."""
    if isinstance(value, torch.Tensor):
        h.update(f'T{value.dtype}{tuple(value.shape)}'.encode())
        h.update(value.detach().cpu().contiguous().view(-1)
                 .view(torch.uint8).numpy().tobytes()
                 if value.numel() else b'')
    elif isinstance(value, BaseData):
        h.update(type(value).__qualname__.encode())
        for key in sorted(value.keys()):
            h.update(key.encode())
            _digest(value[key], h)
    elif isinstance(value, (list, tuple)):
        h.update(f'L{len(value)}'.encode())
        for item in value:
            _digest(item, h)
    elif isinstance(value, dict):
        for key in sorted(value, key=str):
            h.update(str(key).encode())
            _digest(value[key], h)
    else:
        h.update(_plain(value).encode())


def _to_bytes(data: BaseData) -> bytes:
    buffer = io.BytesIO()
    torch.save(data, buffer)
    return buffer.getvalue()


class _Precompute:
    """``pre_transform(item)``, checked to be a Data object, serialised
    (the work of one example in a worker process: the main process only
    writes the bytes)."""
    def __init__(self, pre_transform):
        self.pre_transform = pre_transform

    def __call__(self, item) -> bytes:
        out = item if self.pre_transform is None else \
            self.pre_transform(item)
        if not isinstance(out, BaseData):
            raise TypeError(f"the pre_transform must return a "
                            f"torch_geometric Data object, got "
                            f"{type(out).__name__}")
        return _to_bytes(out)


class _Range:
    """``source[start:]`` as a lazy sequence."""
    def __init__(self, source, start: int):
        self.source, self.start = source, start

    def __len__(self) -> int:
        return len(self.source) - self.start

    def __iter__(self):
        for i in range(self.start, len(self.source)):
            yield self.source[i]


class PrecomputedOnDisk(OnDiskDataset):
    r"""Precomputed examples (DeltaConv's MLS operators, Harmonic Surface
    Networks' log maps, transport and harmonic terms on several levels, a
    Gravo MG hierarchy, ...) stored in an on-disk database, so that data
    sets whose precomputation does not fit in memory can be trained on with
    the ordinary :class:`~torch_geometric.loader.DataLoader`. Built on
    PyG's :class:`~torch_geometric.data.OnDiskDataset` (SQLite backend;
    every example is one row, serialised with :func:`torch.save` in the
    worker that computed it, so the
    :class:`~torch_geometric.data.Data` subclass, e.g.
    :class:`~tg_intrinsic.data.IntrinsicData` and its per-level batching,
    survives the round trip).

    Example :math:`i` of the data set is

    .. math::
        \mathcal{D}_i = \mathrm{pre\_transform}(\mathrm{source}_i),
        \qquad i = 0, \dots, |\mathrm{source}| - 1,

    computed once by :obj:`workers` processes (one thread each; the stored
    examples do not depend on the number of workers) and written in
    order, :obj:`chunk_size` examples per database transaction, so memory
    stays bounded by a few chunks whatever the size.

    The write is resumable and never read as complete when it is not:
    ``root/processed/started.json`` records the settings when a write
    starts, every committed chunk stays, and ``root/processed/
    complete.json`` is written (atomically) after the last one. A killed
    run resumes at the first missing example when the data set is made
    again with the same settings; with other settings an unfinished
    database is started over. A finished one made with another
    :obj:`pre_transform` or another source (its length, or the contents
    of its first, middle and last items) raises a :class:`ValueError`
    that lists the differences (pass :obj:`force_reload=True` to rebuild).

    Args:
        root (str): Folder of the database (``root/processed/sqlite.db``).
        source (Sequence): The examples to precompute: a data set, a list
            of :class:`~torch_geometric.data.Data`, or any sequence of
            picklable items that :obj:`pre_transform` turns into Data;
            :obj:`None` opens the finished database in :obj:`root` as it
            is (e.g. in another process), without checking its settings.
        pre_transform (callable, optional): Applied to every source item
            before it is stored, e.g.
            :class:`~tg_intrinsic.transforms.MLSOperators`; with more than
            one worker it must be picklable (a module-level function or
            class instance). (default: :obj:`None`, the items are stored
            as they are)
        transform (callable, optional): Applied to every example on
            access. (default: :obj:`None`)
        workers (int, optional): Processes that run :obj:`pre_transform`.
            (default: :obj:`1`)
        chunk_size (int, optional): Examples per database transaction.
            (default: :obj:`32`)
        log (bool, optional): Print progress. (default: :obj:`True`)
        force_reload (bool, optional): Delete the database and precompute
            again. (default: :obj:`False`)

    Shapes:
        - **output:** what :obj:`pre_transform` returns, one example per
          source item
    """
    #: Bumped whenever the stored format changes.
    version = 2
    #: One column: the example as :func:`torch.save` writes it.
    SCHEMA = {'data': dict(dtype=torch.uint8, size=(-1, ))}

    def __init__(self, root: str, source: Optional[Sequence],
                 pre_transform: Optional[Callable] = None,
                 transform: Optional[Callable] = None, workers: int = 1,
                 chunk_size: int = 32, log: bool = True,
                 force_reload: bool = False):
        name = type(self).__name__
        root = osp.expanduser(os.fspath(root))
        folder = osp.join(root, 'processed')
        if source is None:  # open a finished database as it is
            done = self._read(osp.join(folder, 'complete.json'))
            if done is None or not osp.exists(osp.join(folder, 'sqlite.db')):
                raise ValueError(f"{name}: '{folder}' holds no finished "
                                 f"database; give the 'source' to "
                                 f"precompute it")
            self.source, self.precompute = None, pre_transform
            self.workers, self.chunk_size = 1, 1
            self.settings = done['settings']
            super().__init__(root, transform, schema=dict(self.SCHEMA),
                             log=log)
            self.pre_transform = pre_transform
            return
        try:
            length = len(source)
        except TypeError:
            raise TypeError(f"{name}: 'source' must be a sequence (a data "
                            f"set or a list) with a length, got "
                            f"{type(source).__name__}") from None
        if length == 0:
            raise ValueError(f"{name}: 'source' is empty; give at least one "
                             f"example to precompute")
        self.workers = check_workers(workers)
        self.chunk_size = check_positive_int(chunk_size, 'chunk_size', 1)
        if self.workers > 1 and pre_transform is not None:
            check_picklable(pre_transform, 'pre_transform', name)
        self.source, self.precompute = source, pre_transform
        self.settings = self.settings_of(source, pre_transform)
        if force_reload:
            self._remove(folder)
        self._check_finished(folder)
        super().__init__(root, transform, schema=dict(self.SCHEMA), log=log)
        self.pre_transform = pre_transform

    # ------------------------------------------------------------------
    @property
    def processed_file_names(self) -> List[str]:
        return [f'{self.backend}.db', 'complete.json']

    @classmethod
    def settings_of(cls, source: Sequence, pre_transform) -> Dict[str, Any]:
        """What the stored examples depend on: the format, the
        pre-transform (as it prints) and the source's type, length and a
        hash of its first, middle and last items."""
        n = len(source)
        h = hashlib.sha1()
        for i in sorted({0, n // 2, n - 1}):
            _digest(source[i], h)
        return {'format': cls.version, 'pre_transform': _plain(pre_transform),
                'source': type(source).__name__, 'length': n,
                'digest': h.hexdigest()}

    @staticmethod
    def _read(path: str) -> Optional[Dict]:
        try:
            with open(path) as f:
                return json.load(f)
        except (OSError, ValueError):
            return None

    def _remove(self, folder: str):
        if getattr(self, '_db', None) is not None:
            self.close()
            self._db = None
        for name in ('sqlite.db', 'sqlite.db-journal', 'complete.json',
                     'started.json'):
            if osp.exists(osp.join(folder, name)):
                os.remove(osp.join(folder, name))

    def _check_finished(self, folder: str):
        done = self._read(osp.join(folder, 'complete.json'))
        if done is None or not osp.exists(osp.join(folder, 'sqlite.db')):
            return
        if done.get('settings') != self.settings:
            old = done.get('settings') or {}
            changes = [f"{key} {old.get(key)!r} -> {value!r}"
                       for key, value in self.settings.items()
                       if old.get(key) != value]
            raise ValueError(
                f"{type(self).__name__}: '{folder}' holds examples made "
                f"with other settings ({'; '.join(changes)}); pass "
                f"force_reload=True to precompute them again, or give "
                f"another root")

    def process(self):
        from tg_intrinsic.utils import atomic_write_json
        folder = self.processed_dir
        started = osp.join(folder, 'started.json')
        if self._read(started) != self.settings:  # nothing to resume
            self._remove(folder)
            atomic_write_json(started, self.settings)
        start = len(self.db)
        name = type(self).__name__
        chunk = []
        for data in parallel_map(
                _Precompute(self.precompute), _Range(self.source, start),
                self.workers, desc=f'Precomputing {name}', log=self.log,
                unit='example',
                name_of=lambda i, _: f'{name} example {start + i}'):
            chunk.append(data)
            if len(chunk) == self.chunk_size:
                self.extend(chunk)
                chunk = []
        if chunk:
            self.extend(chunk)
        atomic_write_json(osp.join(folder, 'complete.json'),
                          {'settings': self.settings, 'length': len(self)})

    def serialize(self, data) -> Dict[str, torch.Tensor]:
        """The database row of ``data`` (a Data object, or its bytes)."""
        blob = data if isinstance(data, bytes) else _to_bytes(data)
        with warnings.catch_warnings():  # read-only bytes: never written
            warnings.simplefilter('ignore')
            return {'data': torch.frombuffer(blob, dtype=torch.uint8)}

    def deserialize(self, row: Dict[str, torch.Tensor]) -> BaseData:
        return torch.load(io.BytesIO(row['data'].numpy()), weights_only=False)

    def __getitems__(self, indices: List[int]) -> List[BaseData]:
        # through self.indices(), so a subset (index_select) batches its
        # own examples
        order = self.indices()
        return self.multi_get([int(order[i]) for i in indices])

    def __repr__(self) -> str:
        return (f'{self.__class__.__name__}({len(self)}, pre_transform='
                f'{self.pre_transform}, root={self.root!r})')
