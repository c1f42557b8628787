"""Reads ScanObjectNN's HDF5 files from a local folder."""
import os.path as osp
from typing import List, Optional

import torch

from tg_intrinsic.data import IntrinsicData
from tg_intrinsic.io.labels import check_labels, to_int_labels

from .common import FolderDataset, check_option

# variant: (folder, file name after 'training_' / 'test_')
VARIANTS = {
    'OBJ_ONLY': ('main_split_nobg', 'objectdataset.h5'),
    'OBJ_BG': ('main_split', 'objectdataset.h5'),
    'PB_T50_RS': ('main_split', 'objectdataset_augmentedrot_scale75.h5'),
}
# label order of the released files
CLASSES = ('bag', 'bin', 'box', 'cabinet', 'chair', 'desk', 'display',
           'door', 'shelf', 'table', 'bed', 'pillow', 'sink', 'sofa',
           'toilet')
LAYOUT = ("h5_files/main_split/training_objectdataset_augmentedrot_scale75.h5"
          " (and test_*, the main_split_nobg folder; root may be h5_files "
          "itself)")


class ScanObjectNN(FolderDataset):
    r"""ScanObjectNN, 15 classes of scanned objects with 2048 points each,
    read from the released HDF5 files in a local folder (nothing is
    downloaded).

    The data set is from Uy et al., "Revisiting point cloud
    classification: a new benchmark dataset and classification model on
    real-world data" (ICCV 2019); its files are::

        h5_files/
        ├── main_split/
        │   ├── training_objectdataset.h5                      OBJ_BG
        │   ├── test_objectdataset.h5
        │   ├── training_objectdataset_augmentedrot_scale75.h5 PB_T50_RS
        │   └── test_objectdataset_augmentedrot_scale75.h5
        └── main_split_nobg/
            ├── training_objectdataset.h5                      OBJ_ONLY
            └── test_objectdataset.h5

    :obj:`root` is the folder holding :obj:`h5_files/` or :obj:`h5_files/`
    itself. Each file holds the datasets :obj:`data` (:math:`(B, 2048, 3)`
    float), :obj:`label` (:math:`(B)`) and optionally :obj:`mask`
    (:math:`(B, 2048)`, -1 on background points), which becomes
    :obj:`data.object_mask` (:obj:`True` on object points). Class names
    are in :obj:`classes`. Reading needs :obj:`h5py`
    (:obj:`pip install tg_intrinsic[h5]`); the processed data are cached in
    :obj:`root/processed_tg_intrinsic*/` and re-read when the file changes.

    Args:
        root (str): The folder holding :obj:`h5_files/`, or that folder.
        split (str, optional): :obj:`"train"` or :obj:`"test"`.
            (default: :obj:`"train"`)
        variant (str, optional): :obj:`"OBJ_ONLY"` (objects without
            background), :obj:`"OBJ_BG"` (with background) or
            :obj:`"PB_T50_RS"` (the hardest: perturbed, rotated and scaled
            boxes with background). (default: :obj:`"PB_T50_RS"`)
        transform (callable, optional): Applied on access.
            (default: :obj:`None`)
        pre_transform (callable, optional): Applied before saving.
            (default: :obj:`None`)
        pre_filter (callable, optional): Keeps a shape if it returns
            :obj:`True`. (default: :obj:`None`)
        log (bool, optional): Print progress. (default: :obj:`True`)
        force_reload (bool, optional): Re-read the file.
            (default: :obj:`False`)
        workers (int, optional): Processes that apply the pre-filter and
            the pre-transform, one thread each; the result does not depend
            on it. (default: :obj:`1`)
        cache_root (str, optional): Keep the processed files under this
            folder instead of inside :obj:`root` (a read-only data set).
            (default: :obj:`None`)

    Raises:
        ImportError: without h5py.
        ValueError: naming the file: missing, unreadable, without the
            datasets :obj:`data` and :obj:`label`, with shapes that do not
            agree, or labels that are not integers in [0, 14].

    Shapes:
        - **pos** :math:`(2048, 3)` float32
        - **y** :math:`(1)` int64
        - **object_mask** :math:`(2048)` bool, when the file has a mask
    """
    LAYOUT = LAYOUT
    classes = list(CLASSES)

    def __init__(self, root: str, split: str = 'train',
                 variant: str = 'PB_T50_RS', transform=None,
                 pre_transform=None, pre_filter=None, log: bool = True,
                 force_reload: bool = False, workers: int = 1,
                 cache_root: Optional[str] = None):
        self.variant = check_option(variant, 'variant', VARIANTS)
        super().__init__(root, split, transform, pre_transform, pre_filter,
                         log, force_reload, workers, cache_root)

    @property
    def cache_name(self) -> str:
        return f'scanobjectnn_{self.variant}_{self.split}'

    @property
    def num_classes(self) -> int:
        return len(CLASSES)

    def scan(self) -> List[str]:
        folder, name = VARIANTS[self.variant]
        name = ('training_' if self.split == 'train' else 'test_') + name
        candidates = [osp.join(self.root, 'h5_files', folder, name),
                      osp.join(self.root, folder, name)]
        found = [path for path in candidates if osp.isfile(path)]
        if not found:
            raise ValueError(f"ScanObjectNN: found neither '{candidates[0]}'"
                             f" nor '{candidates[1]}' ({self.variant}, "
                             f"{self.split}); expected the layout {LAYOUT}")
        self._path = found[0]
        return [self._path]

    def read(self):
        try:
            import h5py
        except ImportError as error:
            raise ImportError("ScanObjectNN reads HDF5 files with h5py; "
                              "install it with: pip install "
                              "tg_intrinsic[h5]") from error
        path = self._path
        try:
            with h5py.File(path, 'r') as f:
                missing = [k for k in ('data', 'label') if k not in f]
                if missing:
                    raise ValueError(f"no dataset(s) {missing} (it has "
                                     f"{sorted(f.keys())})")
                points, label = f['data'][:], f['label'][:]
                mask = f['mask'][:] if 'mask' in f else None
        except (OSError, ValueError) as error:
            raise ValueError(f"could not read '{path}': {error}") from error
        if points.ndim != 3 or points.shape[2] < 3 or \
                label.size != len(points) or \
                (mask is not None and mask.shape != points.shape[:2]):
            raise ValueError(
                f"'{path}': 'data' {points.shape}, 'label' {label.shape}"
                f"{'' if mask is None else f', mask {mask.shape}'} do not "
                f"agree; expected [B, P, 3], [B] and [B, P]")
        label = check_labels(to_int_labels(label, path), path,
                             num_classes=len(CLASSES))
        pos = torch.from_numpy(points[..., :3]).float()
        data_list = []
        for i in self.progress(range(len(points)), 'shape'):
            data = IntrinsicData(pos=pos[i], y=torch.tensor([label[i]]))
            if mask is not None:
                data.object_mask = torch.from_numpy(mask[i] != -1)
            data_list.append(data)
        return data_list, {}

    def __repr__(self) -> str:
        return (f'{self.__class__.__name__}({len(self)}, split={self.split!r},'
                f' variant={self.variant!r})')
