"""SHREC'11-style non-rigid mesh dataset generated offline."""
import os.path as osp
from typing import Callable, Optional, Tuple

import torch

from tg_intrinsic.data import IntrinsicData
from tg_intrinsic.geometry.checks import check_positive_int

from . import shrec_shapes as shapes
from .common import (GeneratedDataset, check_split, check_workers, fmt,
                     map_examples, preprocess, save_atomic, shape_rng,
                     worker_copy)


class SyntheticSHREC(GeneratedDataset):
    r"""A synthetic, SHREC'11-style dataset of non-rigid, articulated
    closed surfaces for mesh classification and part segmentation, as used
    to evaluate Harmonic Surface Networks ("CNNs on surfaces using
    rotation-equivariant features", Wiersma et al., SIGGRAPH 2020).

    Twelve classes of procedurally built creatures and objects
    (:obj:`classes`: ant, bird, claw, dinosaur, hand, human, octopus,
    quadruped, snake, starfish, tree, vase). Every shape is a new instance
    (random proportions) in a random pose: a skeleton of rigid bones is
    bent at its joints and the surface is the zero level set of a smooth
    union of round cones and ellipsoids around the bones,

    .. math::
        f(\mathbf{x}) = \operatorname{smin}_{k_i}\big(d_1(\mathbf{x}),
        \dots, d_P(\mathbf{x})\big), \qquad
        \operatorname{smin}_k(a, b) = \min(a, b)
        - \tfrac{k}{4}\max\!\big(1 - \tfrac{|a - b|}{k}, 0\big)^2,

    so a pose bends the surface near the joints only (near-isometric
    deformations within an instance). The level set is extracted with
    marching tetrahedra, which yields a closed, embedded 2-manifold; poses
    whose parts touch (the genus changes) are redrawn. Meshes are then
    decimated by quadric edge collapses (manifold-preserving) to a random
    vertex count in :obj:`num_vertices`, relaxed tangentially (vertices
    slide towards their neighbours' centroid and are projected back onto
    the level set, for well-shaped triangles), perturbed by noise along the
    normals (meshes with a fold-over are redone, so the surfaces do not
    intersect themselves), centred, scaled to unit surface area and
    randomly rotated, so that neither the scale, the orientation nor the
    vertex count gives the class away. Part labels are those of the
    nearest part.

    Shapes are generated on first use from :obj:`seed` (each shape from its
    own seed, so results do not depend on the machine or the order of
    generation) and cached under :obj:`root`; the generation parameters are
    part of the processed file names, so changing them regenerates.

    Args:
        root (str): Root directory; processed files go to
            :obj:`root/processed`.
        split (str, optional): :obj:`"train"` or :obj:`"test"`.
            (default: :obj:`"train"`)
        task (str, optional): :obj:`"classification"` (:obj:`data.y` is the
            class, shape :obj:`[1]`) or :obj:`"segmentation"` (:obj:`data.y`
            is the part label of every vertex, :obj:`data.category` the
            class). (default: :obj:`"classification"`)
        num_train_per_class (int, optional): Training shapes per class; the
            rest of each class is the test split. (default: :obj:`10`, as in
            the HSN SHREC experiment)
        num_per_class (int, optional): Shapes per class in total.
            (default: :obj:`20`)
        num_vertices (tuple, optional): Inclusive range the vertex count of
            every mesh is drawn from uniformly. (default: :obj:`(500, 2000)`)
        noise (float, optional): Standard deviation of the displacement
            of every vertex along its normal, relative to its shortest
            edge (clipped at 2.5 standard deviations).
            (default: :obj:`0.05`)
        rotate (bool, optional): Randomly rotate every shape (uniformly on
            :math:`SO(3)`). (default: :obj:`True`)
        seed (int, optional): Seed of the generation. (default: :obj:`0`)
        transform (callable, optional): Applied on access.
            (default: :obj:`None`)
        pre_transform (callable, optional): Applied before saving.
            (default: :obj:`None`)
        pre_filter (callable, optional): Keeps a shape if it returns
            :obj:`True`. (default: :obj:`None`)
        log (bool, optional): Print progress (a tqdm bar while generating).
            (default: :obj:`True`)
        force_reload (bool, optional): Regenerate. (default: :obj:`False`)
        workers (int, optional): Processes that generate the shapes and
            apply the pre-filter and the pre-transform, one thread each;
            the result does not depend on it. (default: :obj:`1`)

    Shapes:
        - **pos** :math:`(N, 3)` float32, :math:`500 \leq N \leq 2000`
        - **face** :math:`(3, F)` int64, :math:`F = 2N - 4` (closed genus-0
          surfaces, consistently oriented, outward normals)
        - **y** :math:`(1)` int64 class, or :math:`(N)` int64 part label
        - **category** :math:`(1)` int64 class (segmentation only)

    Stats:
        .. list-table::
            :header-rows: 1

            * - #classes
              - #parts
              - #shapes (default)
              - #vertices
            * - 12
              - 6 (:obj:`part_names`)
              - 240 (120 train / 120 test)
              - 500 -- 2000
    """

    classes: Tuple[str, ...] = tuple(shapes.CLASSES)
    part_names: Tuple[str, ...] = shapes.PART_NAMES
    #: Bumped whenever the generator changes, to invalidate old caches.
    version = 2

    def __init__(
        self,
        root: str,
        split: str = 'train',
        task: str = 'classification',
        num_train_per_class: int = 10,
        num_per_class: int = 20,
        num_vertices: Tuple[int, int] = (500, 2000),
        noise: float = 0.05,
        rotate: bool = True,
        seed: int = 0,
        transform: Optional[Callable] = None,
        pre_transform: Optional[Callable] = None,
        pre_filter: Optional[Callable] = None,
        log: bool = True,
        force_reload: bool = False,
        workers: int = 1,
    ):
        self.split = check_split(split)
        if task not in ('classification', 'segmentation'):
            raise ValueError(f"'task' must be 'classification' or "
                             f"'segmentation', got {task!r}")
        self.task = task
        self.num_per_class = check_positive_int(num_per_class, 'num_per_class', 2)
        self.num_train_per_class = check_positive_int(num_train_per_class,
                                             'num_train_per_class', 1)
        if self.num_train_per_class >= self.num_per_class:
            raise ValueError(f"'num_train_per_class' ({num_train_per_class}) "
                             f"must be smaller than 'num_per_class' "
                             f"({num_per_class}) to leave test shapes")
        try:
            lo, hi = (int(v) for v in num_vertices)
        except (TypeError, ValueError):
            raise ValueError(f"'num_vertices' must be a pair (min, max), got "
                             f"{num_vertices!r}") from None
        if not 100 <= lo <= hi:
            raise ValueError(f"'num_vertices' must satisfy 100 <= min <= max, "
                             f"got {num_vertices!r}")
        self.num_vertices = (lo, hi)
        noise = float(noise)
        if not 0.0 <= noise <= 0.2:
            raise ValueError(f"'noise' must be in [0, 0.2] (relative to the "
                             f"shortest edge of every vertex), got {noise}")
        self.noise = noise
        self.rotate = bool(rotate)
        self.seed = check_positive_int(seed, 'seed', 0)
        self.workers = check_workers(workers)
        super().__init__(root, transform, pre_transform, pre_filter, log=log,
                         force_reload=force_reload)
        self.load(self.processed_paths[self._file_index(split, task)],
                  data_cls=IntrinsicData)

    # ------------------------------------------------------------------
    @property
    def tag(self) -> str:
        """Generation parameters, as they appear in the processed files."""
        return (f'v{self.version}_seed{self.seed}_n{self.num_per_class}'
                f'_train{self.num_train_per_class}'
                f'_verts{fmt(self.num_vertices)}_noise{fmt(self.noise)}'
                f'_rot{fmt(self.rotate)}')

    _SPLITS = ('train', 'test')
    _TASKS = ('classification', 'segmentation')

    def _file_index(self, split, task):
        return self._SPLITS.index(split) * 2 + self._TASKS.index(task)

    @property
    def processed_file_names(self):
        return [f'shrec_{self.tag}_{s}_{t[:3]}.pt' for s in self._SPLITS
                for t in self._TASKS]

    @property
    def num_classes(self) -> int:
        """12 shape classes, or 6 part labels for segmentation."""
        if self.task == 'segmentation':
            return len(self.part_names)
        return len(self.classes)

    def process(self):
        keys = [(c, j) for c in range(len(self.classes))
                for j in range(self.num_per_class)]
        lists = [[] for _ in range(4)]
        desc = 'Generating SyntheticSHREC'
        results = map_examples(self, _Generate(worker_copy(self)), keys,
                               desc, 'shape', lambda _, key:
                               f'SyntheticSHREC {self.classes[key[0]]} '
                               f'shape {key[1]}')
        for (_, j), pair in zip(keys, results):
            split = 'train' if j < self.num_train_per_class else 'test'
            for task, data in zip(self._TASKS, pair):
                if data is not None:
                    lists[self._file_index(split, task)].append(data)
        for data_list, path in zip(lists, self.processed_paths):
            if len(data_list) == 0:
                raise ValueError(f"'pre_filter' removed every shape of "
                                 f"{osp.basename(path)}")
            save_atomic(type(self), data_list, path)

    def generate(self, c: int, j: int):
        """Shape ``j`` of class ``c`` for classification and for
        segmentation (without transforms)."""
        lo, hi = self.num_vertices
        rng = shape_rng(self.seed, c, j)
        n = int(rng.integers(lo, hi + 1))
        V, F, lab = shapes.make_shape(self.classes[c], rng, n,
                                      noise=self.noise, rotate=self.rotate)
        pos = torch.from_numpy(V).float()
        face = torch.from_numpy(F).t().contiguous().long()
        y = torch.tensor([c], dtype=torch.long)
        cls = IntrinsicData(pos=pos, face=face, y=y)
        seg = IntrinsicData(pos=pos.clone(), face=face.clone(),
                            y=torch.from_numpy(lab).long(),
                            category=y.clone())
        return cls, seg

    def __repr__(self) -> str:
        return (f'{self.__class__.__name__}({len(self)}, split={self.split!r},'
                f' task={self.task!r}, seed={self.seed})')


class _Generate:
    """Both tasks' versions of one shape, pre-filtered and pre-transformed
    (the work of one shape in a worker process)."""
    def __init__(self, dataset):
        self.dataset = dataset

    def __call__(self, key):
        return [preprocess(self.dataset, data)
                for data in self.dataset.generate(*key)]
