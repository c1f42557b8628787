"""ShapeNet-Part-style part segmentation data set generated offline."""
from typing import Callable, Dict, List, Optional, Tuple

import numpy as np
import torch
from tqdm.auto import tqdm

from tg_intrinsic.data import IntrinsicData
from tg_intrinsic.geometry.checks import check_positive_int
from tg_intrinsic.geometry.pointcloud.neighbors import fps

from . import modelnet_shapes as shapes
from .common import (GeneratedDataset, check_fraction, check_split,
                     check_split_counts, fmt, save_atomic, shape_rng)

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


def _uniform(rng, lo, hi):
    return float(rng.uniform(lo, hi))


def airplane(rng):
    L = _uniform(rng, 1.6, 2.2)
    R = _uniform(rng, 0.09, 0.14)
    zs = np.array([0, 0.08, 0.25, 0.75, 0.95, 1.0]) * L
    rs = np.array([0, 0.6, 1.0, 1.0, 0.5, 0.15]) * R
    out = [(shapes.lathe([-L / 2, 0, 0], zs, rs, axis=(1.0, 0, 0)),
            'body')]
    span = _uniform(rng, 1.4, 2.2)
    chord = _uniform(rng, 0.22, 0.35)
    sweep = _uniform(rng, 0.0, 0.5)
    wx = _uniform(rng, -0.15, 0.1) * L
    wz = _uniform(rng, -0.6, 0.6) * R
    for side in (-1, 1):
        out.append((shapes.box([wx - sweep * span / 4, side * span / 4, wz],
                               [chord, span / 2, 0.035],
                               yaw=side * sweep * 0.5), 'wing'))
    ts = span * _uniform(rng, 0.25, 0.4)
    out.append((shapes.box([-0.42 * L, 0, R * 0.3],
                           [chord * 0.6, ts, 0.03]), 'tail'))
    fh = _uniform(rng, 0.18, 0.35)
    out.append((shapes.box([-0.42 * L, 0, R * 0.5 + fh / 2],
                           [chord * 0.7, 0.03, fh]), 'tail'))
    n_eng = int(rng.choice([0, 2, 2, 4]))
    for k in range(n_eng // 2):
        y = span * (0.15 + 0.15 * k)
        for side in (-1, 1):
            x0 = wx - sweep * y / 2 + chord * 0.6
            out.append((shapes.cylinder(
                [x0, side * y, wz - 0.09],
                [x0 - chord * 1.2, side * y, wz - 0.09], 0.06), 'engine'))
    return out


def chair(rng):
    W, D = _uniform(rng, 0.4, 0.6), _uniform(rng, 0.4, 0.6)
    h = _uniform(rng, 0.4, 0.5)
    t = _uniform(rng, 0.04, 0.07)
    out = [(shapes.box([0, 0, h], [W, D, t]), 'seat')]
    if rng.random() < 0.75:
        lr = _uniform(rng, 0.015, 0.03)
        for x in (-1, 1):
            for y in (-1, 1):
                out.append((shapes.cylinder(
                    [x * (W / 2 - 0.04), y * (D / 2 - 0.04), 0],
                    [x * (W / 2 - 0.04), y * (D / 2 - 0.04), h - t / 2],
                    lr), 'leg'))
    else:  # office chair: column and star base
        out.append((shapes.cylinder([0, 0, 0.08], [0, 0, h - t / 2], 0.03),
                    'leg'))
        for k in range(5):
            a = 2 * np.pi * k / 5
            out.append((shapes.box([0.15 * np.cos(a), 0.15 * np.sin(a),
                                    0.06], [0.3, 0.04, 0.04], yaw=a), 'leg'))
    bh = _uniform(rng, 0.35, 0.6)
    tilt = _uniform(rng, 0.0, 0.25)
    back = shapes.box([0, 0, 0], [W, 0.04, bh])
    back.A = shapes.rot_x(-tilt) @ back.A
    back.t = np.array([0, -D / 2 + 0.02 - np.sin(tilt) * bh / 2,
                       h + t / 2 + bh / 2 * np.cos(tilt)])
    out.append((back, 'back'))
    if rng.random() < 0.5:  # armrests
        for x in (-1, 1):
            out.append((shapes.box([x * W / 2, 0, h + 0.2],
                                   [0.05, D * 0.9, 0.04]), 'arm'))
            out.append((shapes.box([x * W / 2, D / 2 - 0.06, h + 0.1],
                                   [0.04, 0.04, 0.2]), 'arm'))
    return out


def lamp(rng):
    base_r = _uniform(rng, 0.15, 0.25)
    H = _uniform(rng, 0.7, 1.4)
    base_h = _uniform(rng, 0.04, 0.1)
    out = [(shapes.cylinder([0, 0, 0], [0, 0, base_h], base_r), 'base')]
    if rng.random() < 0.5:  # straight stem
        top = np.array([0, 0, H])
        out.append((shapes.cylinder([0, 0, base_h], top, 0.02), 'tube'))
    else:  # arm with an elbow
        elbow = np.array([0, 0, H * 0.6])
        top = elbow + np.array([_uniform(rng, 0.2, 0.4), 0, H * 0.4])
        out.append((shapes.cylinder([0, 0, base_h], elbow, 0.02), 'tube'))
        out.append((shapes.cylinder(elbow, top, 0.02), 'tube'))
        out.append((shapes.ellipsoid(elbow, [0.035] * 3), 'tube'))
    sr0, sr1 = _uniform(rng, 0.08, 0.15), _uniform(rng, 0.18, 0.35)
    sh = _uniform(rng, 0.15, 0.3)
    if rng.random() < 0.5:  # conical shade around the bulb
        out.append((shapes.lathe(top - np.array([0, 0, sh * 0.6]),
                                 [0, 0.005, sh], [sr1, sr1, sr0]), 'shade'))
    else:  # globe
        out.append((shapes.ellipsoid(top, [sr1 * 0.8] * 3), 'shade'))
    return out


def mug(rng):
    R = _uniform(rng, 0.25, 0.4)
    H = _uniform(rng, 0.5, 0.9)
    th = _uniform(rng, 0.02, 0.04)
    out = [(shapes.tube([0, 0, H / 2], R, R - th, H), 'body'),
           (shapes.cylinder([0, 0, 0], [0, 0, th * 1.5], R - th * 0.5),
            'body')]
    hr = _uniform(rng, 0.15, 0.25) * H
    out.append((shapes.torus(
        [R + hr * 0.3, 0, H * _uniform(rng, 0.45, 0.6)], hr,
        _uniform(rng, 0.03, 0.05), np.pi * 1.2,
        R_axis=shapes.rot_x(np.pi / 2) @ shapes.rot_z(-0.6 * np.pi)),
        'handle'))
    return out


def table(rng):
    W, D = _uniform(rng, 0.8, 1.8), _uniform(rng, 0.6, 1.0)
    h = _uniform(rng, 0.6, 0.8)
    t = _uniform(rng, 0.03, 0.06)
    round_top = rng.random() < 0.35
    if round_top:
        out = [(shapes.cylinder([0, 0, h - t], [0, 0, h], D / 2 * 1.1),
                'top')]
    else:
        out = [(shapes.box([0, 0, h - t / 2], [W, D, t]), 'top')]
    if round_top or rng.random() < 0.3:  # pedestal
        out.append((shapes.cylinder([0, 0, 0.03], [0, 0, h - t], 0.05),
                    'leg'))
        out.append((shapes.cylinder([0, 0, 0], [0, 0, 0.03],
                                    _uniform(rng, 0.2, 0.35)), 'support'))
    else:
        lw = _uniform(rng, 0.03, 0.07)
        x, y = W / 2 - 0.06, D / 2 - 0.06
        for sx in (-1, 1):
            for sy in (-1, 1):
                out.append((shapes.box([sx * x, sy * y, (h - t) / 2],
                                       [lw, lw, h - t]), 'leg'))
        if rng.random() < 0.5:  # lower shelf
            out.append((shapes.box([0, 0, 0.15], [2 * x, 2 * y, 0.02]),
                        'support'))
    return out


BUILDERS: Dict[str, Callable] = {'Airplane': airplane, 'Chair': chair,
                                 'Lamp': lamp, 'Mug': mug, 'Table': table}


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
    handle: 11-12) and Table (top, leg, support: 13-15). Every instance
    draws its primitives' proportions (and optional parts: engines,
    armrests, lower shelves, elbows, shade styles) at random, and is
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
    version = 1

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
    ):
        self.split = check_split(split)
        self.num_points = check_positive_int(num_points, 'num_points', 1)
        self.num_per_category = check_split_counts(num_per_category,
                                                   'num_per_category')
        self.oversample = check_positive_int(oversample, 'oversample', 1)
        self.scale_jitter = check_fraction(scale_jitter, 'scale_jitter')
        self.seed = check_positive_int(seed, 'seed', 0)
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
        ntr, nte = self.num_per_category
        lists = ([], [])
        total = len(self.categories) * (ntr + nte)
        with tqdm(total=total, desc='Generating SyntheticShapeParts',
                  disable=not self.log, unit='shape') as bar:
            for c in range(len(self.categories)):
                for j in range(ntr + nte):
                    data = self.generate(c, j)
                    bar.update(1)
                    if self.pre_filter is not None and \
                            not self.pre_filter(data):
                        continue
                    if self.pre_transform is not None:
                        data = self.pre_transform(data)
                    lists[0 if j < ntr else 1].append(data)
        for data_list, path in zip(lists, self.processed_paths):
            if len(data_list) == 0:
                raise ValueError("'pre_filter' removed every shape of a split")
            save_atomic(type(self), data_list, path)

    def generate(self, c: int, j: int, return_parts: bool = False):
        """Generates shape ``j`` of category ``c`` (without transforms).
        With :obj:`return_parts`, also returns the primitives
        (:class:`~tg_intrinsic.datasets.modelnet_shapes.Part`, in the
        coordinates of the returned points) and their global part labels.
        """
        name = self.categories[c]
        rng = shape_rng(self.seed, c, j)
        built = BUILDERS[name](rng)
        parts = [part for part, _ in built]
        offset = CATEGORY_PARTS[name][0]
        labels = np.array([offset + PART_NAMES[name].index(part_name)
                           for _, part_name in built], dtype=np.int64)
        if self.scale_jitter > 0:
            stretch = np.exp(rng.uniform(-self.scale_jitter,
                                         self.scale_jitter, 3))
            for part in parts:
                part.A = stretch[:, None] * part.A
                part.t = stretch * part.t
        dense = self.num_points * self.oversample
        pts, nrm, fid = shapes.sample_surface(parts, dense, rng)
        primitive = shapes.shape_mesh(parts)[2][fid]
        idx = fps(torch.from_numpy(pts), self.num_points / dense,
                  random_start=False)[:self.num_points].numpy()
        pts, nrm, primitive = pts[idx], nrm[idx], primitive[idx]
        centre = 0.5 * (pts.max(0) + pts.min(0))
        scale = np.linalg.norm(pts - centre, axis=1).max()
        pts = (pts - centre) / scale
        data = IntrinsicData(pos=torch.from_numpy(pts).float(),
                             normal=torch.from_numpy(nrm).float(),
                             y=torch.from_numpy(labels[primitive]),
                             category=torch.tensor([c], dtype=torch.long))
        if not return_parts:
            return data
        for part in parts:
            part.A = part.A / scale
            part.t = (part.t - centre) / scale
        return data, parts, labels

    def __repr__(self) -> str:
        return (f'{self.__class__.__name__}({len(self)}, split={self.split!r},'
                f' num_points={self.num_points}, seed={self.seed})')
