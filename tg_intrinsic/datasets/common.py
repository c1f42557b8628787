"""Helpers shared by the datasets (private)."""
import copy
import hashlib
import json
import os
import os.path as osp
import re
from typing import Dict, List, Optional, Sequence

import numpy as np
from torch_geometric.data import InMemoryDataset
from tqdm.auto import tqdm

from tg_intrinsic.data import IntrinsicData
from tg_intrinsic.geometry.checks import check_positive_int
from tg_intrinsic.parallel import check_picklable, parallel_map


def processing_suffix(pre_transform, pre_filter) -> str:
    """``''`` without pre-processing, else ``'_'`` and a hash of what the
    pre-transform and pre-filter print as: each pre-processing gets its own
    processed folder, so a cache made with another (or no) pre-transform is
    never silently reused. Memory addresses are dropped from the text so
    functions hash the same from run to run."""
    if pre_transform is None and pre_filter is None:
        return ''
    text = ' | '.join(re.sub(r' at 0x[0-9a-fA-F]+', '', repr(f))
                      for f in (pre_transform, pre_filter))
    return '_' + hashlib.sha1(text.encode()).hexdigest()[:10]


class GeneratedDataset(InMemoryDataset):
    """An InMemoryDataset made in ``process()``: no raw files, no download.
    The processed folder is ``root/processed`` plus
    :func:`processing_suffix`."""
    @property
    def raw_file_names(self):
        return []

    @property
    def processed_dir(self) -> str:
        return osp.join(self.root, 'processed' + processing_suffix(
            self.pre_transform, self.pre_filter))

    def download(self):
        pass

    def generate_splits(self, groups: int, counts, desc: str):
        """Generates shape ``j`` of every group (class, category)
        ``c < groups`` with ``self.generate(c, j)``, the first
        ``counts[0]`` of a group for training and the next ``counts[1]``
        for testing, applies the pre-filter and the pre-transform (in
        ``self.workers`` processes, see :func:`map_examples`), and saves
        the two splits to :attr:`processed_paths` atomically."""
        train, test = counts
        keys = [(c, j) for c in range(groups) for j in range(train + test)]
        lists = ([], [])
        results = map_examples(self, _Generate(worker_copy(self)), keys,
                               desc, 'shape', lambda _, key:
                               f'{type(self).__name__} group {key[0]} '
                               f'shape {key[1]}')
        for (_, j), data in zip(keys, results):
            if data is not None:
                lists[0 if j < train else 1].append(data)
        for data_list, path in zip(lists, self.processed_paths):
            if len(data_list) == 0:
                raise ValueError("'pre_filter' removed every shape of a split")
            save_atomic(type(self), data_list, path)


def check_workers(workers) -> int:
    """A positive number of worker processes."""
    return check_positive_int(workers, 'workers', 1)


def worker_copy(dataset):
    """A shallow copy of ``dataset`` to send to worker processes: without
    its on-access ``transform`` (not needed there, and maybe not
    picklable) and without loaded data."""
    light = copy.copy(dataset)
    light.transform = None
    for name in ('_data', 'slices', '_data_list'):
        if name in vars(light):
            setattr(light, name, None)
    return light


def preprocess(dataset, data):
    """``data`` after the ``pre_filter`` (``None`` if it drops it) and the
    ``pre_transform`` of ``dataset``."""
    if dataset.pre_filter is not None and not dataset.pre_filter(data):
        return None
    if dataset.pre_transform is not None:
        data = dataset.pre_transform(data)
    return data


def map_examples(dataset, function, items, desc: str, unit: str,
                 name_of=None):
    """:func:`~tg_intrinsic.parallel.parallel_map` of ``function`` over
    ``items`` with ``dataset.workers`` processes and ``dataset.log``; with
    more than one worker, a pre-transform or pre-filter that cannot be
    pickled is named in a :class:`TypeError` that says what to do."""
    workers = getattr(dataset, 'workers', 1)
    if workers > 1 and len(items) > 1:
        for what in ('pre_transform', 'pre_filter'):
            value = getattr(dataset, what, None)
            if value is not None:
                check_picklable(value, what, type(dataset).__name__)
    return parallel_map(function, items, workers, desc=desc,
                        log=dataset.log, unit=unit, name_of=name_of)


class _Generate:
    """``dataset.generate(c, j)``, pre-filtered and pre-transformed (the
    work of one shape in a worker process)."""
    def __init__(self, dataset):
        self.dataset = dataset

    def __call__(self, key):
        return preprocess(self.dataset, self.dataset.generate(*key))


class _Preprocess:
    """The pre-filter and pre-transform of ``dataset`` on one example."""
    def __init__(self, dataset):
        self.dataset = dataset

    def __call__(self, data):
        return preprocess(self.dataset, data)


def check_option(value, name, options):
    if value not in options:
        raise ValueError(f"'{name}' must be one of {tuple(options)}, got "
                         f"{value!r}")
    return value


def check_task(task, **segmentation_options):
    """``task`` is one of :data:`TASKS`; the ``segmentation_options``
    (``name=(value, default)``) keep their defaults for classification."""
    check_option(task, 'task', TASKS)
    changed = [name for name, (value, default) in
               segmentation_options.items() if value != default]
    if task == 'classification' and changed:
        raise ValueError(f"{', '.join(map(repr, changed))} apply to "
                         f"task='segmentation' only; classification takes "
                         f"its classes from the folder names")
    return task


def check_split(split, splits=('train', 'test')):
    return check_option(split, 'split', splits)


def check_split_counts(counts, name):
    """A pair (train, test) of positive shape counts."""
    try:
        train, test = counts
    except (TypeError, ValueError):
        raise ValueError(f"'{name}' must be a pair (train, test), got "
                         f"{counts!r}") from None
    return (check_positive_int(train, f'{name}[0]', 1),
            check_positive_int(test, f'{name}[1]', 1))


def check_fraction(value, name) -> float:
    """A number in [0, 1]."""
    value = float(value)
    if not 0.0 <= value <= 1.0:
        raise ValueError(f"'{name}' must be in [0, 1], got {value}")
    return value


def fmt(value):
    """Short, file-name safe text of a generation parameter."""
    if isinstance(value, (bool, np.bool_)):
        return str(int(value))
    if isinstance(value, (float, np.floating)):
        return np.format_float_positional(float(value), trim='-')
    if isinstance(value, (tuple, list)):
        return '-'.join(fmt(v) for v in value)
    return str(value)


def shape_rng(seed, *keys):
    """Independent generator per shape: shape ``keys`` do not depend on how
    many shapes are generated, so a larger dataset extends a smaller one."""
    return np.random.default_rng(np.random.SeedSequence([int(seed), *keys]))


def save_atomic(dataset_cls, data_list, path):
    """Like :meth:`InMemoryDataset.save`, but through a temporary file, so
    an interrupted generation never leaves a truncated cache behind."""
    from tg_intrinsic.utils import atomic_torch_save
    data, slices = dataset_cls.collate(data_list)
    atomic_torch_save((data.to_dict(), slices, data.__class__), path)


PROCESSED = 'processed_tg_intrinsic'
TASKS = ('classification', 'segmentation')


def processed_folder(root, pre_transform, pre_filter) -> str:
    """``root/processed_tg_intrinsic`` plus :func:`processing_suffix`."""
    return osp.join(root, PROCESSED + processing_suffix(pre_transform,
                                                        pre_filter))


def cache_base(root: str, cache_root: Optional[str]) -> str:
    """Where a folder data set keeps its processed files: inside ``root``,
    or, with ``cache_root`` (a read-only data set, a shared one), in a
    folder of its own under ``cache_root`` named after ``root``'s path."""
    if cache_root is None:
        return root
    real = osp.realpath(root)
    return osp.join(osp.expanduser(os.fspath(cache_root)), 'folder_cache',
                    osp.basename(real) + '-' +
                    hashlib.sha1(real.encode()).hexdigest()[:10])


def list_files(folder: str, extensions: Sequence[str]) -> List[str]:
    """Sorted paths of the files in ``folder`` whose (lower-case)
    extension is in ``extensions``; ``[]`` if there is no such folder."""
    if not osp.isdir(folder):
        return []
    return [osp.join(folder, name) for name in sorted(os.listdir(folder))
            if osp.splitext(name)[1].lower() in extensions
            and osp.isfile(osp.join(folder, name))]


def class_folders(root: str, splits: Sequence[str]) -> List[str]:
    """Sorted names of the folders of ``root`` that hold a folder named
    after one of ``splits`` (hidden and processed folders skipped)."""
    return [name for name in sorted(os.listdir(root))
            if not name.startswith(('.', PROCESSED))
            and any(osp.isdir(osp.join(root, name, s)) for s in splits)]


def find_label_file(stem: str, beside: str, beside_extensions,
                    folders, folder_extensions) -> Optional[str]:
    """The label file of ``stem``: ``beside/stem.EXT`` for an extension in
    ``beside_extensions``, or ``FOLDER/stem.EXT`` for a folder in
    ``folders`` and an extension in ``folder_extensions``; ``None`` if
    there is none, a :class:`ValueError` listing them if there are
    several."""
    candidates = [osp.join(beside, stem + ext) for ext in beside_extensions]
    candidates += [osp.join(folder, stem + ext) for folder in folders
                   for ext in folder_extensions]
    found = [path for path in candidates if osp.isfile(path)]
    if len(found) > 1:
        raise ValueError(f"several label files for '{stem}': {found}; keep "
                         f"one of them")
    return found[0] if found else None


def file_manifest(root: str, paths: Sequence[str]) -> Dict[str, list]:
    """``{name relative to root: [size, mtime_ns]}`` of every input file."""
    manifest = {}
    for path in paths:
        stat = os.stat(path)
        manifest[osp.relpath(path, root)] = [stat.st_size, stat.st_mtime_ns]
    return manifest


class FolderDataset(InMemoryDataset):
    """An InMemoryDataset read from the user's local folder, never
    downloaded.

    The processed data go to ``root/processed_tg_intrinsic<suffix>/`` (a
    folder per pre-transform and pre-filter, see
    :func:`processing_suffix`) as ``<cache_name>.pt``, with
    ``<cache_name>_meta.json`` (what :meth:`read` returns beside the data,
    e.g. the class names) and ``<cache_name>_manifest.json``: the relative
    name, size and modification time of every input file :meth:`scan`
    lists. The files are read again when that manifest differs from the
    folder's (a file added, removed or changed) or with
    ``force_reload=True``. Every file is written atomically, the manifest
    last. With ``cache_root`` (a read-only data set) the processed folder
    lies under ``cache_root`` instead (:func:`cache_base`).

    Subclasses set ``LAYOUT`` (the folder layout, for error messages) and
    ``SPLITS``, and define ``cache_name`` (a file name for the split and
    every option that changes the data), ``scan()`` (the input files) and
    ``read()`` (``(list of Data, meta dict)``).
    """
    LAYOUT = ''
    SPLITS = ('train', 'test')

    def __init__(self, root, split, transform, pre_transform, pre_filter,
                 log, force_reload, workers: int = 1,
                 cache_root: Optional[str] = None):
        self.split = check_split(split, self.SPLITS)
        self.workers = check_workers(workers)
        root = osp.expanduser(os.fspath(root))
        if not osp.isdir(root):
            raise ValueError(f"{type(self).__name__}: '{root}' is not a "
                             f"folder; expected the layout {self.LAYOUT}")
        self.root = root
        self.cache_base = cache_base(root, cache_root)
        self.manifest = file_manifest(root, self.scan())
        path = osp.join(processed_folder(self.cache_base, pre_transform,
                                         pre_filter),
                        self.cache_name + '_manifest.json')
        stored = None
        if osp.isfile(path):
            with open(path) as f:
                stored = json.load(f)
        super().__init__(root, transform, pre_transform, pre_filter, log=log,
                         force_reload=force_reload or stored != self.manifest)
        self.load(self.processed_paths[0], data_cls=IntrinsicData)
        with open(self.processed_paths[1]) as f:
            self.meta = json.load(f)

    @property
    def raw_dir(self) -> str:
        return self.root

    @property
    def raw_file_names(self):
        return []

    @property
    def processed_dir(self) -> str:
        return processed_folder(self.cache_base, self.pre_transform,
                                self.pre_filter)

    @property
    def processed_file_names(self):
        return [self.cache_name + '.pt', self.cache_name + '_meta.json',
                self.cache_name + '_manifest.json']

    def class_items(self, extensions: Sequence[str]):
        """``(classes, [(path, class index), ...])`` of the classification
        layout ``root/<class>/<split>/*``: classes are the sorted folders
        with a ``train`` or ``test`` folder."""
        name = type(self).__name__
        classes = class_folders(self.root, ('train', 'test'))
        if not classes:
            raise ValueError(f"{name}: no class folders with a 'train' or "
                             f"'test' sub-folder in '{self.root}'; expected "
                             f"the layout {self.LAYOUT}")
        items = [(path, c) for c, cls in enumerate(classes)
                 for path in list_files(osp.join(self.root, cls, self.split),
                                        extensions)]
        if not items:
            raise ValueError(f"{name}: no {'/'.join(extensions)} files for "
                             f"split '{self.split}' under '{self.root}' "
                             f"(classes: {classes}); expected the layout "
                             f"{self.LAYOUT}")
        return classes, items

    def progress(self, items, unit: str):
        """``items`` with a progress bar when ``log`` is on."""
        return tqdm(items, desc=f'Reading {type(self).__name__} '
                    f'({self.split})', disable=not self.log, unit=unit)

    def process(self):
        from tg_intrinsic.utils import atomic_write_json
        data_list, meta = self.read()
        if self.pre_filter is not None or self.pre_transform is not None:
            name = type(self).__name__
            data_list = [data for data in map_examples(
                self, _Preprocess(worker_copy(self)), data_list,
                f'Pre-processing {name} ({self.split})', 'example',
                lambda index, data: getattr(data, 'path', None) or
                f'{name} example {index}') if data is not None]
            if not data_list:
                raise ValueError(f"{name}: 'pre_filter' removed every "
                                 f"example of split '{self.split}' in "
                                 f"'{self.root}'")
        save_atomic(type(self), data_list, self.processed_paths[0])
        atomic_write_json(self.processed_paths[1], meta)
        atomic_write_json(self.processed_paths[2], self.manifest)
