"""Synthetic shape correspondence: one template mesh in many poses."""
from typing import Callable, Optional, Sequence

import numpy as np
import scipy.sparse as sp
import torch
from scipy.sparse.csgraph import connected_components
from torch import Tensor

from tg_intrinsic.data import IntrinsicData
from tg_intrinsic.geometry.checks import check_positive_int

from . import shrec_shapes as shapes
from .common import (GeneratedDataset, check_split, check_workers, fmt,
                     map_examples, preprocess, save_atomic, shape_rng,
                     worker_copy)
from .quadric_decimation import self_intersections


class SyntheticCorrespondence(GeneratedDataset):
    r"""A FAUST-style dense correspondence dataset generated offline: one
    template mesh in many non-rigid poses, so that vertex :math:`i` of
    every pose corresponds to vertex :math:`i` of the template (the
    ground truth is the vertex index, :obj:`data.y`), as in the
    correspondence experiment of Harmonic Surface Networks ("CNNs on
    surfaces using rotation-equivariant features", Wiersma et al.,
    SIGGRAPH 2020).

    The template is a rest-pose humanoid of :class:`SyntheticSHREC` (a
    closed genus-0 mesh of unit area, :obj:`num_vertices` vertices, no
    noise). Its four limbs are found from the part labels (connected
    components of upper, lower and end parts); the shoulder / hip
    :math:`\mathbf{r}` and the elbow / knee :math:`\mathbf{m}` of a limb
    are the centroids of the vertices where its parts meet. A pose turns
    every upper limb by a rotation :math:`R_1` (random axis across the
    limb, angle up to :math:`40^\circ \cdot` :obj:`pose`) about
    :math:`\mathbf{r}` and its lower limb by a further :math:`R_2` (up to
    :math:`70^\circ \cdot` :obj:`pose`) about :math:`\mathbf{m}`, blended
    by linear blend skinning,

    .. math::
        \mathbf{x}' = (1 - w_1)\, \mathbf{x} + (w_1 - w_2)\,
        T_1 \mathbf{x} + w_2\, T_1 T_2 \mathbf{x},

    with weights :math:`w_1 \geq w_2` the indicator functions of the limb
    and of its lower part, smoothed over a few rings of the mesh. Bones
    move rigidly, so a pose is near-isometric: edge lengths change at the
    joints only (median change below 2 %, at most 60 %, which is checked);
    poses whose surface intersects itself are redrawn. Poses keep the
    template's connectivity; with :obj:`permute` the vertices of every
    pose are listed in a random order (and :obj:`data.y` says which
    template vertex each one is). Every pose comes from its own seed, so
    the data do not depend on the machine or on the order of generation.

    Args:
        root (str): Root directory; processed files go to
            :obj:`root/processed`.
        split (str, optional): :obj:`"train"` or :obj:`"test"`.
            (default: :obj:`"train"`)
        num_train (int, optional): Training poses. (default: :obj:`20`)
        num_test (int, optional): Test poses. (default: :obj:`10`)
        num_vertices (int, optional): Vertices of the template.
            (default: :obj:`1000`)
        pose (float, optional): Scale of the joint angles, in
            :math:`[0, 1.5]`; :obj:`0` repeats the template.
            (default: :obj:`1.0`)
        rotate (bool, optional): Randomly rotate every pose (uniformly on
            :math:`SO(3)`). (default: :obj:`False`, as FAUST's aligned
            scans)
        permute (bool, optional): List the vertices of every pose in a
            random order. (default: :obj:`False`)
        seed (int, optional): Seed of the generation. (default: :obj:`0`)
        transform (callable, optional): Applied on access.
            (default: :obj:`None`)
        pre_transform (callable, optional): Applied before saving.
            (default: :obj:`None`)
        log (bool, optional): Print progress. (default: :obj:`True`)
        force_reload (bool, optional): Regenerate. (default: :obj:`False`)
        workers (int, optional): Processes that pose the template and
            apply the pre-filter and the pre-transform, one thread each;
            the result does not depend on it. (default: :obj:`1`)

    Shapes:
        - **pos** :math:`(N, 3)` float32, **face** :math:`(3, F)` int64
          (the template's triangles, renumbered with :obj:`permute`)
        - **y** :math:`(N)` int64: the template vertex of every vertex
        - **part** :math:`(N)` int64: its part label
          (:obj:`SyntheticSHREC.part_names`)
        - :obj:`template`: the rest pose with ``pos``, ``face``, ``part``
    """
    #: Bumped whenever the generator changes, to invalidate old caches.
    version = 1
    #: Largest joint angles at pose 1 (upper and lower limb), in degrees.
    max_angles = (40.0, 70.0)
    #: Largest relative change of an edge length that a pose may have.
    max_stretch = 0.6

    def __init__(self, root: str, split: str = 'train', num_train: int = 20,
                 num_test: int = 10, num_vertices: int = 1000,
                 pose: float = 1.0, rotate: bool = False,
                 permute: bool = False, seed: int = 0,
                 transform: Optional[Callable] = None,
                 pre_transform: Optional[Callable] = None,
                 log: bool = True, force_reload: bool = False,
                 workers: int = 1):
        self.split = check_split(split)
        self.num_train = check_positive_int(num_train, 'num_train')
        self.num_test = check_positive_int(num_test, 'num_test')
        self.num_vertices = check_positive_int(num_vertices, 'num_vertices',
                                               minimum=300)
        pose = float(pose)
        if not 0.0 <= pose <= 1.5:
            raise ValueError(f"'pose' must be in [0, 1.5] (a scale of the "
                             f"joint angles), got {pose}")
        self.pose = pose
        self.rotate, self.permute = bool(rotate), bool(permute)
        self.seed = check_positive_int(seed, 'seed', 0)
        self.workers = check_workers(workers)
        super().__init__(root, transform, pre_transform, None, log=log,
                         force_reload=force_reload)
        self.load(self.processed_paths[('train', 'test').index(split)],
                  data_cls=IntrinsicData)
        self.template = torch.load(self.processed_paths[2],
                                   weights_only=False)

    @property
    def tag(self) -> str:
        """Generation parameters, as they appear in the processed files."""
        return (f'v{self.version}_seed{self.seed}_train{self.num_train}'
                f'_test{self.num_test}_verts{self.num_vertices}'
                f'_pose{fmt(self.pose)}_rot{fmt(self.rotate)}'
                f'_perm{fmt(self.permute)}')

    @property
    def processed_file_names(self):
        return [f'corr_{self.tag}_{name}.pt'
                for name in ('train', 'test', 'template')]

    @property
    def num_classes(self) -> int:
        """Vertices of the template (the classes of a vertex)."""
        return self.num_vertices

    def process(self):
        V, F, part = shapes.make_shape(
            'human', shape_rng(self.seed, 0), self.num_vertices, pose=0.0,
            noise=0.0, rotate=False)
        rig = _rig(V, F, part)
        template = IntrinsicData(
            pos=torch.from_numpy(V).float(),
            face=torch.from_numpy(F).t().contiguous().long(),
            part=torch.from_numpy(part).long())
        keys = [(split, k) for split, count in (('train', self.num_train),
                                                ('test', self.num_test))
                for k in range(count)]
        desc = 'Generating SyntheticCorrespondence'
        results = list(map_examples(
            self, _Pose(worker_copy(self), (V, F, part, rig)), keys, desc,
            'pose', lambda _, key: f'SyntheticCorrespondence {key[0]} pose '
            f'{key[1]}'))
        lists = [[data for (split, _), data in zip(keys, results)
                  if split == name] for name in ('train', 'test')]
        for data_list, path in zip(lists, self.processed_paths):
            save_atomic(type(self), data_list, path)
        torch.save(template, self.processed_paths[2])

    def _pose(self, V, F, part, rig, rng) -> IntrinsicData:
        for attempt in range(20):
            scale = self.pose * (1.0 if attempt < 10 else 0.5)
            W = pose_limbs(V, rig, rng, scale, self.max_angles)
            if edge_stretch(V, W, F).max() <= self.max_stretch and \
                    self_intersections(W, F) == 0:
                break
        else:  # pragma: no cover - half the angles always worked so far
            raise RuntimeError('no valid pose found in 20 draws; lower '
                               "'pose'")
        if self.rotate:
            W = W @ shapes.random_rotation(rng).T
        order = rng.permutation(len(V)) if self.permute \
            else np.arange(len(V))
        inverse = np.empty_like(order)
        inverse[order] = np.arange(len(V))
        return IntrinsicData(
            pos=torch.from_numpy(W[order]).float(),
            face=torch.from_numpy(inverse[F]).t().contiguous().long(),
            y=torch.from_numpy(order).long(),
            part=torch.from_numpy(part[order]).long())

    def __repr__(self) -> str:
        return (f'{self.__class__.__name__}({len(self)}, split={self.split!r},'
                f' num_vertices={self.num_vertices}, seed={self.seed})')


class _Pose:
    """Pose ``(split, k)`` of the template, pre-transformed (the work of
    one pose in a worker process)."""
    def __init__(self, dataset, template):
        self.dataset, self.template = dataset, template

    def __call__(self, key):
        split, k = key
        rng = shape_rng(self.dataset.seed, 1 + (split == 'test'), k)
        return preprocess(self.dataset,
                          self.dataset._pose(*self.template, rng))


def _adjacency(F, n):
    e = np.concatenate([F[:, [0, 1]], F[:, [1, 2]], F[:, [2, 0]]])
    A = sp.coo_matrix((np.ones(len(e)), (e[:, 0], e[:, 1])), shape=(n, n))
    return ((A + A.T) > 0).astype(float).tocsr()


def _rig(V, F, part, rings: int = 8):
    """Limbs of a labelled template: per limb the root and middle joints
    and the smoothed skinning weights of the limb and its lower part."""
    n = len(V)
    A = _adjacency(F, n)
    limb = np.isin(part, [shapes.PROX, shapes.DIST, shapes.EXTR])
    mask = sp.diags(limb.astype(float))
    _, comp = connected_components(mask @ A @ mask, directed=False)
    step = sp.diags(1.0 / np.asarray(A.sum(1)).ravel()) @ A

    def smooth(w):
        for _ in range(rings):
            w = 0.5 * w + 0.5 * (step @ w)
        return w

    def meet(a, b):  # centroid of the vertices of a next to b
        touch = (A @ b.astype(float)) > 0
        return V[a & touch].mean(0)

    rig = []
    for c in np.unique(comp[limb]):
        m = limb & (comp == c)
        upper, lower = m & (part == shapes.PROX), m & (part != shapes.PROX)
        if not upper.any() or not lower.any():  # pragma: no cover
            continue
        root, mid = meet(m, ~limb), meet(upper, lower)
        w1 = smooth(m.astype(float))
        w2 = np.minimum(smooth(lower.astype(float)), w1)
        rig.append((root, mid, V[lower].mean(0), w1, w2))
    return rig


def _across(rng, direction):
    """A random unit axis perpendicular to ``direction``."""
    d = direction / np.linalg.norm(direction)
    a = rng.normal(size=3)
    return a - (a @ d) * d


def pose_limbs(V, rig, rng, scale, max_angles):
    """Linear blend skinning of every limb of ``rig`` (see the class)."""
    out = V.copy()
    for root, mid, end, w1, w2 in rig:
        R1 = shapes.rot(_across(rng, mid - root), np.deg2rad(
            rng.uniform(-1, 1) * max_angles[0] * scale))
        R2 = shapes.rot(_across(rng, end - mid), np.deg2rad(
            rng.uniform(-1, 1) * max_angles[1] * scale))
        T1 = (V - root) @ R1.T + root
        T12 = ((V - mid) @ R2.T + mid - root) @ R1.T + root
        out += (w1 - w2)[:, None] * (T1 - V) + w2[:, None] * (T12 - V)
    return out


def edge_stretch(V, W, F):
    """Relative change of every edge length from ``V`` to ``W``."""
    e = np.concatenate([F[:, [0, 1]], F[:, [1, 2]], F[:, [2, 0]]])
    before = np.linalg.norm(V[e[:, 0]] - V[e[:, 1]], axis=1)
    after = np.linalg.norm(W[e[:, 0]] - W[e[:, 1]], axis=1)
    return np.abs(after / before - 1)


def correspondence_accuracy(pred: Tensor, target: Tensor, dist: Tensor,
                            thresholds: Sequence[float]) -> Tensor:
    r"""Fraction of predicted correspondences within each geodesic error
    threshold. These are the curves of the Princeton benchmark (Kim et al.,
    2011), as in the FAUST plot of Harmonic Surface Networks:

    .. math::
        a(t) = \frac{1}{N} \big|\{i : D_{\hat{y}_i y_i} \leq t \cdot
        \max D\}\big|,

    with :math:`D` the geodesic distances on the template (e.g. from
    :func:`~tg_intrinsic.geometry.geodesics.distance.geodesic_distances`)
    and :math:`t` relative to its geodesic diameter.

    Shapes:
        - **input:** pred, target :math:`(N)` template vertices, dist
          :math:`(T, T)`, thresholds :math:`(K)`
        - **output:** :math:`(K)`
    """
    if pred.shape != target.shape or pred.dim() != 1:
        raise ValueError(f"'pred' and 'target' must be 1-D of the same "
                         f"length, got {tuple(pred.shape)} and "
                         f"{tuple(target.shape)}")
    if dist.dim() != 2 or dist.size(0) != dist.size(1):
        raise ValueError(f"'dist' must be a square matrix of template "
                         f"distances, got {tuple(dist.shape)}")
    if pred.numel() and (min(int(pred.min()), int(target.min())) < 0 or
                         max(int(pred.max()), int(target.max()))
                         >= dist.size(0)):
        raise ValueError(f"'pred' and 'target' must be template vertices in "
                         f"[0, {dist.size(0)})")
    error = dist[pred, target] / dist.max()
    t = torch.as_tensor(thresholds, dtype=error.dtype, device=error.device)
    return (error[None, :] <= t[:, None]).to(error.dtype).mean(1)

