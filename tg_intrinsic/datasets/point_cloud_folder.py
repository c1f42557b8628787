"""Reads a folder of point clouds, with classes or per-point labels."""
import os.path as osp
from typing import List, Optional

import torch

from tg_intrinsic.data import IntrinsicData
from tg_intrinsic.geometry.checks import check_positive_int
from tg_intrinsic.io.labels import check_labels, read_labels, to_int_labels
from tg_intrinsic.io.points import POINT_EXTENSIONS, read_points

from .common import FolderDataset, check_task, find_label_file, list_files

# label files beside a point file, and in the label folders
BESIDE_LABELS = ('.seg', '.labels', '.label')
FOLDER_LABELS = BESIDE_LABELS + ('.txt', '.npy')
LABEL_FOLDERS = ('labels', 'seg', 'points_label')
LAYOUT = ("root/<class>/<split>/<name>.ply|.txt|.xyz|.npy|.pts for "
          "classification, root/<split>/<name>.ply|.txt|.xyz|.npy|.pts with "
          "a label column or label files for segmentation")


class PointCloudFolder(FolderDataset):
    r"""A dataset of point clouds from a local folder, for classification
    (one class per cloud) or segmentation (one label per point): the point
    cloud counterpart of :class:`MeshFolder`. Nothing is downloaded.

    **Classification** (:obj:`task="classification"`): classes are the
    sub-folders with a :obj:`train` or :obj:`test` folder, sorted;
    :obj:`data.y` is the index into :obj:`classes`::

        root/
        ├── chair/
        │   ├── train/chair_0001.txt  chair_0002.ply ...
        │   └── test/...
        └── lamp/
            ├── train/...
            └── test/...

    **Segmentation** (:obj:`task="segmentation"`): :obj:`data.y` holds one
    0-based label per point, from a label file (one integer per line, or a
    1-D :obj:`.npy`) or else from the point file's label column::

        root/
        ├── train/
        │   ├── scan1.txt          x y z [nx ny nz] label
        │   ├── scan2.xyz
        │   └── scan2.seg          labels beside the points (same stem), or
        ├── test/scan3.pts
        └── points_label/scan3.seg ... in labels/, seg/ or points_label/

    The label file of :obj:`<stem>.*` is :obj:`<stem>.seg|.labels|.label`
    beside it, or :obj:`<stem>.seg|.labels|.label|.txt|.npy` in
    :obj:`root/labels/`, :obj:`root/seg/` or :obj:`root/points_label/`
    (the folder of ShapeNet-Part's original release, whose :obj:`.seg`
    labels are 1-based: pass :obj:`label_offset=1`); at most one may exist.
    Without one, the label is the last column of a 4-column (:obj:`x y z
    label`) or 7-column (:obj:`x y z nx ny nz label`) table, or the
    :obj:`label` / :obj:`class` property of a PLY file.

    Point files (:func:`~tg_intrinsic.io.points.read_points`): tables
    (:obj:`.txt`, :obj:`.xyz`, :obj:`.pts`, :obj:`.npy`; whitespace or
    comma separated) hold :obj:`x y z` in columns 1-3 and normals in
    columns 4-6 when there are at least 6 columns; PLY files hold normals
    as :obj:`nx ny nz`. Normals go to :obj:`data.normal`; every cloud of a
    split must have them or none. Points are kept as read (no sampling,
    no reordering). The processed data are cached in
    :obj:`root/processed_tg_intrinsic*/` with a manifest of the input
    files: adding, removing or changing a file re-reads the folder.

    Args:
        root (str): The dataset folder.
        split (str, optional): :obj:`"train"` or :obj:`"test"`.
            (default: :obj:`"train"`)
        task (str, optional): :obj:`"classification"` or
            :obj:`"segmentation"`. (default: :obj:`"classification"`)
        label_offset (int, optional): Subtracted from every label (1 for
            1-based files). (default: :obj:`0`)
        num_classes (int, optional): The number of segmentation classes;
            labels must lie below it. (default: :obj:`None`, the largest
            label over both splits plus one)
        transform (callable, optional): Applied on access.
            (default: :obj:`None`)
        pre_transform (callable, optional): Applied before saving.
            (default: :obj:`None`)
        pre_filter (callable, optional): Keeps a cloud if it returns
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
        ValueError: if :obj:`root` does not follow the layout, or naming
            the file: a point file that cannot be read, a missing label
            file (and no label column), labels that are not integers, are
            negative or out of range, or not one per point.

    Shapes:
        - **pos** :math:`(N, 3)` float32
        - **normal** :math:`(N, 3)` float32, when the files have normals
        - **y** :math:`(1)` int64 class index (classification), or
          :math:`(N)` int64 point labels (segmentation)
    """
    LAYOUT = LAYOUT

    def __init__(
        self,
        root: str,
        split: str = 'train',
        task: str = 'classification',
        label_offset: int = 0,
        num_classes: Optional[int] = None,
        transform=None,
        pre_transform=None,
        pre_filter=None,
        log: bool = True,
        force_reload: bool = False,
        workers: int = 1,
        cache_root: Optional[str] = None,
    ):
        self.task = check_task(task, label_offset=(label_offset, 0),
                               num_classes=(num_classes, None))
        self.label_offset = check_positive_int(label_offset, 'label_offset', 0)
        self.num_classes_arg = None if num_classes is None else \
            check_positive_int(num_classes, 'num_classes', 1)
        super().__init__(root, split, transform, pre_transform, pre_filter,
                         log, force_reload, workers, cache_root)
        self.classes: Optional[List[str]] = self.meta['classes']

    @property
    def cache_name(self) -> str:
        if self.task == 'classification':
            return f'points_classification_{self.split}'
        return (f'points_segmentation_{self.split}_offset{self.label_offset}'
                f'_classes{self.num_classes_arg or "auto"}')

    @property
    def num_classes(self) -> int:
        return self.meta['num_classes']

    def scan(self) -> List[str]:
        if self.task == 'classification':
            self._classes, self._items = self.class_items(POINT_EXTENSIONS)
            return [path for path, _ in self._items]
        self._items = self._labelled(self.split)
        if not self._items:
            raise ValueError(f"PointCloudFolder: no "
                             f"{'/'.join(POINT_EXTENSIONS)} files in "
                             f"'{osp.join(self.root, self.split)}'; expected"
                             f" the layout {LAYOUT}")
        # The other split's labels count towards num_classes.
        other = 'test' if self.split == 'train' else 'train'
        self._others = [] if self.num_classes_arg else self._labelled(other)
        return [p for item in self._items + self._others for p in item
                if p is not None]

    def _labelled(self, split: str) -> list:
        """``(point file, label file or None)`` for every cloud of a
        split."""
        folder = osp.join(self.root, split)
        label_folders = [osp.join(self.root, f) for f in LABEL_FOLDERS]
        return [(path, find_label_file(
            osp.splitext(osp.basename(path))[0], folder, BESIDE_LABELS,
            label_folders, FOLDER_LABELS))
            for path in list_files(folder, POINT_EXTENSIONS)]

    def _read(self, path: str, label_file: Optional[str]):
        pos, normal, column = read_points(path)
        if self.task == 'classification':
            return pos, normal, None
        if label_file is not None:
            labels, source = read_labels(label_file), label_file
        elif column is not None:
            labels, source = to_int_labels(column, path), path
        else:
            raise ValueError(
                f"PointCloudFolder: no labels for '{path}': it has no label "
                f"column (4 or 7 columns, or a PLY 'label' property) and no "
                f"label file <stem>{'|'.join(BESIDE_LABELS)} beside it or "
                f"<stem>{'|'.join(FOLDER_LABELS)} in "
                f"{'/, '.join(LABEL_FOLDERS)}/ under '{self.root}'")
        if len(labels) != len(pos):
            raise ValueError(f"'{source}' holds {len(labels)} labels but "
                             f"'{path}' has {len(pos)} points; give one "
                             f"label per point")
        return pos, normal, check_labels(labels, source, self.label_offset,
                                         self.num_classes_arg)

    def read(self):
        if self.task == 'classification':
            items = [(path, None, c) for path, c in self._items]
        else:
            items = [(path, label_file, None)
                     for path, label_file in self._items]
        data_list = []
        for path, label_file, c in self.progress(items, 'cloud'):
            pos, normal, labels = self._read(path, label_file)
            data = IntrinsicData(pos=torch.from_numpy(pos).float(),
                                 y=torch.tensor([c]) if labels is None
                                 else torch.from_numpy(labels))
            if normal is not None:
                data.normal = torch.from_numpy(normal).float()
            data_list.append(data)
        with_normal = ['normal' in d for d in data_list]
        if any(with_normal) and not all(with_normal):
            bare = items[with_normal.index(False)][0]
            raise ValueError(f"PointCloudFolder: '{bare}' has no normals but"
                             f" other clouds of split '{self.split}' do; "
                             f"give every cloud normals or none")
        if self.task == 'classification':
            return data_list, {'classes': self._classes,
                               'num_classes': len(self._classes)}
        num_classes = self.num_classes_arg or max(
            [int(d.y.max()) + 1 for d in data_list] +
            [int(self._read(*item)[2].max()) + 1 for item in self._others])
        return data_list, {'classes': None, 'num_classes': num_classes}

    def __repr__(self) -> str:
        return (f'{self.__class__.__name__}({len(self)}, split={self.split!r},'
                f' task={self.task!r}, num_classes={self.num_classes})')
