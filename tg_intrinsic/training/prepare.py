"""The shape pipelines: DeltaNet's points with their operators, HSN's
discs, log maps and transport; prepared once per shape by parallel
processes and cached under ``--root``; and the training augmentation."""
import hashlib
import json
import os
from typing import Optional

import numpy as np
import torch
from torch_geometric.data import Data
from torch_geometric.transforms import Compose, NormalizeScale, RandomScale

from tg_intrinsic.errors import UsageError
from tg_intrinsic.training.sources import source_splits
from tg_intrinsic.utils import atomic_torch_save


def hsn_pipeline(radius: float = 0.2, rings: int = 6, max_order: int = 1,
                 method: str = 'fast', resample_vertices: Optional[int] = None):
    """The precomputation Harmonic Surface Networks train on, shared by
    ``train`` and ``tg-intrinsic precompute hsn``: optionally
    :obj:`resample_vertices` vertices by farthest point sampling (the
    paper's segmentation input), then mesh -> unit area, frames, geodesic
    discs of :obj:`radius` with log map and transport on two levels (a
    quarter of the points and twice the radius on level 1),
    circular-harmonic terms with :obj:`rings` rings up to order
    :obj:`max_order`; :obj:`method` is the log map method (``'fast'`` or
    ``'vector_heat'``). The paper's setting: radius 0.2 on unit area."""
    from tg_intrinsic.transforms import (FarthestPointResample,
                                         HarmonicPrecompute, LogMap,
                                         MultiscaleSupports, NormalizeArea)
    steps = [] if resample_vertices is None else \
        [FarthestPointResample(resample_vertices)]
    # LogMap writes the transport angles too (same solve).
    return Compose(steps + [
        NormalizeArea(), LogMap(radius, method=method),
        MultiscaleSupports([0.25], [2 * radius], method=method),
        HarmonicPrecompute(rings, max_order)])


def _cache_path(args, kind: str, sets, settings) -> str:
    """A cache file under ``root/<kind>_cache`` keyed by the data (its
    processed files' names, sizes and times) and every setting."""
    stamps = []
    for dataset in sets:
        for path in getattr(dataset, 'processed_paths', []):
            if os.path.exists(path):
                info = os.stat(path)
                stamps.append([path, info.st_size, info.st_mtime_ns])
    key = json.dumps([args.dataset, args.task, args.mesh_root,
                      [len(s) for s in sets], stamps, settings], default=str)
    return os.path.join(args.root, f'{kind}_cache', hashlib.sha1(
        key.encode()).hexdigest()[:16] + '.pt')


def _prepare_all(sets, prepare, cache: str, quiet: bool, workers: int = 1,
                 on_disk: bool = False):
    """``prepare(data, split, index)`` of every shape of the train and test
    sets, by ``workers`` processes (the same for any number): two lists
    cached in the file ``cache``, or, ``on_disk``, two
    :class:`~tg_intrinsic.datasets.PrecomputedOnDisk` data sets in the
    folder beside it (``<cache>_on_disk/train`` and ``test``)."""
    from tg_intrinsic.parallel import parallel_map
    splits = ('train', 'test')
    if on_disk:
        from tg_intrinsic.datasets.precomputed_on_disk import \
            PrecomputedOnDisk
        folder = os.path.splitext(cache)[0] + '_on_disk'
        return [PrecomputedOnDisk(os.path.join(folder, split),
                                  _Enumerated(dataset, split),
                                  _Unpack(prepare), workers=workers,
                                  log=not quiet)
                for split, dataset in zip(splits, sets)]
    if os.path.exists(cache):
        return torch.load(cache, weights_only=False)
    # one pool for both splits
    items = [_Enumerated(dataset, split)
             for split, dataset in zip(splits, sets)]
    done = list(parallel_map(_Unpack(prepare), _Chain(items), workers,
                             desc='preparing', log=not quiet, unit='shape',
                             name_of=lambda index, item: None))
    out = [done[:len(items[0])], done[len(items[0]):]]
    os.makedirs(os.path.dirname(cache), exist_ok=True)
    atomic_torch_save(out, cache)
    return out


class _Enumerated:
    """The items ``(data, split, index)`` of one split (picklable)."""
    def __init__(self, dataset, split: str):
        self.dataset, self.split = dataset, split

    def __len__(self) -> int:
        return len(self.dataset)

    def __getitem__(self, index: int):
        if not 0 <= index < len(self.dataset):
            raise IndexError(index)
        return self.dataset[index], self.split, index


class _Chain:
    """The items of several sequences, one after the other."""
    def __init__(self, parts):
        self.parts = parts

    def __len__(self) -> int:
        return sum(len(part) for part in self.parts)

    def __iter__(self):
        for part in self.parts:
            for index in range(len(part)):
                yield part[index]


class _Unpack:
    """``prepare(*item)`` for the items of :class:`_Enumerated`."""
    def __init__(self, prepare):
        self.prepare = prepare

    def __call__(self, item):
        return self.prepare(*item)

    def __repr__(self) -> str:
        return repr(self.prepare)


class _NamedErrors:
    """``prepare(data, split, index)`` whose failures name the shape (its
    file when the data set knows it)."""
    def __init__(self, prepare):
        self.prepare = prepare

    def __call__(self, data, split, index):
        try:
            return self.prepare(data, split, index)
        except ValueError as error:
            where = getattr(data, 'path', None) or f'{split} shape {index}'
            raise ValueError(f"{where}: {error}") from error

    def __repr__(self) -> str:
        return repr(self.prepare)


class _PreparePoints:
    """DeltaNet's preparation of one shape (see :func:`build_point_sets`),
    a picklable callable for the worker processes."""
    def __init__(self, num_points: int, k: int, regularizer: float,
                 data_seed: int, task: str):
        self.num_points, self.k, self.regularizer = num_points, k, regularizer
        self.data_seed, self.task = data_seed, task

    def __call__(self, data, split, index):
        from tg_intrinsic.geometry import estimate_normals, fps
        from tg_intrinsic.geometry.pointcloud.sampling import sample_surface
        from tg_intrinsic.transforms import MLSOperators
        seed = [self.data_seed, ('train', 'test').index(split), index]
        generator = torch.Generator().manual_seed(int(
            np.random.SeedSequence(seed).generate_state(1)[0]))
        out = Data(y=data.y)
        if getattr(data, 'face', None) is not None:
            pos, normal, chosen, bary = sample_surface(
                data.pos.double(), data.face, self.num_points,
                generator=generator)
            if self.task == 'segmentation':
                corner = data.face[bary.argmax(1), chosen]
                out.y = data.y[corner]
        else:
            pos = data.pos.double()
            normal = getattr(data, 'normal', None)
            if pos.size(0) < self.num_points:
                raise ValueError(f"has {pos.size(0)} points, fewer than "
                                 f"--num-points {self.num_points}")
            if pos.size(0) > self.num_points:
                keep = fps(pos, self.num_points / pos.size(0),
                           random_start=False)[:self.num_points]
                pos = pos[keep]
                normal = None if normal is None else normal[keep]
                if self.task == 'segmentation':
                    out.y = data.y[keep]
            if normal is None:
                normal = estimate_normals(pos, k=10)
        out.pos, out.normal = pos.float(), normal.float()
        for key in ('category', 'path'):
            if key in data:
                out[key] = data[key]
        return MLSOperators(self.k, self.regularizer)(NormalizeScale()(out))

    def __repr__(self) -> str:
        return (f'{type(self).__name__}(num_points={self.num_points}, '
                f'k={self.k}, regularizer={self.regularizer}, '
                f'data_seed={self.data_seed}, task={self.task!r})')


class _Pipeline:
    """``pipeline(data)`` called as ``prepare(data, split, index)``."""
    def __init__(self, pipeline):
        self.pipeline = pipeline

    def __call__(self, data, split, index):
        return self.pipeline(data)

    def __repr__(self) -> str:
        return repr(self.pipeline)


def _check_num_classes(source, num_classes: Optional[int]) -> None:
    """Raises a :class:`UsageError` when a checkpoint to resume, trained on
    ``num_classes`` classes, does not fit the data set ``source``."""
    if num_classes is not None and source.num_classes != num_classes:
        raise UsageError(
            f"the checkpoint in --out was trained on {num_classes} classes, "
            f"but the data set has {source.num_classes}; resume it on its "
            f"data, or start a new run with --overwrite (without --resume) "
            f"or in another --out")


def build_point_sets(args, num_classes: Optional[int] = None):
    """DeltaNet's train and test examples: :obj:`args.num_points` points
    per shape with unit normals, in the unit sphere, with the MLS operators
    (k neighbours, regulariser) attached. Meshes are sampled by
    :func:`~tg_intrinsic.geometry.pointcloud.sampling.sample_surface` with a generator
    seeded by (data seed, split, index); per-vertex labels go to each point
    from its triangle's nearest corner. Point clouds with more points keep
    their farthest-point subset; without normals they are estimated.
    Cached under ``root/deltanet_cache`` (prepared by ``args.workers``
    processes; stored on disk with ``args.on_disk``). With
    :obj:`num_classes` (a checkpoint's), data of another number of classes
    are refused before they are prepared."""
    if args.num_points < args.k:
        raise UsageError(f"--num-points {args.num_points} is fewer than --k "
                         f"{args.k}, the neighbours every point's operators "
                         f"fit; give --num-points {args.k} or more, or a "
                         f"smaller --k")
    sets = source_splits(args)
    _check_num_classes(sets[0], num_classes)
    prepare = _PreparePoints(args.num_points, args.k, args.regularizer,
                             args.data_seed, args.task)
    cache = _cache_path(args, 'deltanet', sets,
                        [args.num_points, args.k, args.regularizer,
                         args.data_seed])
    train_items, test_items = _prepare_all(
        sets, _NamedErrors(prepare), cache, args.quiet,
        args.workers, args.on_disk)
    return train_items, test_items, sets[0]


def build_mesh_datasets(args, num_classes: Optional[int] = None):
    """HSN's train and test examples: every mesh precomputed by
    :func:`hsn_pipeline` (the vertices are the points), cached under
    ``root/hsn_cache`` (prepared by ``args.workers`` processes; stored on
    disk with ``args.on_disk``). With :obj:`num_classes` (a checkpoint's),
    data of another number of classes are refused before they are
    prepared."""
    sets = source_splits(args)
    _check_num_classes(sets[0], num_classes)
    pipeline = hsn_pipeline(args.radius, args.rings, args.max_order,
                            args.logmap_method, args.resample_vertices)
    cache = _cache_path(args, 'hsn', sets,
                        [args.num_vertices, args.shapes_per_class,
                         repr(pipeline)])
    train_items, test_items = _prepare_all(
        sets, _NamedErrors(_Pipeline(pipeline)), cache, args.quiet,
        args.workers, args.on_disk)
    return train_items, test_items, sets[0]


def augmentation(args) -> Optional[Compose]:
    """The training-time transforms of ``args``: rotation, scale and
    translation, in that order."""
    from tg_intrinsic.transforms import (RandomAxisScale, RandomRotation,
                                         RandomTranslation)
    steps = []
    if args.rotate != 'none':
        steps.append(RandomRotation(None if args.rotate == 'so3'
                                    else args.rotate, args.max_angle))
    if args.scale is not None:
        steps.append(RandomAxisScale(tuple(args.scale)) if args.anisotropic
                     else RandomScale(tuple(args.scale)))
    if args.translate > 0:
        steps.append(RandomTranslation(args.translate))
    return Compose(steps) if steps else None
