"""Helpers shared by the datasets (private)."""
import numpy as np
from torch_geometric.data import InMemoryDataset


class GeneratedDataset(InMemoryDataset):
    """An InMemoryDataset made in ``process()``: no raw files, no download."""
    @property
    def raw_file_names(self):
        return []

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
