"""Reads a folder of meshes laid out as ``root/<class>/<split>/*``."""
import json
import os
import os.path as osp
from typing import Callable, List, Optional, Tuple

import torch
from torch_geometric.data import InMemoryDataset
from tqdm.auto import tqdm

from tg_intrinsic.data import IntrinsicData

from tg_intrinsic.io.mesh import read_mesh
from tg_intrinsic.utils import atomic_write_json

from ._common import check_split, processing_suffix, save_atomic

EXTENSIONS = ('.obj', '.off', '.ply')
LAYOUT = ('root/<class>/<split>/<name>.obj|.off|.ply, e.g. '
          'ModelNet40/chair/train/chair_0001.off (ModelNet\'s release) or '
          'shrec_16/alien/test/T1.obj (MeshCNN\'s SHREC\'11 copy)')


class MeshFolder(InMemoryDataset):
    r"""A dataset of triangle meshes stored as
    :obj:`root/<class>/<split>/*.obj|*.off|*.ply`, the layout of ModelNet's
    :obj:`.off` release and of MeshCNN's copy of SHREC'11.

    Classes are the sub-folders of :obj:`root` (those with a :obj:`train` or
    :obj:`test` folder), sorted alphabetically; :obj:`data.y` is the index
    into :obj:`classes`. Meshes are read without any processing: vertices
    are neither merged nor reordered (polygons are split into triangle
    fans). :obj:`.off` files are parsed directly, which also accepts
    ModelNet's known malformed header where the counts follow :obj:`OFF`
    on the same line (:obj:`OFF490 518 0`); :obj:`.obj` and :obj:`.ply`
    files are read with :obj:`trimesh` (:obj:`process=False`). The processed
    dataset is cached in :obj:`root/processed_tg_intrinsic/` (a folder of
    its own per :obj:`pre_transform` and :obj:`pre_filter`).

    Args:
        root (str): The dataset folder.
        split (str, optional): :obj:`"train"` or :obj:`"test"`.
            (default: :obj:`"train"`)
        transform (callable, optional): Applied on access.
            (default: :obj:`None`)
        pre_transform (callable, optional): Applied before saving.
            (default: :obj:`None`)
        pre_filter (callable, optional): Keeps a mesh if it returns
            :obj:`True`. (default: :obj:`None`)
        log (bool, optional): Print progress. (default: :obj:`True`)
        force_reload (bool, optional): Re-read the files.
            (default: :obj:`False`)

    Raises:
        ValueError: if :obj:`root` does not exist or has no class folders,
            if the split has no mesh files, or naming the file that could
            not be read.

    Shapes:
        - **pos** :math:`(N, 3)` float32
        - **face** :math:`(3, F)` int64
        - **y** :math:`(1)` int64 class index
    """

    def __init__(
        self,
        root: str,
        split: str = 'train',
        transform: Optional[Callable] = None,
        pre_transform: Optional[Callable] = None,
        pre_filter: Optional[Callable] = None,
        log: bool = True,
        force_reload: bool = False,
    ):
        self.split = check_split(split)
        root = osp.expanduser(os.fspath(root))
        if not osp.isdir(root):
            raise ValueError(f"MeshFolder: '{root}' is not a folder; expected "
                             f"the layout {LAYOUT}")
        super().__init__(root, transform, pre_transform, pre_filter, log=log,
                         force_reload=force_reload)
        self.load(self.processed_paths[0], data_cls=IntrinsicData)
        with open(self.processed_paths[1]) as f:
            self.classes: List[str] = json.load(f)

    @property
    def raw_dir(self) -> str:
        return self.root

    @property
    def raw_file_names(self):
        return []

    @property
    def processed_dir(self) -> str:
        suffix = processing_suffix(self.pre_transform, self.pre_filter)
        return osp.join(self.root, 'processed_tg_intrinsic' + suffix)

    @property
    def processed_file_names(self):
        return [f'{self.split}.pt', f'{self.split}_classes.json']

    @property
    def num_classes(self) -> int:
        return len(self.classes)

    def find_classes(self) -> List[str]:
        """Sorted class folder names under :obj:`root`."""
        names = []
        for name in sorted(os.listdir(self.root)):
            path = osp.join(self.root, name)
            if name.startswith(('.', 'processed_tg_intrinsic')) \
                    or not osp.isdir(path):
                continue
            if osp.isdir(osp.join(path, 'train')) or \
                    osp.isdir(osp.join(path, 'test')):
                names.append(name)
        if not names:
            raise ValueError(f"MeshFolder: no class folders with a 'train' or "
                             f"'test' sub-folder in '{self.root}'; expected "
                             f"the layout {LAYOUT}")
        return names

    def find_files(self, classes: List[str]) -> List[Tuple[str, int]]:
        files = []
        for c, name in enumerate(classes):
            folder = osp.join(self.root, name, self.split)
            if not osp.isdir(folder):
                continue
            for fname in sorted(os.listdir(folder)):
                if osp.splitext(fname)[1].lower() in EXTENSIONS:
                    files.append((osp.join(folder, fname), c))
        if not files:
            raise ValueError(f"MeshFolder: no {'/'.join(EXTENSIONS)} files "
                             f"for split '{self.split}' under '{self.root}' "
                             f"(classes: {classes}); expected the layout "
                             f"{LAYOUT}")
        return files

    def process(self):
        classes = self.find_classes()
        files = self.find_files(classes)
        data_list = []
        for path, c in tqdm(files, desc=f'Reading MeshFolder ({self.split})',
                            disable=not self.log, unit='mesh'):
            pos, face = read_mesh(path)
            data = IntrinsicData(pos=torch.from_numpy(pos).float(),
                                 face=torch.from_numpy(face).t().contiguous(),
                                 y=torch.tensor([c], dtype=torch.long))
            if self.pre_filter is not None and not self.pre_filter(data):
                continue
            if self.pre_transform is not None:
                data = self.pre_transform(data)
            data_list.append(data)
        if not data_list:
            raise ValueError(f"MeshFolder: 'pre_filter' removed every mesh of "
                             f"split '{self.split}' in '{self.root}'")
        save_atomic(type(self), data_list, self.processed_paths[0])
        atomic_write_json(self.processed_paths[1], classes)

    def __repr__(self) -> str:
        return (f'{self.__class__.__name__}({len(self)}, split={self.split!r},'
                f' num_classes={self.num_classes})')
