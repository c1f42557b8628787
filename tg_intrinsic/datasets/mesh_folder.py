"""Reads a folder of triangle meshes, with classes or per-vertex labels."""
import os.path as osp
import warnings
from typing import List, Optional

import numpy as np
import torch

from tg_intrinsic.data import IntrinsicData
from tg_intrinsic.geometry.checks import check_positive_int
from tg_intrinsic.geometry.mesh import weld_vertices
from tg_intrinsic.io.labels import (LABEL_KINDS, check_labels,
                                    edge_label_scores, face_label_scores,
                                    label_kind, label_scores, read_labels,
                                    read_soft_labels, scores_to_labels)
from tg_intrinsic.io.mesh import read_mesh

from .common import (FolderDataset, check_option, check_task,
                      find_label_file, list_files)

EXTENSIONS = ('.obj', '.off', '.ply')
# label files beside a mesh, and in the label folders root/seg, root/labels
BESIDE_LABELS = ('.txt', '.seg', '.labels', '.label', '.npy')
FOLDER_LABELS = ('.eseg', ) + BESIDE_LABELS
LABEL_FOLDERS = ('seg', 'labels')
LAYOUT = ("root/<class>/<split>/<name>.obj|.off|.ply for classification "
          "(e.g. ModelNet40/chair/train/chair_0001.off, shrec_16/alien/test/"
          "T1.obj), root/<split>/<name>.obj|.off|.ply with label files for "
          "segmentation (e.g. MeshCNN's human_seg/train/shrec__1.obj with "
          "human_seg/seg/shrec__1.eseg)")


class MeshFolder(FolderDataset):
    r"""A dataset of triangle meshes from a local folder, for shape
    classification (one class per mesh) or segmentation (one label per
    vertex). Nothing is downloaded.

    **Classification** (:obj:`task="classification"`) reads the layout of
    ModelNet's :obj:`.off` release (e.g. ModelNet40) and of MeshCNN's copy
    of SHREC'11 (:obj:`shrec_16`). Classes are the sub-folders with a
    :obj:`train` or :obj:`test` folder, sorted; :obj:`data.y` is the index
    into :obj:`classes`::

        root/
        ├── alien/
        │   ├── train/T1.obj  T2.obj ...
        │   └── test/T5.obj ...
        └── ants/
            ├── train/...
            └── test/...

    **Segmentation** (:obj:`task="segmentation"`) reads MeshCNN's
    :obj:`human_seg` / :obj:`coseg_*` layout, or label files beside the
    meshes. :obj:`data.y` holds one 0-based label per vertex::

        root/
        ├── train/
        │   ├── shrec__1.obj
        │   └── shrec__1.txt      labels beside the mesh (same stem), or
        ├── test/shrec__12.obj
        ├── seg/shrec__1.eseg     ... in seg/ or labels/ (MeshCNN: per edge)
        ├── labels/shrec__12.txt
        └── sseg/shrec__1.seseg   MeshCNN's soft labels (optional)

    The label file of :obj:`<stem>.obj` is :obj:`<stem>.txt|.seg|.labels|
    .label|.npy` beside it or in :obj:`root/seg/` or :obj:`root/labels/`
    (which also take MeshCNN's :obj:`.eseg`); exactly one must exist, unless
    there is a soft label file :obj:`root/sseg/<stem>.seseg`. A file holds
    one integer per line (or a 1-D :obj:`.npy` array): per vertex, per face
    or per edge in MeshCNN's order (see
    :func:`~tg_intrinsic.io.labels.meshcnn_edges`: MeshCNN drops zero-area
    and repeated-directed-edge faces, then numbers edges by first
    appearance). :obj:`.eseg` and :obj:`.seseg` files are per edge; for the
    others :obj:`label_kind="auto"` compares the file's length with the
    vertex count, then the face count, then MeshCNN's edge count of the
    mesh as read, and takes the first that matches (a file as long as both
    the vertex and the face count is read per vertex; pass
    :obj:`label_kind` to say otherwise). Labels become per-vertex labels by
    weighted votes (:mod:`tg_intrinsic.io.labels`): a vertex takes the
    label with the largest total area of its incident faces, or the largest
    total length of its incident edges (soft labels: their rows summed,
    weighted by length), ties going to the smaller label. With a
    :obj:`.seseg` file, :obj:`data.y_soft` holds that length-weighted sum
    normalised per vertex (MeshCNN counts a prediction as right where its
    soft label is positive); without a hard label file, :obj:`data.y` is
    its largest class.

    **1-based files.** :obj:`label_offset` is subtracted from every hard
    label. Its default :obj:`None` picks it from the format, never from the
    values: 1 for MeshCNN's :obj:`.eseg` (human_seg and coseg number their
    parts from 1, and MeshCNN subtracts the smallest class), 0 for every
    other file. Deciding from the values (e.g. "the smallest label is 1")
    would silently shift a split in which part 0 happens not to occur.
    :obj:`.seseg` columns are 0-based already. A label that is negative
    after the offset, or not below :obj:`num_classes` when it is given,
    raises a :class:`ValueError` naming the file and the row.
    :obj:`num_classes` defaults to the largest label (or soft label
    column) over both splits plus one.

    **Welding.** Meshes whose vertices repeat a position exactly (triangle
    soups written by many OBJ exporters, split seams) are welded with
    :func:`~tg_intrinsic.geometry.weld_vertices` (exact duplicates only)
    and a warning saying how many vertices were merged; other meshes are
    left exactly as read (vertices neither merged nor reordered). Welding
    keeps the first copy of every vertex in file order. Labels are matched
    against the mesh as read and follow the weld: per-vertex labels by
    majority over the merged copies (ties to the smaller label), face and
    edge labels are voted on the welded mesh.

    :obj:`.off` files are parsed directly (ModelNet's malformed
    :obj:`OFF490 518 0` header included); :obj:`.obj` and :obj:`.ply` files
    are read with :obj:`trimesh` (:obj:`process=False`). Polygons become
    triangle fans. A face that repeats a vertex (e.g. the OBJ line
    :obj:`f 1 1 2`) is an error, as are face indices out of range: the
    :class:`ValueError` names the file, the first such triangle and, for
    :obj:`.obj` and :obj:`.off` files, its line, and says how to remove
    them (:func:`~tg_intrinsic.io.read_surface`). Such faces are not
    dropped silently, because per-face label files count them. The
    processed data are cached in
    :obj:`root/processed_tg_intrinsic*/` with a manifest of the input files
    (names, sizes, modification times): adding, removing or changing a
    mesh or label file re-reads the folder.

    Args:
        root (str): The dataset folder.
        split (str, optional): :obj:`"train"` or :obj:`"test"`.
            (default: :obj:`"train"`)
        task (str, optional): :obj:`"classification"` or
            :obj:`"segmentation"`. (default: :obj:`"classification"`)
        label_kind (str, optional): What the hard label files (other than
            :obj:`.eseg`) label: :obj:`"auto"` (by length), :obj:`"vertex"`,
            :obj:`"face"` or :obj:`"edge"`. (default: :obj:`"auto"`)
        label_offset (int, optional): Subtracted from every hard label;
            :obj:`None` means 1 for :obj:`.eseg` files and 0 otherwise.
            (default: :obj:`None`)
        num_classes (int, optional): The number of segmentation classes;
            labels must lie below it. (default: :obj:`None`, the largest
            label over both splits plus one)
        transform (callable, optional): Applied on access.
            (default: :obj:`None`)
        pre_transform (callable, optional): Applied before saving.
            (default: :obj:`None`)
        pre_filter (callable, optional): Keeps a mesh if it returns
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
        ValueError: if :obj:`root` is not a folder or does not follow the
            layout, or naming the file: a mesh that cannot be read or has
            faces that repeat a vertex, a missing label file, or labels that are not integers, are
            negative, out of range, or whose count matches no vertex, face
            or edge count of the mesh.

    Shapes:
        - **pos** :math:`(N, 3)` float32
        - **face** :math:`(3, F)` int64
        - **y** :math:`(1)` int64 class index (classification), or
          :math:`(N)` int64 vertex labels (segmentation)
        - **y_soft** :math:`(N, C)` float32, only with :obj:`.seseg` files
    """
    LAYOUT = LAYOUT

    def __init__(
        self,
        root: str,
        split: str = 'train',
        task: str = 'classification',
        label_kind: str = 'auto',
        label_offset: Optional[int] = None,
        num_classes: Optional[int] = None,
        transform=None,
        pre_transform=None,
        pre_filter=None,
        log: bool = True,
        force_reload: bool = False,
        workers: int = 1,
        cache_root: Optional[str] = None,
    ):
        self.task = check_task(task, label_kind=(label_kind, 'auto'),
                               label_offset=(label_offset, None),
                               num_classes=(num_classes, None))
        check_option(label_kind, 'label_kind', LABEL_KINDS)
        self.label_kind = label_kind
        self.label_offset = None if label_offset is None else \
            check_positive_int(label_offset, 'label_offset', 0)
        self.num_classes_arg = None if num_classes is None else \
            check_positive_int(num_classes, 'num_classes', 1)
        super().__init__(root, split, transform, pre_transform, pre_filter,
                         log, force_reload, workers, cache_root)
        self.classes: Optional[List[str]] = self.meta['classes']

    @property
    def cache_name(self) -> str:
        if self.task == 'classification':
            return f'classification_{self.split}'
        return (f'segmentation_{self.split}_{self.label_kind}_offset'
                f'{"auto" if self.label_offset is None else self.label_offset}'
                f'_classes{self.num_classes_arg or "auto"}')

    @property
    def num_classes(self) -> int:
        return self.meta['num_classes']

    def scan(self) -> List[str]:
        if self.task == 'classification':
            self._classes, self._items = self.class_items(EXTENSIONS)
            return [path for path, _ in self._items]
        self._items = self._labelled(self.split)
        if not self._items:
            raise ValueError(f"MeshFolder: no {'/'.join(EXTENSIONS)} files "
                             f"in '{osp.join(self.root, self.split)}'; "
                             f"expected the layout {LAYOUT}")
        # The other split's labels count towards num_classes.
        other = 'test' if self.split == 'train' else 'train'
        self._others = [] if self.num_classes_arg else [
            item[1:] for item in self._labelled(other)]
        return [p for item in self._items + self._others for p in item
                if p is not None]

    def _labelled(self, split: str) -> list:
        """``(mesh, hard label file or None, soft label file or None)``
        for every mesh of a split."""
        folder = osp.join(self.root, split)
        label_folders = [osp.join(self.root, f) for f in LABEL_FOLDERS]
        items = []
        for path in list_files(folder, EXTENSIONS):
            stem = osp.splitext(osp.basename(path))[0]
            hard = find_label_file(stem, folder, BESIDE_LABELS, label_folders,
                                   FOLDER_LABELS)
            soft = osp.join(self.root, 'sseg', stem + '.seseg')
            soft = soft if osp.isfile(soft) else None
            if hard is None and soft is None:
                raise ValueError(
                    f"MeshFolder: no label file for '{path}'; looked for "
                    f"{stem}{'|'.join(BESIDE_LABELS)} beside it and "
                    f"{stem}{'|'.join(FOLDER_LABELS)} in "
                    f"{'/, '.join(LABEL_FOLDERS)}/ and {stem}.seseg in "
                    f"sseg/ under '{self.root}'")
            items.append((path, hard, soft))
        return items

    def _offset(self, path: str) -> int:
        if self.label_offset is not None:
            return self.label_offset
        return 1 if path.lower().endswith('.eseg') else 0

    def _weld(self, path, pos, face):
        pos_t, face_t, inverse = weld_vertices(torch.from_numpy(pos),
                                               torch.from_numpy(face).t())
        merged = len(pos) - len(pos_t)
        if merged:
            follow = '; its labels follow the weld' \
                if self.task == 'segmentation' else ''
            warnings.warn(f"MeshFolder: '{path}' has vertices at exactly the "
                          f"same position (a triangle soup?); merged "
                          f"{merged} vertices ({len(pos)} -> {len(pos_t)})"
                          f"{follow}", stacklevel=2)
        return pos_t.numpy(), face_t.t().numpy(), inverse.numpy()

    def _data(self, pos, face, **attrs) -> IntrinsicData:
        return IntrinsicData(pos=torch.from_numpy(pos).float(),
                             face=torch.from_numpy(face).t().contiguous(),
                             **attrs)

    def read(self):
        if self.task == 'classification':
            data_list = [self._data(*self._weld(path, *read_mesh(
                path, weld=False))[:2],
                                    y=torch.tensor([c]))
                         for path, c in self.progress(self._items, 'mesh')]
            return data_list, {'classes': self._classes,
                               'num_classes': len(self._classes)}
        read = [self._read_labelled(*item)
                for item in self.progress(self._items, 'mesh')]
        data_list = [data for data, _ in read]
        num_classes = self.num_classes_arg or max(
            [used for _, used in read] +
            [self._read_label_files(*item)[2] for item in self._others])
        for data in data_list:
            if 'y_soft' in data:
                data.y_soft = torch.nn.functional.pad(
                    data.y_soft, (0, num_classes - data.y_soft.size(1)))
        return data_list, {'classes': None, 'num_classes': num_classes}

    def _read_label_files(self, hard: Optional[str], soft: Optional[str]):
        """The checked 0-based hard labels, the soft label rows (:obj:`None`
        without the file) and how many classes they use."""
        labels = soft_rows = None
        used = 0
        if hard is not None:
            labels = check_labels(read_labels(hard), hard, self._offset(hard),
                                  self.num_classes_arg)
            used = int(labels.max()) + 1
        if soft is not None:
            soft_rows = read_soft_labels(soft)
            if self.num_classes_arg and \
                    soft_rows.shape[1] > self.num_classes_arg:
                raise ValueError(f"'{soft}' has {soft_rows.shape[1]} "
                                 f"classes (columns) but num_classes is "
                                 f"{self.num_classes_arg}")
            used = max(used, soft_rows.shape[1])
        return labels, soft_rows, used

    def _read_labelled(self, path: str, hard: Optional[str],
                       soft: Optional[str]):
        """The labelled mesh and how many classes its label files use."""
        # welded below, after the labels of the stored edges are matched
        pos, face = read_mesh(path, weld=False)
        mesh = f"'{path}'"
        labels, soft_rows, used = self._read_label_files(hard, soft)
        edges = None
        if hard is not None:
            kind = 'edge' if hard.lower().endswith('.eseg') \
                else self.label_kind
            kind, edges = label_kind(hard, len(labels), pos, face, kind,
                                     mesh)
        if soft is not None and (edges is None or
                                 len(edges) != len(soft_rows)):
            _, edges = label_kind(soft, len(soft_rows), pos, face, 'edge',
                                  mesh)
        pos, face, inverse = self._weld(path, pos, face)
        attrs = {}
        if soft_rows is not None:
            scores = edge_label_scores(pos, inverse[edges], soft_rows)
            total = scores.sum(1, keepdims=True)
            attrs['y_soft'] = torch.from_numpy(
                scores / np.where(total > 0, total, 1)).float()
        if hard is None:
            kind, source = 'edge', soft
        else:
            source = hard
            scores = (label_scores(inverse, labels, len(pos))
                      if kind == 'vertex' else
                      face_label_scores(pos, face, labels) if kind == 'face'
                      else edge_label_scores(pos, inverse[edges], labels))
        y = scores_to_labels(scores)
        missing = np.nonzero(y < 0)[0]
        if missing.size:
            raise ValueError(
                f"{missing.size} vertex(es) of '{path}' (first: "
                f"{missing[0]}) get no label from '{source}': they lie on no"
                f" labelled {kind} of positive "
                f"{'area' if kind == 'face' else 'length'}; remove "
                f"unreferenced vertices or give per-vertex labels")
        return self._data(pos, face, y=torch.from_numpy(y), **attrs), used

    def __repr__(self) -> str:
        return (f'{self.__class__.__name__}({len(self)}, split={self.split!r},'
                f' task={self.task!r}, num_classes={self.num_classes})')
