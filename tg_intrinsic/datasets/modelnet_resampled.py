"""Reads PointNet++'s resampled ModelNet point clouds from a local folder."""
import os.path as osp
from typing import List, Optional

import torch

from tg_intrinsic.data import IntrinsicData
from tg_intrinsic.geometry.checks import check_positive_int
from tg_intrinsic.io.points import read_points

from .common import FolderDataset, check_option

LAYOUT = ("modelnet40_normal_resampled/ with modelnet40_shape_names.txt, "
          "modelnet40_train.txt, modelnet40_test.txt (and the modelnet10_* "
          "equivalents) and <class>/<class>_0001.txt")


def _lines(path: str) -> List[str]:
    with open(path) as f:
        return [line.strip() for line in f if line.strip()]


class ModelNetResampled(FolderDataset):
    r"""ModelNet40 or ModelNet10 as the point clouds with normals that
    PointNet++ resampled from the meshes, read from a local folder (nothing
    is downloaded).

    The folder is PointNet++'s (Qi et al., 2017)
    :obj:`modelnet40_normal_resampled/`::

        modelnet40_normal_resampled/
        ├── modelnet40_shape_names.txt   one class per line: airplane, ...
        ├── modelnet40_train.txt         one shape per line: airplane_0001
        ├── modelnet40_test.txt
        ├── modelnet10_shape_names.txt   (and modelnet10_train/test.txt)
        ├── airplane/
        │   ├── airplane_0001.txt        10,000 lines "x,y,z,nx,ny,nz"
        │   └── ...
        └── ...

    :obj:`data.y` is the line number of the class in
    :obj:`modelnet{40,10}_shape_names.txt` (PointNet++'s code reads
    :obj:`shape_names.txt` for ModelNet40, which is used when the former is
    missing); a shape :obj:`night_stand_0001` is the file
    :obj:`night_stand/night_stand_0001.txt`. Like PointNet++'s loader
    (:obj:`point_set[0:npoints]`), the first :obj:`num_points` points of
    every file are kept; its centring and scaling to the unit sphere are
    left to a transform (e.g. PyG's :class:`NormalizeScale`).
    ModelNet's original mesh release (:obj:`ModelNet40/<class>/{train,test}/
    *.off`) is read by :class:`MeshFolder` instead. The processed data are
    cached in :obj:`root/processed_tg_intrinsic*/` with a manifest of the
    files read: changing one of them re-reads the folder.

    Args:
        root (str): The :obj:`modelnet40_normal_resampled` folder.
        split (str, optional): :obj:`"train"` or :obj:`"test"`.
            (default: :obj:`"train"`)
        num_classes (int, optional): :obj:`40` or :obj:`10` (ModelNet10's
            shape lists). (default: :obj:`40`)
        num_points (int, optional): The number of points kept per shape,
            the first ones of the file. (default: :obj:`1024`)
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
        ValueError: naming the file: a missing list or shape file, a shape
            of an unknown class, a file without normals or with fewer than
            :obj:`num_points` points.

    Shapes:
        - **pos** :math:`(\text{num\_points}, 3)` float32
        - **normal** :math:`(\text{num\_points}, 3)` float32
        - **y** :math:`(1)` int64
    """
    LAYOUT = LAYOUT

    def __init__(self, root: str, split: str = 'train', num_classes: int = 40,
                 num_points: int = 1024, transform=None, pre_transform=None,
                 pre_filter=None, log: bool = True,
                 force_reload: bool = False, workers: int = 1,
                 cache_root: Optional[str] = None):
        self.num_classes_arg = check_option(num_classes, 'num_classes',
                                            (40, 10))
        self.num_points = check_positive_int(num_points, 'num_points', 1)
        super().__init__(root, split, transform, pre_transform, pre_filter,
                         log, force_reload, workers, cache_root)
        self.classes: List[str] = self.meta['classes']

    @property
    def cache_name(self) -> str:
        return (f'modelnet{self.num_classes_arg}_{self.split}_'
                f'{self.num_points}')

    @property
    def num_classes(self) -> int:
        return len(self.classes)

    def _list_file(self, *names: str) -> str:
        """The first of ``root/<name>`` that exists."""
        paths = [osp.join(self.root, name) for name in names]
        for path in paths:
            if osp.isfile(path):
                return path
        raise ValueError(f"ModelNetResampled: '{paths[0]}' does not exist; "
                         f"expected the layout {LAYOUT}")

    def scan(self) -> List[str]:
        prefix = f'modelnet{self.num_classes_arg}'
        names = self._list_file(f'{prefix}_shape_names.txt', *(
            ['shape_names.txt'] if self.num_classes_arg == 40 else []))
        shapes = self._list_file(f'{prefix}_{self.split}.txt')
        self._classes = _lines(names)
        index = {name: c for c, name in enumerate(self._classes)}
        self._items = []
        for row, shape in enumerate(_lines(shapes)):
            name = shape.rsplit('_', 1)[0]
            if name not in index:
                raise ValueError(f"'{shapes}' line {row + 1}: shape "
                                 f"{shape!r} is of class {name!r}, which "
                                 f"'{names}' does not list")
            path = osp.join(self.root, name, shape + '.txt')
            if not osp.isfile(path):
                raise ValueError(f"'{path}' (listed in '{shapes}') does not "
                                 f"exist")
            self._items.append((path, index[name]))
        if not self._items:
            raise ValueError(f"ModelNetResampled: '{shapes}' lists no shapes")
        return [names, shapes] + [path for path, _ in self._items]

    def read(self):
        data_list = []
        for path, c in self.progress(self._items, 'shape'):
            pos, normal, _ = read_points(path, max_points=self.num_points)
            if normal is None:
                raise ValueError(f"'{path}' has no normals; expected lines "
                                 f"'x,y,z,nx,ny,nz'")
            if len(pos) < self.num_points:
                raise ValueError(f"'{path}' has {len(pos)} points, fewer "
                                 f"than num_points={self.num_points}")
            data_list.append(IntrinsicData(
                pos=torch.from_numpy(pos).float(),
                normal=torch.from_numpy(normal).float(),
                y=torch.tensor([c])))
        return data_list, {'classes': self._classes}

    def __repr__(self) -> str:
        return (f'{self.__class__.__name__}({len(self)}, split={self.split!r},'
                f' num_classes={self.num_classes_arg}, '
                f'num_points={self.num_points})')
