"""ShapeNet-Part-style part segmentation data set generated offline."""
from typing import Callable, Dict, List, Optional, Tuple

import numpy as np
import torch

from tg_intrinsic.data import IntrinsicData
from tg_intrinsic.geometry.checks import check_positive_int

from . import modelnet_shapes as shapes
from .common import (GeneratedDataset, check_fraction, check_split,
                     check_split_counts, check_workers, fmt, shape_rng)
from .synthetic_modelnet import sample_cloud

#: Semantic parts of every category, in the order of the global labels.
PART_NAMES: Dict[str, Tuple[str, ...]] = {
    'Airplane': ('body', 'wing', 'tail', 'engine'),
    'Chair': ('back', 'seat', 'leg', 'arm'),
    'Lamp': ('base', 'tube', 'shade'),
    'Mug': ('body', 'handle'),
    'Table': ('top', 'leg', 'support'),
}
_START = np.concatenate([[0], np.cumsum([len(p) for p in
                                         PART_NAMES.values()])])
#: Global part labels of every category (Airplane 0-3, ..., Table 13-15).
CATEGORY_PARTS: Dict[str, List[int]] = {
    name: list(range(int(start), int(start) + len(parts)))
    for (name, parts), start in zip(PART_NAMES.items(), _START)}
NUM_PARTS = int(_START[-1])


#: The composed-shape builders of every category (named parts, see
#: :func:`~tg_intrinsic.datasets.modelnet_shapes.named`).
BUILDERS: Dict[str, Callable] = {
    'Airplane': shapes.airplane, 'Chair': shapes.chair, 'Lamp': shapes.lamp,
    'Mug': shapes.cup, 'Table': shapes.table}


class SyntheticShapeParts(GeneratedDataset):
    r"""A synthetic, ShapeNet-Part-style part segmentation data set: point
    clouds with normals of man-made objects assembled from primitives,
    every point labelled with its semantic part, for the part segmentation
    setting of "DeltaConv: anisotropic operators for geometric deep
    learning on point clouds" (Wiersma et al., SIGGRAPH 2022). Generated,
    not downloaded.

    Five categories (:obj:`categories`) with 16 parts numbered globally in
    category order, as ShapeNet-Part's 50 (:obj:`category_parts`,
    :obj:`part_names`): Airplane (body, wing, tail, engine: 0-3), Chair
    (back, seat, leg, arm: 4-7), Lamp (base, tube, shade: 8-10), Mug (body,
    handle: 11-12) and Table (top, leg, support: 13-15). The shapes are
    those of :class:`SyntheticModelNet`'s airplane, chair, lamp, cup and
    table, whose builders name their parts
    (:func:`~tg_intrinsic.datasets.modelnet_shapes.named`). Every instance
    draws its primitives' proportions (and optional parts: engines,
    armrests, handles, lower shelves, elbows, shade styles) at random, and
    is
    stretched along x, y and z by :math:`e^{u}`, :math:`u \sim U(-s, s)`
    (:obj:`scale_jitter`). Points are drawn area-weighted from the visible
    surface of the union of the primitives (as
    :class:`SyntheticModelNet`), :obj:`oversample` times
    :obj:`num_points` of them, thinned to :obj:`num_points` by farthest
    point sampling; each takes the normal of its triangle and the part of
    its primitive. Clouds are centred (bounding box) and scaled into the
    unit ball,

    .. math::
        \mathbf{x}_i \leftarrow \frac{\mathbf{x}_i - \mathbf{c}}
        {\max_j \|\mathbf{x}_j - \mathbf{c}\|_2}.

    The layout matches :class:`ShapeNetPartNormal` (``pos``, ``normal``,
    ``y`` per point, ``category``; :obj:`part_mask`), so the same training
    code runs on both. Each shape is generated from its own seed
    (:obj:`seed`, category, index) and cached under :obj:`root`; the
    parameters are part of the processed file names.

    Args:
        root (str): Root directory; processed files go to
            :obj:`root/processed`.
        split (str, optional): :obj:`"train"` or :obj:`"test"`.
            (default: :obj:`"train"`)
        num_points (int, optional): Points per cloud.
            (default: :obj:`1024`)
        num_per_category (tuple, optional): Shapes per category in the
            training and the test split. (default: :obj:`(40, 10)`)
        oversample (int, optional): Surface samples per output point before
            farthest point sampling. (default: :obj:`2`)
        scale_jitter (float, optional): :math:`s` of the random stretch,
            in :math:`[0, 1]`. (default: :obj:`0.15`)
        seed (int, optional): Seed of the generation. (default: :obj:`0`)
        transform (callable, optional): Applied on access.
            (default: :obj:`None`)
        pre_transform (callable, optional): Applied before saving.
            (default: :obj:`None`)
        pre_filter (callable, optional): Keeps a shape if it returns
            :obj:`True`. (default: :obj:`None`)
        log (bool, optional): Print progress. (default: :obj:`True`)
        force_reload (bool, optional): Regenerate. (default: :obj:`False`)
        workers (int, optional): Processes that generate the shapes and
            apply the pre-filter and the pre-transform, one thread each;
            the result does not depend on it. (default: :obj:`1`)

    Shapes:
        - **pos** :math:`(N, 3)` float32, :math:`\max_i \|\mathbf{x}_i\|
          = 1`
        - **normal** :math:`(N, 3)` float32 unit normals (outward)
        - **y** :math:`(N)` int64 global part labels
        - **category** :math:`(1)` int64

    Stats:
        .. list-table::
            :header-rows: 1

            * - #categories
              - #parts
              - #shapes (default)
              - #points
            * - 5
              - 16
              - 250 (200 train / 50 test)
              - 1024
    """

    categories: Tuple[str, ...] = tuple(PART_NAMES)
    part_names: Dict[str, Tuple[str, ...]] = PART_NAMES
    category_parts: Dict[str, List[int]] = CATEGORY_PARTS
    #: Bumped whenever the generator changes, to invalidate old caches.
    version = 2

    def __init__(
        self,
        root: str,
        split: str = 'train',
        num_points: int = 1024,
        num_per_category: Tuple[int, int] = (40, 10),
        oversample: int = 2,
        scale_jitter: float = 0.15,
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
        self.num_per_category = check_split_counts(num_per_category,
                                                   'num_per_category')
        self.oversample = check_positive_int(oversample, 'oversample', 1)
        self.scale_jitter = check_fraction(scale_jitter, 'scale_jitter')
        self.seed = check_positive_int(seed, 'seed', 0)
        self.workers = check_workers(workers)
        self.part_mask = torch.zeros(len(self.categories), NUM_PARTS,
                                     dtype=torch.bool)
        for row, name in enumerate(self.categories):
            self.part_mask[row, CATEGORY_PARTS[name]] = True
        super().__init__(root, transform, pre_transform, pre_filter, log=log,
                         force_reload=force_reload)
        self.load(self.processed_paths[0 if split == 'train' else 1],
                  data_cls=IntrinsicData)

    @property
    def tag(self) -> str:
        """Generation parameters, as they appear in the processed files."""
        return (f'v{self.version}_seed{self.seed}_pts{self.num_points}'
                f'_n{fmt(self.num_per_category)}_over{self.oversample}'
                f'_jit{fmt(self.scale_jitter)}')

    @property
    def processed_file_names(self):
        return [f'parts_{self.tag}_{s}.pt' for s in ('train', 'test')]

    @property
    def num_classes(self) -> int:
        return NUM_PARTS

    def process(self):
        self.generate_splits(len(self.categories), self.num_per_category,
                             'Generating SyntheticShapeParts')

    def generate(self, c: int, j: int, return_parts: bool = False):
        """Generates shape ``j`` of category ``c`` (without transforms).
        With :obj:`return_parts`, also returns the primitives
        (:class:`~tg_intrinsic.datasets.modelnet_shapes.Part`, in the
        coordinates of the returned points) and their global part labels.
        """
        name = self.categories[c]
        rng = shape_rng(self.seed, c, j)
        parts = BUILDERS[name](rng)
        offset = CATEGORY_PARTS[name][0]
        labels = np.array([offset + PART_NAMES[name].index(part.name)
                           for part in parts], dtype=np.int64)
        pts, nrm, primitive = sample_cloud(parts, self.num_points,
                                           self.oversample,
                                           self.scale_jitter, rng)
        data = IntrinsicData(pos=torch.from_numpy(pts).float(),
                             normal=torch.from_numpy(nrm).float(),
                             y=torch.from_numpy(labels[primitive]),
                             category=torch.tensor([c], dtype=torch.long))
        if not return_parts:
            return data
        return data, parts, labels

    def __repr__(self) -> str:
        return (f'{self.__class__.__name__}({len(self)}, split={self.split!r},'
                f' num_points={self.num_points}, seed={self.seed})')
