"""Reads a folder of meshes laid out as ``root/<class>/<split>/*``."""
import json
import os
import os.path as osp
from typing import Callable, List, Optional, Tuple

import numpy as np
import torch
from torch_geometric.data import InMemoryDataset
from tqdm.auto import tqdm

from tg_intrinsic.data import IntrinsicData

from tg_intrinsic.utils import atomic_write_json

from ._common import check_split, save_atomic

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
    dataset is cached in :obj:`root/processed_tg_intrinsic/`.

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
        return osp.join(self.root, 'processed_tg_intrinsic')

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
            if name.startswith('.') or name == 'processed_tg_intrinsic' \
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


# ------------------------------------------------------------------ readers


def read_mesh(path: str) -> Tuple[np.ndarray, np.ndarray]:
    """Reads a triangle mesh: ``(pos [N, 3] float64, face [F, 3] int64)``.

    Raises a :class:`ValueError` that names the file if it cannot be read
    or holds no valid triangles.
    """
    ext = osp.splitext(path)[1].lower()
    try:
        if ext == '.off':
            pos, face = read_off(path)
        else:
            import trimesh
            kwargs = dict(maintain_order=True, skip_materials=True) \
                if ext == '.obj' else {}
            mesh = trimesh.load(path, process=False, force='mesh', **kwargs)
            pos = np.asarray(mesh.vertices, dtype=np.float64)
            face = np.asarray(mesh.faces, dtype=np.int64).reshape(-1, 3)
    except Exception as e:  # noqa: BLE001 - re-raised with the file name
        raise ValueError(f"MeshFolder: could not read mesh file '{path}': "
                         f"{type(e).__name__}: {e}") from e
    if pos.ndim != 2 or pos.shape[1] != 3 or len(pos) == 0:
        raise ValueError(f"MeshFolder: mesh file '{path}' has no vertices")
    if len(face) == 0:
        raise ValueError(f"MeshFolder: mesh file '{path}' has no triangles")
    if not np.isfinite(pos).all():
        raise ValueError(f"MeshFolder: mesh file '{path}' has NaN or "
                         f"infinite vertex coordinates")
    if face.min() < 0 or face.max() >= len(pos):
        raise ValueError(f"MeshFolder: mesh file '{path}' has face indices "
                         f"outside [0, {len(pos) - 1}]")
    return pos, face


def read_off(path: str) -> Tuple[np.ndarray, np.ndarray]:
    """Reads an OFF file (also ``COFF``/``NOFF`` with extra columns, and
    ModelNet's ``OFF<nv> <nf> <ne>`` single-line header). Polygons are
    split into triangle fans."""
    with open(path, 'r', errors='replace') as f:
        lines = [ln.split('#', 1)[0].strip() for ln in f]
    lines = [ln for ln in lines if ln]
    if not lines:
        raise ValueError('empty file')
    head = lines[0]
    keyword = head.split()[0]
    if not keyword.upper().lstrip('CN').startswith('OFF'):
        raise ValueError(f"missing 'OFF' header (first line: {head[:40]!r})")
    rest = head[head.upper().index('OFF') + 3:].split()
    i = 1
    if not rest:  # counts on the next line
        rest = lines[1].split()
        i = 2
    try:
        nv, nf = int(rest[0]), int(rest[1])
    except (IndexError, ValueError):
        raise ValueError(f'malformed OFF header {head!r}') from None
    if len(lines) < i + nv + nf:
        raise ValueError(f'OFF header announces {nv} vertices and {nf} faces '
                         f'but the file has only {len(lines) - i} data lines')
    vlines = lines[i:i + nv]
    try:
        pos = np.array([ln.split()[:3] for ln in vlines], dtype=np.float64)
    except ValueError:
        raise ValueError('malformed vertex line') from None
    if pos.shape != (nv, 3):
        raise ValueError('every vertex line needs 3 coordinates')
    ftok = [ln.split() for ln in lines[i + nv:i + nv + nf]]
    try:
        if all(len(t) >= 4 and t[0] == '3' for t in ftok):  # all triangles
            return pos, np.array([t[1:4] for t in ftok],
                                 dtype=np.int64).reshape(-1, 3)
        tris = []
        for tok in ftok:
            k = int(tok[0])
            if k < 3 or len(tok) < k + 1:
                raise ValueError(f"malformed face line {' '.join(tok)[:40]!r}")
            idx = [int(t) for t in tok[1:k + 1]]
            for j in range(1, k - 1):
                tris.append((idx[0], idx[j], idx[j + 1]))
    except ValueError as e:
        raise ValueError(f'malformed face line ({e})') from None
    return pos, np.array(tris, dtype=np.int64).reshape(-1, 3)
