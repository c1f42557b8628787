"""Helpers shared by the datasets (private)."""
import hashlib
import os.path as osp
import re

import numpy as np
from torch_geometric.data import InMemoryDataset


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


def check_split(split):
    if split not in ('train', 'test'):
        raise ValueError(f"'split' must be 'train' or 'test', got {split!r}")
    return split


def check_int(value, name, minimum):
    if isinstance(value, bool) or not isinstance(value, (int, np.integer)):
        raise ValueError(f"'{name}' must be an integer, got {value!r}")
    if value < minimum:
        raise ValueError(f"'{name}' must be at least {minimum}, got {value}")
    return int(value)


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
