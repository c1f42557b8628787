"""ModelNet-style rigid point-cloud dataset generated offline."""
from typing import Callable, Optional, Tuple

import numpy as np
import torch

from tg_intrinsic.data import IntrinsicData
from tg_intrinsic.geometry.checks import check_positive_int
from tg_intrinsic.geometry.pointcloud.neighbors import fps

from . import modelnet_shapes as shapes
from .common import (GeneratedDataset, check_fraction, check_split,
                     check_split_counts, check_workers, fmt, shape_rng)


def sample_cloud(parts, num_points: int, oversample: int,
                 scale_jitter: float, rng):
    r"""A point cloud of the composed shape ``parts`` (primitives of
    :mod:`.modelnet_shapes`): the parts stretched along x, y and z by
    :math:`e^u`, :math:`u \sim U(-s, s)` with ``s = scale_jitter`` (in
    place), ``oversample * num_points`` area-weighted samples of the
    visible surface thinned to ``num_points`` by farthest point sampling,
    centred on the bounding box and scaled into the unit ball. Returns the
    points, their normals and the index of the part each lies on; the
    parts are moved into the same coordinates."""
    if scale_jitter > 0:
        stretch = np.exp(rng.uniform(-scale_jitter, scale_jitter, 3))
        for part in parts:
            part.A = stretch[:, None] * part.A
            part.t = stretch * part.t
    dense = num_points * oversample
    pts, nrm, fid = shapes.sample_surface(parts, dense, rng)
    idx = fps(torch.from_numpy(pts), num_points / dense,
              random_start=False)[:num_points].numpy()
    pts, nrm = pts[idx], nrm[idx]
    part_index = shapes.shape_mesh(parts)[2][fid[idx]]
    centre = 0.5 * (pts.max(0) + pts.min(0))
    scale = np.linalg.norm(pts - centre, axis=1).max()
    for part in parts:
        part.A = part.A / scale
        part.t = (part.t - centre) / scale
    return (pts - centre) / scale, nrm, part_index


class SyntheticModelNet(GeneratedDataset):
    r"""A synthetic, ModelNet-style dataset of rigid man-made objects as
    point clouds with normals, for point-cloud classification (the
    setting of "DeltaConv: anisotropic operators for geometric deep
    learning on point clouds", Wiersma et al., SIGGRAPH 2022).

    Twelve classes (:obj:`classes`: airplane, bed, bench, bookshelf,
    bottle, chair, cup, guitar, lamp, monitor, sofa, table) assembled from
    boxes, cylinders, ellipsoids, solids of revolution, tori and hollow
    tubes, with random proportions and part counts per instance (legs or
    pedestals, engines, shelves, seats, armrests, handles, ...) and a
    random stretch along the axes (:obj:`scale_jitter`), in ModelNet's
    canonical upright orientation (z up). Points are drawn
    uniformly from the visible surface of the union of the parts
    (area-weighted triangle sampling; samples hidden inside another part
    or on a face pressed against another part, where parts touch, are
    discarded), :obj:`oversample` times :obj:`num_points` of them, and
    thinned to :obj:`num_points` by farthest point sampling, as in the
    usual ModelNet preprocessing. Each point carries the normal of the
    triangle it was drawn from. Every cloud is centred (bounding-box
    centre) and scaled into the unit ball,

    .. math::
        \mathbf{x}_i \leftarrow \frac{\mathbf{x}_i - \mathbf{c}}
        {\max_j \|\mathbf{x}_j - \mathbf{c}\|_2}.

    Shapes are generated on first use from :obj:`seed` (each shape from its
    own seed) and cached under :obj:`root`; the generation parameters are
    part of the processed file names, so changing them regenerates.

    Args:
        root (str): Root directory; processed files go to
            :obj:`root/processed`.
        split (str, optional): :obj:`"train"` or :obj:`"test"`.
            (default: :obj:`"train"`)
        num_points (int, optional): Points per cloud.
            (default: :obj:`1024`)
        num_per_class (tuple, optional): Shapes per class in the training
            and the test split. (default: :obj:`(40, 10)`)
        oversample (int, optional): Surface samples per output point before
            farthest point sampling. (default: :obj:`4`)
        scale_jitter (float, optional): Every instance is stretched along
            x, y and z by independent factors :math:`e^{u}`,
            :math:`u \sim U(-s, s)` (more variation of the proportions, as
            ModelNet's anisotropic-scaling augmentation), before sampling.
            (default: :obj:`0.25`)
        rotate_up (bool, optional): Rotate every shape by a random angle
            about the up (z) axis. (default: :obj:`False`, aligned)
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
        - **pos** :math:`(N, 3)` float32 with :math:`N =`
          :obj:`num_points`, :math:`\max_i \|\mathbf{x}_i\| = 1`
        - **normal** :math:`(N, 3)` float32 unit normals (outward)
        - **y** :math:`(1)` int64 class

    Stats:
        .. list-table::
            :header-rows: 1

            * - #classes
              - #shapes (default)
              - #points
            * - 12
              - 600 (480 train / 120 test)
              - 1024
    """

    classes: Tuple[str, ...] = tuple(shapes.CLASSES)
    #: Bumped whenever the generator changes, to invalidate old caches.
    version = 2

    def __init__(
        self,
        root: str,
        split: str = 'train',
        num_points: int = 1024,
        num_per_class: Tuple[int, int] = (40, 10),
        oversample: int = 4,
        scale_jitter: float = 0.25,
        rotate_up: bool = False,
        seed: int = 0,
        transform: Optional[Callable] = None,
        pre_transform: Optional[Callable] = None,
        pre_filter: Optional[Callable] = None,
        log: bool = True,
        force_reload: bool = False,
        workers: int = 1,
    ):
        self.split = check_split(split)
        self.num_points = check_positive_int(num_points, 'num_points', 1)
        self.num_per_class = check_split_counts(num_per_class,
                                                'num_per_class')
        self.oversample = check_positive_int(oversample, 'oversample', 1)
        self.scale_jitter = check_fraction(scale_jitter, 'scale_jitter')
        self.rotate_up = bool(rotate_up)
        self.seed = check_positive_int(seed, 'seed', 0)
        self.workers = check_workers(workers)
        super().__init__(root, transform, pre_transform, pre_filter, log=log,
                         force_reload=force_reload)
        self.load(self.processed_paths[0 if split == 'train' else 1],
                  data_cls=IntrinsicData)

    @property
    def tag(self) -> str:
        """Generation parameters, as they appear in the processed files."""
        return (f'v{self.version}_seed{self.seed}_pts{self.num_points}'
                f'_n{fmt(self.num_per_class)}_over{self.oversample}'
                f'_jit{fmt(self.scale_jitter)}'
                f'_rotup{fmt(self.rotate_up)}')

    @property
    def processed_file_names(self):
        return [f'modelnet_{self.tag}_{s}.pt' for s in ('train', 'test')]

    @property
    def num_classes(self) -> int:
        return len(self.classes)

    def process(self):
        self.generate_splits(len(self.classes), self.num_per_class,
                             'Generating SyntheticModelNet')

    def generate(self, c: int, j: int) -> IntrinsicData:
        """Generates shape ``j`` of class ``c`` (without transforms)."""
        rng = shape_rng(self.seed, c, j)
        parts = shapes.CLASSES[self.classes[c]](rng)
        pts, nrm, _ = sample_cloud(parts, self.num_points, self.oversample,
                                   self.scale_jitter, rng)
        if self.rotate_up:
            a = rng.uniform(0, 2 * np.pi)
            R = np.array([[np.cos(a), -np.sin(a), 0],
                          [np.sin(a), np.cos(a), 0], [0, 0, 1.0]])
            pts, nrm = pts @ R.T, nrm @ R.T
        return IntrinsicData(pos=torch.from_numpy(pts).float(),
                             normal=torch.from_numpy(nrm).float(),
                             y=torch.tensor([c], dtype=torch.long))

    def __repr__(self) -> str:
        return (f'{self.__class__.__name__}({len(self)}, split={self.split!r},'
                f' num_points={self.num_points}, seed={self.seed})')
