"""Reads ShapeNet-Part (the release with normals) from a local folder."""
import json
import os.path as osp
from typing import Dict, List, Optional, Sequence, Union

import numpy as np
import torch

from tg_intrinsic.data import IntrinsicData
from tg_intrinsic.io.labels import to_int_labels
from tg_intrinsic.io.points import read_points

from .common import FolderDataset

LAYOUT = ("shapenetcore_partanno_segmentation_benchmark_v0_normal/ with "
          "synsetoffset2category.txt, <synset>/<token>.txt and "
          "train_test_split/shuffled_{train,val,test}_file_list.json")
# Parts per category. The 50 global part labels number the parts of the
# categories in this (alphabetical) order: Airplane 0-3, Bag 4-5, ...,
# Table 47-49, as in PointNet++'s part segmentation code.
PART_COUNTS = {
    'Airplane': 4, 'Bag': 2, 'Cap': 2, 'Car': 4, 'Chair': 4, 'Earphone': 3,
    'Guitar': 3, 'Knife': 2, 'Lamp': 4, 'Laptop': 2, 'Motorbike': 6,
    'Mug': 2, 'Pistol': 3, 'Rocket': 3, 'Skateboard': 3, 'Table': 3,
}
_START = np.concatenate([[0], np.cumsum(list(PART_COUNTS.values()))])
CATEGORY_PARTS: Dict[str, List[int]] = {
    name: list(range(int(start), int(start) + count))
    for (name, count), start in zip(PART_COUNTS.items(), _START)}
NUM_PARTS = int(_START[-1])


class ShapeNetPartNormal(FolderDataset):
    r"""ShapeNet-Part as PointNet++ released it with normals, read from a
    local folder (nothing is downloaded).

    The data set (Yi et al., 2016) has 16 object categories whose points
    carry one of 50 part labels, in
    :obj:`shapenetcore_partanno_segmentation_benchmark_v0_normal`::

        shapenetcore_partanno_segmentation_benchmark_v0_normal/
        ├── synsetoffset2category.txt   "Airplane<TAB>02691156" per line
        ├── 02691156/
        │   ├── 1a04e3eab45ca15dd86060f189eb133.txt   "x y z nx ny nz part"
        │   └── ...
        ├── ...
        └── train_test_split/
            ├── shuffled_train_file_list.json  ["shape_data/02691156/1a..."]
            ├── shuffled_val_file_list.json
            └── shuffled_test_file_list.json

    :obj:`data.y` holds the global part label of every point (0-49, read
    from the last column), :obj:`data.category` the index of the object
    category in the attribute :obj:`categories`, which lists all 16 in the
    order of :obj:`synsetoffset2category.txt` whatever the argument
    :obj:`categories` selects (so indices agree between selections).
    :obj:`category_parts` maps each category to its part labels
    (Airplane: 0-3, Bag: 4-5, ..., Table: 47-49) and :obj:`part_mask`
    (:math:`(16, 50)` bool) holds the same as rows, to restrict predictions
    to a shape's parts and to average the IoU over them (instance and
    category mIoU). A point whose label is not a part of its category
    raises an error. The processed data are cached in
    :obj:`root/processed_tg_intrinsic*/` with a manifest of the files read.

    Args:
        root (str): The dataset folder.
        split (str, optional): :obj:`"train"`, :obj:`"val"`, :obj:`"test"`
            or :obj:`"trainval"` (train and val). (default:
            :obj:`"trainval"`)
        categories (str or [str], optional): Keep only these categories
            (e.g. :obj:`["Airplane", "Chair"]`). (default: :obj:`None`, all)
        transform (callable, optional): Applied on access.
            (default: :obj:`None`)
        pre_transform (callable, optional): Applied before saving.
            (default: :obj:`None`)
        pre_filter (callable, optional): Keeps a shape if it returns
            :obj:`True`. (default: :obj:`None`)
        log (bool, optional): Print progress. (default: :obj:`True`)
        force_reload (bool, optional): Re-read the files.
            (default: :obj:`False`)
        workers (int, optional): Processes that apply the pre-filter and
            the pre-transform, one thread each; the result does not depend
            on it. (default: :obj:`1`)
        cache_root (str, optional): Keep the processed files under this
            folder instead of inside :obj:`root` (a read-only data set).
            (default: :obj:`None`)

    Raises:
        ValueError: on an unknown category, or naming the file: a missing
            list or shape file, an unknown synset, a shape file without
            7 columns, a non-integer label or one outside its category.

    Shapes:
        - **pos** :math:`(N, 3)` float32
        - **normal** :math:`(N, 3)` float32
        - **y** :math:`(N)` int64 part labels
        - **category** :math:`(1)` int64
    """
    LAYOUT = LAYOUT
    SPLITS = ('train', 'val', 'test', 'trainval')

    def __init__(self, root: str, split: str = 'trainval',
                 categories: Optional[Union[str, Sequence[str]]] = None,
                 transform=None, pre_transform=None, pre_filter=None,
                 log: bool = True, force_reload: bool = False,
                 workers: int = 1,
                 cache_root: Optional[str] = None):
        if isinstance(categories, str):
            categories = [categories]
        if categories is not None:
            unknown = [c for c in categories if c not in PART_COUNTS]
            if unknown or not categories:
                raise ValueError(f"unknown ShapeNet-Part categories "
                                 f"{unknown}; choose from "
                                 f"{list(PART_COUNTS)}")
            categories = sorted(set(categories), key=list(PART_COUNTS).index)
        self.selected = categories
        super().__init__(root, split, transform, pre_transform, pre_filter,
                         log, force_reload, workers, cache_root)
        self.categories: List[str] = self.meta['categories']
        self.category_parts = {c: CATEGORY_PARTS[c] for c in self.categories}
        self.part_mask = torch.zeros(len(self.categories), NUM_PARTS,
                                     dtype=torch.bool)
        for row, name in enumerate(self.categories):
            self.part_mask[row, CATEGORY_PARTS[name]] = True

    @property
    def cache_name(self) -> str:
        return (f'shapenetpart_{self.split}_'
                f'{"-".join(self.selected) if self.selected else "all"}')

    @property
    def num_classes(self) -> int:
        return NUM_PARTS

    def _file(self, *parts: str) -> str:
        path = osp.join(self.root, *parts)
        if not osp.isfile(path):
            raise ValueError(f"ShapeNetPartNormal: '{path}' does not exist; "
                             f"expected the layout {LAYOUT}")
        return path

    def scan(self) -> List[str]:
        synsets = self._file('synsetoffset2category.txt')
        self._categories, synset_index = [], {}
        with open(synsets) as f:
            for row, line in enumerate(f):
                fields = line.split()
                if not fields:
                    continue
                if len(fields) != 2 or fields[0] not in PART_COUNTS:
                    raise ValueError(
                        f"'{synsets}' line {row + 1}: expected '<category> "
                        f"<synset>' with one of the 16 ShapeNet-Part "
                        f"categories {list(PART_COUNTS)}, got {line!r}")
                synset_index[fields[1]] = len(self._categories)
                self._categories.append(fields[0])
        keep = self.selected or self._categories
        splits = ('train', 'val') if self.split == 'trainval' \
            else (self.split, )
        inputs = [synsets]
        self._items = []
        for split in splits:
            lists = self._file('train_test_split',
                               f'shuffled_{split}_file_list.json')
            inputs.append(lists)
            with open(lists) as f:
                try:
                    names = json.load(f)
                except ValueError as error:
                    raise ValueError(f"could not read '{lists}': "
                                     f"{error}") from error
            for name in names:
                if name.count('/') < 1:
                    raise ValueError(f"'{lists}' lists {name!r}; expected "
                                     f"entries 'shape_data/<synset>/<token>'")
                synset, token = name.split('/')[-2:]
                if synset not in synset_index:
                    raise ValueError(f"'{lists}' lists {name!r}, whose synset"
                                     f" '{synset}' is not in '{synsets}'")
                c = synset_index[synset]
                if self._categories[c] in keep:
                    path = osp.join(self.root, synset, token + '.txt')
                    if not osp.isfile(path):
                        raise ValueError(f"'{path}' (listed in '{lists}') "
                                         f"does not exist")
                    self._items.append((path, c))
        if not self._items:
            raise ValueError(f"ShapeNetPartNormal: split '{self.split}' has "
                             f"no shapes of {keep}")
        return inputs + [path for path, _ in self._items]

    def read(self):
        data_list = []
        for path, c in self.progress(self._items, 'shape'):
            pos, normal, label = read_points(path)
            if normal is None or label is None:
                raise ValueError(f"'{path}' must have 7 columns 'x y z nx ny "
                                 f"nz part'")
            labels = to_int_labels(label, path)
            parts = CATEGORY_PARTS[self._categories[c]]
            bad = np.nonzero(~np.isin(labels, parts))[0]
            if bad.size:
                raise ValueError(
                    f"'{path}' row {bad[0] + 1}: part label {labels[bad[0]]} "
                    f"is not a part of {self._categories[c]} (its parts are "
                    f"{parts[0]}-{parts[-1]})")
            data_list.append(IntrinsicData(
                pos=torch.from_numpy(pos).float(),
                normal=torch.from_numpy(normal).float(),
                y=torch.from_numpy(labels), category=torch.tensor([c])))
        return data_list, {'categories': self._categories}

    def __repr__(self) -> str:
        return (f'{self.__class__.__name__}({len(self)}, split={self.split!r},'
                f' categories={self.selected or "all"})')
