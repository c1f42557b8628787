"""Train DeltaNet (on points sampled once from each shape) or a Harmonic
Surface Network (on the mesh vertices) on the synthetic data sets or your
own, with the papers' protocols as defaults.

Examples::

    python -m tg_intrinsic.train --dataset synthetic_modelnet --epochs 30
    python -m tg_intrinsic.train --protocol deltanet-shrec11 \
        --dataset mesh_folder --mesh-root shrec_16
    python -m tg_intrinsic.train --model hsn --dataset synthetic_shrec \
        --num-vertices 300 500
    python -m tg_intrinsic.train --model hsn --task segmentation \
        --dataset synthetic_shrec

Every option left out takes the value of the protocol (``--protocol``, or
the model and task's default one, see :mod:`tg_intrinsic.protocols`).
Inputs are prepared once per shape and cached under ``--root``: DeltaNet's
points (sampled with a generator seeded per shape, so a checkpoint always
scores the same) with their operators, HSN's discs, log maps and
transport. Rotations, uniform scales and translations keep both valid;
a per-axis scale makes DeltaNet rebuild its operators for every batch.

Writes to ``--out``: ``checkpoint.pt`` (model, optimiser, schedule, history
and the settings; written atomically at every evaluation, so ``--resume``
continues an interrupted run), ``metrics.json``, ``metrics.csv`` (one row
per epoch) and ``learning_curve.png``, and records them there
(:mod:`tg_intrinsic.io.results`). Before any data is prepared, the output
folder is checked: it may not be, or be inside, the data set folder; it
may hold files that ``train`` did not write only with ``--overwrite``
(they are kept); and a new run does not start over an earlier one there
unless ``--overwrite``, which deletes the earlier run's files first, so
the folder never mixes two runs.

``--resume`` continues from ``checkpoint.pt`` (or, when there is none,
says so and starts a new run at epoch 1, so a job script can always pass
it). The checkpoint must be readable and of the same model and task, and
the settings must be the checkpoint's: a run resumed with other values
would not be the run the checkpoint continues (the optimiser's state even
keeps the old ``--lr``). The check names every setting that differs.
``--allow-changes epochs,eval-every`` lets the settings that change how
the run goes on, not what the checkpoint holds, differ: ``--epochs``,
``--eval-every``, ``--sync-batch-norm`` and the path of the data set
folder (``--dataset`` or ``--mesh-root``, e.g. after moving it). Settings
that do not change what is computed (``--quiet``, ``--workers``,
``--threads``, ``--device``, ``--backend``, ``--on-disk``, ``--root``)
may always differ, and so may those the model or data set does not use.
A setting an older checkpoint did not save is not checked.

Evaluation reports what inference on the checkpoint gives: the test
scores are taken in eval mode (``model.eval()``) on the weights saved
with them. HSN normalises per mesh (:class:`~tg_intrinsic.nn.
ComplexInstanceNorm`, ``--hsn-norm instance``), the same function in
training and evaluation at any batch size; batch norms (DeltaNet's, or
HSN's with ``--hsn-norm batch``) get running statistics recomputed under
the current weights before every evaluation
(:func:`~tg_intrinsic.nn.recalibrate_batch_norm` over up to
``RECALIBRATION_BATCHES`` training batches without augmentation). Every
evaluation also records ``test_accuracy_batch_statistics``, the same
weights normalised by each (shuffled) test batch's own statistics (not
with fewer than two test shapes per process), and the log says so when
the two differ by more than a point
(``benchmarks/normalisation.py`` measures why both are needed).

Runs are reproducible: ``--seed`` seeds the model's initialisation and,
with the epoch, everything random in an epoch: the shuffling, each
shape's augmentation (seeded by its index too) and dropout. So two runs
with the same arguments on the same machine and thread count give the
same weights bit for bit on the CPU, and an interrupted run resumed with
``--resume`` shuffles and augments its remaining epochs as an
uninterrupted one would, and ends with the same weights. (Older
checkpoints' generator states, ``rng``, are no longer needed and are
ignored.) A run starting or resuming in ``--out`` removes the temporary
files (``.tmp-*``) that a run killed while writing left there.

Data-parallel training: under ``torchrun`` (one process per core or GPU,
e.g. ``torchrun --standalone --nproc_per_node 2 -m tg_intrinsic.train
...``) every process joins the process group its environment describes
(backend ``gloo`` on the CPU, ``nccl`` on CUDA, ``--backend`` to choose)
and trains the model wrapped in
:class:`~torch.nn.parallel.DistributedDataParallel`. ``--batch-size`` is
the global batch, a multiple of the number of processes N: each process
takes its 1/N of every global batch (:func:`tg_intrinsic.distributed.
epoch_batches`; the remainder of an epoch is dropped as on one process),
so N processes and one see the same batches; losses and scores are summed
over the processes and equal one process's. Batch norm: by default each
process normalises with the statistics of its own part of the batch (as
DDP does; faster, but another run than one process's);
``--sync-batch-norm`` takes them over the global batch
(:func:`tg_intrinsic.nn.convert_sync_batch_norm`, on the CPU too), and
then, without dropout (``--dropout 0``), N processes train as one to
float32 rounding. Rank 0 prepares the input cache first (the others then
read it), reads a checkpoint to resume (any number of processes may have
written it) and alone prints and writes the outputs.
"""
import argparse
import hashlib
import json
import math
import os
import random
import time
from contextlib import ExitStack
from typing import Callable, Dict, List, Optional

import numpy as np
import torch
import torch.nn.functional as F
from torch_geometric.data import Data
from torch_geometric.loader import DataLoader
from torch_geometric.transforms import Compose, NormalizeScale, RandomScale
from tqdm import tqdm

from tg_intrinsic import distributed
from tg_intrinsic.devices import (PRECISIONS, autocast, check_device,
                                  check_precision, default_threads)
from tg_intrinsic.errors import UsageError, one_line
from tg_intrinsic.io.figures import save_figure
from tg_intrinsic.io.results import (RECORD, check_output_path, claim_folder,
                                     output_lock, recorded_files,
                                     write_record)
from tg_intrinsic.nn.harmonic_resnet_block import (COMPLEX_NORMS,
                                                   DEFAULT_COMPLEX_NORM)
from tg_intrinsic.nn.recalibrate_batch_norm import (batch_norms,
                                                    batch_statistics_copy,
                                                    recalibrate_batch_norm)
from tg_intrinsic.protocols import DEFAULT_PROTOCOL, PROTOCOLS, get_protocol
from tg_intrinsic.utils import (atomic_torch_save, atomic_write,
                                atomic_write_json, remove_temporaries)

__all__ = [
    'train', 'evaluate', 'build_model', 'read_checkpoint',
    'resolve_protocol', 'hsn_pipeline', 'instance_miou',
    'seed_everything', 'add_arguments', 'parse_args', 'main',
]

DATASETS = ('synthetic_modelnet', 'synthetic_shrec', 'mesh_folder',
            'synthetic_parts')
MODELS = ('deltanet', 'hsn')
TASKS = ('classification', 'segmentation')
ROTATIONS = ('none', 'so3', 'x', 'y', 'z', 'xyz')
# The data sets each model and task can train on.
SUPPORTED = {('deltanet', 'classification'): DATASETS[:3],
             ('deltanet', 'segmentation'): ('synthetic_shrec', 'mesh_folder',
                                            'synthetic_parts'),
             ('hsn', 'classification'): ('synthetic_shrec', 'mesh_folder'),
             ('hsn', 'segmentation'): ('synthetic_shrec', 'mesh_folder')}
DEFAULT_DATASET = {'deltanet': 'synthetic_modelnet',
                   'hsn': 'synthetic_shrec'}
# Options whose default is the protocol's value (argparse default None).
PROTOCOL_OPTIONS = ('task', 'num_points', 'k', 'regularizer',
                    'conv_channels', 'mlp_depth', 'embedding_size', 'radius',
                    'rings', 'max_order', 'hsn_channels', 'resample_vertices',
                    'rotate', 'max_angle', 'scale', 'anisotropic',
                    'translate', 'optimizer', 'lr', 'weight_decay',
                    'schedule', 'lr_min', 'milestones', 'gamma', 'epochs',
                    'batch_size', 'label_smoothing', 'train_per_class')


def resolve_protocol(args) -> None:
    """Fills every option left unset from the protocol (``args.protocol``,
    or the default one of ``args.model`` and ``args.task``); the model
    defaults to the protocol's."""
    if args.model is None:
        args.model = 'deltanet' if args.protocol is None else \
            get_protocol(args.protocol).model
    if args.protocol is None:
        args.protocol = DEFAULT_PROTOCOL[(args.model,
                                          args.task or 'classification')]
    protocol = get_protocol(args.protocol)
    if protocol.model != args.model:
        raise ValueError(f"protocol {protocol.name!r} trains "
                         f"{protocol.model}, not {args.model}")
    for name in PROTOCOL_OPTIONS:
        if getattr(args, name, None) is None:
            value = getattr(protocol, name)
            setattr(args, name, list(value) if isinstance(value, tuple)
                    else value)
    if args.rotate is None:
        args.rotate = 'none'


def source_splits(args):
    """The train and test splits of ``args.dataset`` as stored (meshes or
    point clouds), before any preparation; the generated sets are made by
    ``args.workers`` processes."""
    from tg_intrinsic.datasets import (SyntheticModelNet, SyntheticSHREC,
                                       SyntheticShapeParts, open_folder)
    # generated point clouds: the class and its (train, test) count option
    clouds = {'synthetic_modelnet': (SyntheticModelNet, 'num_per_class'),
              'synthetic_parts': (SyntheticShapeParts, 'num_per_category')}
    if args.dataset in clouds:
        cls, counts = clouds[args.dataset]
        kwargs = dict(num_points=args.num_points, seed=args.data_seed,
                      workers=args.workers, log=not args.quiet)
        if args.shapes_per_class is not None:
            half = max(1, args.shapes_per_class // 2)
            kwargs[counts] = (half, half)
        path = os.path.join(args.root, cls.__name__)
        return [cls(path, split, **kwargs) for split in ('train', 'test')]
    if args.dataset == 'synthetic_shrec':
        kwargs = dict(seed=args.data_seed, task=args.task,
                      workers=args.workers, log=not args.quiet)
        if args.num_vertices is not None:
            kwargs['num_vertices'] = tuple(args.num_vertices)
        if args.shapes_per_class is not None:
            kwargs.update(num_per_class=args.shapes_per_class,
                          num_train_per_class=max(
                              1, args.shapes_per_class // 2))
        path = os.path.join(args.root, 'SyntheticSHREC')
        return [SyntheticSHREC(path, split, **kwargs)
                for split in ('train', 'test')]
    if args.mesh_root is None:
        raise ValueError("--dataset mesh_folder needs --mesh-root PATH")
    # its processed files under --root: the data set may be read-only
    sets = [open_folder(args.mesh_root, split, task=args.task,
                        force_reload=args.force_reload, log=not args.quiet,
                        cache_root=args.root)
            for split in ('train', 'test')]
    count = sets[0].num_classes
    if args.task == 'classification' and count < 2:
        # one class: every prediction is right, nothing is learnt
        names = getattr(sets[0], 'classes', None) or []
        found = f" ({', '.join(names)})" if names else ''
        raise UsageError(
            f"the data set folder '{args.mesh_root}' holds {count} "
            f"class{'' if count == 1 else 'es'}{found}: classification "
            f"needs at least 2, one folder per class; add another class, "
            f"or use --task segmentation if the shapes carry part labels")
    return sets


def select_per_class(labels: List[int], per_class: int, seed: int
                     ) -> List[int]:
    """Indices of :obj:`per_class` items of every class (all of a class
    with fewer), drawn with a generator seeded by :obj:`seed`, in their
    original order: the papers' "10 training shapes per class" splits."""
    labels = np.asarray(labels)
    rng = np.random.default_rng(seed)
    keep = []
    for c in np.unique(labels):
        members = np.flatnonzero(labels == c)
        keep.extend(rng.permutation(members)[:per_class].tolist())
    return sorted(keep)


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


def build_model(name: str, num_classes: int, args,
                num_categories: Optional[int] = None) -> torch.nn.Module:
    """The network of ``args``; DeltaNet segmentation embeds the object
    category when the data have :obj:`num_categories` (ShapeNet-Part)."""
    if name == 'deltanet':
        from tg_intrinsic.nn.models import (DeltaNetClassification,
                                            DeltaNetSegmentation)
        kwargs = dict(conv_channels=args.conv_channels, depth=args.mlp_depth,
                      k=args.k, regularizer=args.regularizer,
                      embedding_size=args.embedding_size,
                      vector_stream=not args.no_vector_stream)
        if getattr(args, 'dropout', None) is not None:
            kwargs['dropout'] = args.dropout
        if args.task == 'classification':
            return DeltaNetClassification(3, num_classes, **kwargs)
        return DeltaNetSegmentation(3, num_classes,
                                    num_categories=num_categories, **kwargs)
    if name == 'hsn':
        from tg_intrinsic.nn.models import (HSNClassification,
                                            HSNSegmentation)
        cls = HSNClassification if args.task == 'classification' \
            else HSNSegmentation
        return cls(3, num_classes, channels=args.hsn_channels,
                   max_order=args.max_order, rings=args.rings,
                   norm=None if args.hsn_norm == 'none' else args.hsn_norm)
    raise ValueError(f"unknown model {name!r}; choose one of {MODELS}")


def instance_miou(pred: torch.Tensor, y: torch.Tensor,
                  parts: torch.Tensor) -> float:
    r"""Mean intersection over union of one shape's parts, as ShapeNet-Part
    is scored: over the parts :obj:`parts` (a boolean mask over labels) of
    its category, a part absent from both prediction and truth counting
    as 1,

    .. math::
        \mathrm{mIoU} = \frac{1}{|P|} \sum_{p \in P}
        \frac{|\{\hat y = p\} \cap \{y = p\}|}
        {|\{\hat y = p\} \cup \{y = p\}|} .
    """
    labels = parts.nonzero().flatten()
    hit = pred.view(-1, 1) == labels.view(1, -1)
    true = y.view(-1, 1) == labels.view(1, -1)
    inter = (hit & true).sum(0).double()
    union = (hit | true).sum(0).double()
    iou = torch.where(union > 0, inter / union.clamp_min(1),
                      torch.ones_like(union))
    return float(iou.mean())


@torch.no_grad()
def evaluate(model, loader, device, part_mask=None,
             statistics: str = 'running', precision: str = '32-true'
             ) -> Dict:
    """Accuracy over shapes (classification) or points (segmentation); with
    a category-to-parts :obj:`part_mask` also the instance-averaged mIoU.
    In a data-parallel run every process scores its part of the test set
    (its :obj:`loader`) and the counts are summed over the processes.
    :obj:`statistics` is ``'running'`` (``model.eval()``, what inference
    gives) or ``'batch'`` (batch norms normalise with each test batch's own
    statistics, on a copy of the model: see
    :func:`batch_statistics_copy`); :obj:`precision` that of training
    (:data:`~tg_intrinsic.devices.PRECISIONS`)."""
    if statistics == 'batch':
        model = batch_statistics_copy(model)
    else:
        model.eval()
    correct = total = 0
    ious = []
    for batch in loader:
        batch = batch.to(device)
        with autocast(precision, device):
            pred = model(batch).argmax(dim=-1)
        correct += int((pred == batch.y.view(-1)).sum())
        total += pred.numel()
        if part_mask is not None:
            for b in range(batch.num_graphs):
                at = batch.batch == b
                ious.append(instance_miou(
                    pred[at], batch.y[at],
                    part_mask[int(batch.category[b])].to(device)))
    sums = distributed.all_reduce_sum(torch.tensor(
        [correct, total, math.fsum(ious), len(ious)], dtype=torch.float64,
        device=device))
    out = {'accuracy': int(sums[0]) / max(int(sums[1]), 1)}
    if int(sums[3]):
        out['miou'] = float(sums[2]) / int(sums[3])
    return out


CSV_COLUMNS = ('epoch', 'train_loss', 'train_accuracy', 'test_accuracy',
               'test_accuracy_batch_statistics', 'test_miou', 'seconds')
# Training batches whose statistics replace batch norms' running ones
# before every evaluation (recalibrate_batch_norm).
RECALIBRATION_BATCHES = 200


def whole_batches(length: int, batch_size: int) -> List[List[int]]:
    """``range(length)`` in batches of :obj:`batch_size`, the remainder
    joined to the last batch: batch statistics need at least two shapes in
    every batch (when :obj:`length` is at least 2)."""
    count = max(1, length // batch_size)
    bounds = [b * batch_size for b in range(count)] + [length]
    return [list(range(bounds[b], bounds[b + 1])) for b in range(count)]


def statistics_gap(record: Dict, points: float = 1.0) -> str:
    """A note for the log when the test accuracy with batch statistics
    differs from the eval-mode one by more than :obj:`points` points."""
    other = record.get('test_accuracy_batch_statistics')
    if other is None or abs(other - record['test_accuracy']) * 100 <= points:
        return ''
    return (f" (with batch statistics {other:.3f}: eval-mode inference "
            f"differs by more than {points:g} point)")


def write_metrics_csv(history: List[Dict], path: str):
    """One row per epoch (``test_accuracy`` empty between evaluations),
    rewritten atomically after every epoch."""
    import csv
    import io
    buffer = io.StringIO()
    writer = csv.DictWriter(buffer, CSV_COLUMNS, extrasaction='ignore',
                            lineterminator='\n')
    writer.writeheader()
    for record in history:
        writer.writerow({k: '' if record.get(k) is None else record[k]
                         for k in CSV_COLUMNS})
    atomic_write(path, lambda f: f.write(buffer.getvalue()), 'w')


def plot_history(history: List[Dict], path: str, title: str):
    import matplotlib
    matplotlib.use('Agg')
    import matplotlib.pyplot as plt
    from matplotlib.ticker import MaxNLocator
    epochs = [h['epoch'] for h in history]
    fig, ax = plt.subplots(1, 2, figsize=(10, 3.6))
    for axis in ax:
        axis.xaxis.set_major_locator(MaxNLocator(integer=True))
        axis.grid(alpha=0.3)
    ax[0].plot(epochs, [h['train_loss'] for h in history])
    ax[0].set_xlabel('epoch')
    ax[0].set_ylabel('training loss')
    ax[1].plot(epochs, [h['train_accuracy'] for h in history], label='train')
    tested = [h for h in history if h.get('test_accuracy') is not None]
    ax[1].plot([h['epoch'] for h in tested],
               [h['test_accuracy'] for h in tested], 'o-', label='test')
    ax[1].set_xlabel('epoch')
    ax[1].set_ylabel('accuracy')
    ax[1].set_ylim(0, 1)
    ax[1].legend()
    ax[0].set_title('training loss')
    ax[1].set_title('accuracy')
    fig.suptitle(title)
    fig.tight_layout()
    save_figure(fig, path)


def seed_everything(seed: int) -> None:
    """Seeds the generators training draws from: torch's (model
    initialisation, dropout, this package's random transforms), NumPy's and
    Python's ``random`` (PyG's ``RandomScale`` and other transforms)."""
    torch.manual_seed(seed)
    np.random.seed(seed % 2 ** 32)
    random.seed(seed)


# The files a run writes into --out (see the module docstring).
CHECKPOINT = 'checkpoint.pt'
OUTPUT_FILES = (CHECKPOINT, 'metrics.json', 'metrics.csv',
                'learning_curve.png')
# Settings that do not change what a run computes: a resumed run may
# always give other values.
RESUME_FREE = ('quiet', 'workers', 'threads', 'device', 'backend', 'on_disk',
               'force_reload', 'root', 'out', 'resume', 'allow_changes',
               'overwrite', 'debug', 'command', 'compile')
# Settings that change how a resumed run goes on but not what its
# checkpoint holds: they may differ with --allow-changes.
RESUME_CHANGEABLE = ('epochs', 'eval_every', 'sync_batch_norm', 'mesh_root')
DELTANET_ONLY = ('num_points', 'k', 'regularizer', 'conv_channels',
                 'mlp_depth', 'embedding_size', 'no_vector_stream',
                 'dropout')
HSN_ONLY = ('hsn_channels', 'max_order', 'rings', 'hsn_norm', 'radius',
            'resample_vertices', 'logmap_method')
# The value of a setting that older checkpoints lack but that is known:
# before --hsn-norm, HSN trained with batch norm.
# Before --precision, every run trained in float32.
OLD_DEFAULTS = {'hsn': {'hsn_norm': 'batch', 'precision': '32-true'},
                'deltanet': {'precision': '32-true'}}


def _option(name: str, args) -> str:
    """The command-line option of the setting ``name``."""
    if name == 'mesh_root' and getattr(args, 'command', None) == 'train':
        return '--dataset'  # tg-intrinsic train names the folder so
    return '--' + name.replace('_', '-')


def _shown(value) -> str:
    if isinstance(value, bool):
        return 'on' if value else 'off'
    if isinstance(value, (list, tuple)):
        return ' '.join(str(v) for v in value)
    return 'none' if value is None else str(value)


def allowed_changes(text: str) -> List[str]:
    """The settings ``--allow-changes`` names (comma-separated option names,
    with or without the dashes) as ``args`` attributes; a
    :class:`ValueError` for a setting a resumed run cannot change."""
    names = []
    for word in filter(None, (w.strip() for w in text.split(','))):
        name = word.lstrip('-').replace('-', '_')
        name = 'mesh_root' if name == 'dataset' else name
        if name not in RESUME_CHANGEABLE + RESUME_FREE:
            shown = ', '.join(n.replace('_', '-') for n in
                              RESUME_CHANGEABLE[:-1]) + ' or dataset'
            raise ValueError(
                f"--allow-changes {word}: only {shown} (the folder's path) "
                f"may change when resuming; the other settings are part of "
                f"what the checkpoint holds, so start a new run to change "
                f"them")
        names.append(name)
    return names


def resume_changes(args, saved: Dict, saved_world: int = 1) -> List[str]:
    """The settings of ``args`` that differ from ``saved`` (a checkpoint's
    ``args``) and matter to the run: not those in :data:`RESUME_FREE`,
    those the model, data set or schedule do not use, nor those the
    checkpoint does not know (older versions saved fewer)."""
    ignored = set(RESUME_FREE)
    ignored.update(HSN_ONLY if args.model == 'deltanet' else DELTANET_ONLY)
    ignored.update(['lr_min'] if args.schedule == 'step'
                   else ['milestones', 'gamma'])
    if args.task != 'classification':
        ignored.add('train_per_class')
    if args.dataset != 'synthetic_shrec':
        ignored.add('num_vertices')
    if args.dataset == 'mesh_folder':
        ignored.add('shapes_per_class')
    if min(saved_world, distributed.launched_world_size()) == 1:
        ignored.add('sync_batch_norm')  # one process: nothing to sync
    changed = []
    for name, value in vars(args).items():
        if name in ignored or name not in saved:
            continue
        old = saved[name]
        old, value = [list(v) if isinstance(v, tuple) else v
                      for v in (old, value)]
        if name == 'mesh_root' and None not in (old, value) and \
                os.path.realpath(old) == os.path.realpath(value):
            continue
        if old != value:
            changed.append(name)
    return changed


def check_resume(args, state: Dict, path: str) -> List[str]:
    """Raises a :class:`UsageError` unless the checkpoint ``state`` (read
    from ``path``) was trained with the model, task and settings of
    ``args``, but for the settings ``args.allow_changes`` lets change;
    returns those changes as ``--option old -> new`` texts."""
    saved = {**OLD_DEFAULTS.get(args.model, {}), **(state.get('args') or {})}
    restart = ("start a new run with --overwrite (without --resume; it "
               "replaces the checkpoint) or in another --out")
    model, task = saved.get('model'), saved.get('task')
    if (model is not None and model != args.model) or \
            (task is not None and task != args.task):
        was = ' '.join(str(w) for w in (model or args.model, task) if w)
        raise UsageError(f"'{path}' holds a {was} model, not {args.model} "
                         f"{args.task}; resume it as {was}, or {restart}")
    changed = resume_changes(args, saved, state.get('world_size', 1))

    def listed(names):
        return ', '.join(f"{_option(n, args)} {_shown(saved[n])} -> "
                         f"{_shown(getattr(args, n))}" for n in names)
    refused = [n for n in changed if n not in args.allow_changes]
    if refused:
        need_flag = [n for n in refused if n in RESUME_CHANGEABLE]
        flag = '--allow-changes ' + ','.join(
            _option(n, args)[2:] for n in need_flag)
        fixed = [_option(n, args) for n in refused if n not in need_flag]
        if not fixed:
            advice = (f"add {flag} to go on with the new values, or resume "
                      f"with the checkpoint's")
        else:
            also = ', '.join(_option(n, args) for n in need_flag)
            advice = (f"{', '.join(fixed)} cannot change when resuming: "
                      f"resume with the checkpoint's values"
                      + (f" (and {flag} for {also})" if need_flag else '')
                      + f", or {restart}")
        raise UsageError(f"'{path}' was trained with other settings: "
                         f"{listed(refused)}; {advice}")
    return [listed([n]) for n in changed]


def read_checkpoint(path: str) -> Dict:
    """The training state saved in ``path``; a :class:`UsageError` when it
    is not a readable checkpoint of a run of this module."""
    restart = ("start a new run with --overwrite (without --resume; it "
               "replaces the file) or in another --out")
    try:
        state = torch.load(path, map_location='cpu', weights_only=False)
    except OSError:
        raise
    except Exception as error:  # noqa: BLE001 - whatever unpickling raises
        raise UsageError(f"'{path}' is not a readable checkpoint "
                         f"(truncated?); {restart}") from error
    if not isinstance(state, dict) or not {
            'model', 'optimizer', 'schedule', 'history', 'epoch'} <= set(
                state):
        raise UsageError(f"'{path}' is not a checkpoint of tg-intrinsic "
                         f"train (it holds no model, optimiser, schedule "
                         f"and epoch); {restart}")
    return state


def _earlier_run(out: str, files: List[str]) -> str:
    """Why a new run does not start in ``out``, which holds ``files`` of
    an earlier one."""
    if CHECKPOINT not in files:
        return (f"--out '{out}' holds an earlier run that saved no "
                f"checkpoint ({', '.join(files)}); --overwrite starts over "
                f"(deleting it), or give another --out")
    try:
        epoch = read_checkpoint(os.path.join(out, CHECKPOINT))['epoch']
    except ValueError:
        return (f"--out '{out}' holds an earlier run with an unreadable "
                f"checkpoint; --overwrite starts over (deleting it), or "
                f"give another --out")
    return (f"--out '{out}' holds an earlier run (checkpoint at epoch "
            f"{epoch}); --resume continues it, --overwrite starts over "
            f"(deleting it), or give another --out")


def claim_output(args) -> Optional[Dict]:
    """Checks the output folder ``args.out`` before any data is read and
    returns the checkpoint to resume (:obj:`None` for a new run): the rules
    of :mod:`tg_intrinsic.io.results` (no input in it, no files another
    command wrote unless ``args.overwrite``), and with ``args.resume`` a
    readable checkpoint of the same model, task and settings
    (:func:`check_resume`). A new run does not start over an earlier one
    unless ``args.overwrite``, which then deletes the earlier run's files.
    Records that ``train`` writes there (:func:`~tg_intrinsic.io.results.
    write_record`) and removes the temporary files of killed writes."""
    out = args.out
    inputs = [args.mesh_root] if getattr(args, 'mesh_root', None) else []
    check_output_path(out, inputs, '--out')
    for source in inputs:
        # a folder data set would read the run's files as data
        real = os.path.realpath(source)
        if os.path.realpath(out).startswith(real + os.sep):
            raise UsageError(f"--out '{out}' is inside the data set folder "
                             f"'{source}', which would read the run's "
                             f"files as data; give an --out outside it")
    path = os.path.join(out, CHECKPOINT)
    own = recorded_files(out, 'train')
    if own is None and os.path.isfile(path) and not os.path.exists(
            os.path.join(out, RECORD)):
        # a run of a version that kept no record: these are its files
        own = {name for name in OUTPUT_FILES
               if os.path.exists(os.path.join(out, name))}
    # left by a run killed while writing a checkpoint or metrics
    leftovers = [] if own is None else remove_temporaries(out)
    state = None
    if args.resume and os.path.exists(path):
        state = read_checkpoint(path)
        changes = check_resume(args, state, path)
        # the files beside the run's were allowed when it started
        claim_folder(out, 'train', args.overwrite or (
            own is not None and CHECKPOINT in own), inputs)
        if changes:
            print(f"resuming with changed settings: {', '.join(changes)}")
    else:
        earlier = sorted(name for name in own or ()
                         if os.path.isfile(os.path.join(out, name)))
        if earlier and not args.overwrite:
            raise UsageError(_earlier_run(out, earlier))
        claim_folder(out, 'train', args.overwrite, inputs)
        for name in earlier:  # the folder never mixes two runs
            os.remove(os.path.join(out, name))
        own = set()
        if args.resume:
            print(f"no checkpoint in {out}: starting a new run at epoch 1")
    if os.path.isdir(out):  # else made with the run's first file
        leftovers += remove_temporaries(out)
        write_record(out, 'train', own or ())
    if leftovers:
        print(f"removed {len(leftovers)} temporary file(s) of an "
              f"interrupted write from {out}: {', '.join(leftovers)}")
    return state


def _from_rank_zero(fn: Callable):
    """``fn()`` on rank 0 and its result on every process; a failure there
    fails every process (a user mistake as a :class:`UsageError`)."""
    if distributed.world_size() == 1:
        return fn()
    if distributed.rank() == 0:
        try:
            result = fn()
        except BaseException as error:
            distributed.broadcast_object(
                (False, f'{type(error).__name__}: {error}',
                 isinstance(error, ValueError), str(error)))
            raise
        distributed.broadcast_object((True, result))
        return result
    reply = distributed.broadcast_object(None)
    if reply[0]:
        return reply[1]
    if reply[2]:
        raise UsageError(reply[3])
    raise RuntimeError(f"rank 0 failed while checking --out: {reply[1]}")


def lone_shape_batches(model: str, batch_size: int, world: int = 1,
                       length: Optional[int] = None) -> Optional[str]:
    """Why ``model``'s batch norm over shapes (DeltaNet's head) cannot
    train on batches of ``batch_size`` (the global batch over ``world``
    processes) of a training set of ``length`` shapes, or :obj:`None`."""
    if model != 'deltanet':
        return None  # HSN normalises over vertices
    per_process = f" per process (the batch is split over {world})" \
        if world > 1 else ''
    need = ("DeltaNet's batch norm normalises over the shapes of a batch "
            f"and needs at least 2 shapes in every batch{per_process}")
    if batch_size // world < 2:
        return (f"--batch-size {batch_size}: {need}; use --batch-size "
                f"{2 * world} or more")
    # The epochs drop the remainder of the training set (see
    # distributed.global_batches), so no batch is smaller than the others
    # unless the whole set is smaller than one batch.
    if length is not None and 0 < length < batch_size and \
            length // world < 2:
        return (f"the training set has {length} shape(s), fewer than "
                f"--batch-size {batch_size}, so they make one batch; {need}:"
                f" add training shapes" +
                (" or use fewer processes" if world > 1 else ''))
    return None


def train(args) -> Dict:
    """Trains as :obj:`args` say (see the module docstring), on one
    process or, under ``torchrun``, on every process of the run."""
    device, started = distributed.start(args.backend, args.device)
    try:
        try:
            check_precision(args.precision, device)
        except ValueError as error:
            raise UsageError(str(error)) from None
        with ExitStack() as held:
            def claim():
                # rank 0 writes --out, so it alone holds its lock, for the
                # whole run: a second run into it stops at once
                check_output_path(args.out)
                held.enter_context(output_lock(args.out, '--out'))
                return claim_output(args)
            # before the data are prepared (minutes): rank 0 checks --out
            # and reads the checkpoint, which every process then gets (no
            # shared file system needed)
            state = _from_rank_zero(claim)
            return _train(args, device, state)
    finally:
        if started:
            distributed.stop()


def _train(args, device, state: Optional[Dict]) -> Dict:
    rank, world = distributed.rank(), distributed.world_size()
    main_process = rank == 0

    def say(text):
        if main_process:
            print(text)

    quiet = args.quiet or not main_process
    seed_everything(args.seed)
    # by default the cores this process shares with the others torchrun
    # started here: concurrent runs do not each take them all
    torch.set_num_threads(args.threads or default_threads())
    build = build_mesh_datasets if args.model == 'hsn' else build_point_sets
    if not main_process:   # no progress bars beside rank 0's
        args = argparse.Namespace(**{**vars(args), 'quiet': True})
    # rank 0 prepares (and caches) the inputs, the others then read them
    classes = None if state is None else state.get('num_classes')
    train_items, test_items, source = distributed.rank_zero_first(
        lambda: build(args, classes))
    num_classes = source.num_classes
    part_mask = getattr(source, 'part_mask', None)
    if args.train_per_class is not None and args.task == 'classification':
        labels = [int(item.y) for item in train_items]
        train_items = [train_items[i] for i in select_per_class(
            labels, args.train_per_class, args.data_seed)]
    train_set = _Mapped(train_items, augmentation(args), args.seed)
    if args.task == 'classification' or part_mask is not None:
        # per-shape features (DeltaNet's head, its category embedding)
        # pass through batch norm
        problem = lone_shape_batches(args.model, args.batch_size, world,
                                     len(train_set))
        if problem:
            raise UsageError(problem)
    # Seeded again: whether the inputs were prepared now or read from the
    # cache must not change what follows.
    seed_everything(args.seed)
    model = build_model(args.model, num_classes, args, None if part_mask
                        is None else part_mask.size(0))
    if args.sync_batch_norm and world > 1:
        from tg_intrinsic.nn import convert_sync_batch_norm
        model = convert_sync_batch_norm(model)
    model = model.to(device)
    if args.optimizer == 'sgd':
        optimizer = torch.optim.SGD(model.parameters(), lr=args.lr,
                                    momentum=0.9,
                                    weight_decay=args.weight_decay)
    else:
        optimizer = torch.optim.Adam(model.parameters(), lr=args.lr,
                                     weight_decay=args.weight_decay)
    if args.schedule == 'cosine':
        schedule = torch.optim.lr_scheduler.CosineAnnealingLR(
            optimizer, T_max=args.epochs, eta_min=args.lr_min)
    else:
        schedule = torch.optim.lr_scheduler.MultiStepLR(
            optimizer, milestones=args.milestones, gamma=args.gamma)
    checkpoint_path = os.path.join(args.out, CHECKPOINT)
    # the files this run wrote into --out, recorded before each is written
    written = (recorded_files(args.out, 'train') or set()) \
        if main_process else set()

    def mark_written(name):
        if name not in written:
            written.add(name)
            write_record(args.out, 'train', written)

    history: List[Dict] = []
    start_epoch = 1
    if state is not None:
        # Written by any number of processes: the batches and random draws
        # of an epoch depend on (seed, epoch) only, so the generators'
        # states that older versions saved ('rng') are not needed.
        try:
            model.load_state_dict(state['model'])
            optimizer.load_state_dict(state['optimizer'])
            schedule.load_state_dict(state['schedule'])
        except (RuntimeError, ValueError, KeyError) as error:
            # a checkpoint of an older version, which saved fewer settings
            # (and not the number of classes) than are checked now
            raise UsageError(f"'{checkpoint_path}' does not fit the model "
                             f"of these settings ({one_line(error)[:200]});"
                             f" resume it with the settings and data it was "
                             f"trained with, or start a new run with "
                             f"--overwrite (without --resume) or in another "
                             f"--out") from error
        history = state['history']
        start_epoch = state['epoch'] + 1
        say(f"resuming from epoch {state['epoch']} of {checkpoint_path}")
    net = model
    if world > 1:
        net = torch.nn.parallel.DistributedDataParallel(
            model, device_ids=None if device.type == 'cpu' else [device])
    if args.compile:  # shapes vary by batch: one graph for all of them
        net = torch.compile(net, dynamic=True)
    # float16 gradients underflow without scaling; a no-op otherwise
    scaler = torch.amp.GradScaler(device.type,
                                  enabled=args.precision == '16-mixed')
    # the test set: a contiguous part on every process, scores summed
    test_loader = DataLoader(
        [test_items[i] for i in distributed.shard(
            range(len(test_items)), rank, world)], args.batch_size)
    # batch statistics of shuffled test batches (the test set is often
    # sorted by class); recalibration on the training items without
    # augmentation, in training batches (the same count on every process)
    shuffled = distributed.shard(np.random.default_rng(
        distributed.derived_seed(args.seed, 0, 1)).permutation(
            len(test_items)), rank, world)
    shuffled_test_loader = None if len(test_items) // world < 2 else \
        DataLoader([test_items[i] for i in shuffled],
                   batch_sampler=whole_batches(len(shuffled),
                                               args.batch_size))
    recalibration = distributed.epoch_batches(
        len(train_set), args.batch_size, args.seed, 0, rank,
        world)[:RECALIBRATION_BATCHES]
    has_batch_norm = bool(batch_norms(model))
    num_params = sum(p.numel() for p in model.parameters())
    say(f"{args.model} ({num_params / 1e6:.2f}M parameters), protocol "
        f"{args.protocol}, on {args.dataset}: {len(train_set)} train / "
        f"{len(test_items)} test, {num_classes} classes, {device}"
        + (f", {world} processes" if world > 1 else ''))
    started = time.perf_counter()
    for epoch in range(start_epoch, args.epochs + 1):
        # Everything random in an epoch derives from (seed, epoch): the
        # batches, each item's augmentation (seeded by its index too) and
        # dropout (seeded by the rank too).
        seed_everything(distributed.derived_seed(args.seed, epoch, rank))
        train_set.epoch = epoch
        train_loader = DataLoader(train_set, batch_sampler=(
            distributed.epoch_batches(len(train_set), args.batch_size,
                                      args.seed, epoch, rank, world)))
        net.train()
        totals = torch.zeros(3, dtype=torch.float64, device=device)
        # closed (and cleared) before an error propagates, so that the
        # error is printed on a line of its own
        with tqdm(train_loader, desc=f'epoch {epoch}/{args.epochs}',
                  leave=False, disable=quiet) as bar:
            for batch in bar:
                batch = batch.to(device)
                optimizer.zero_grad()
                with autocast(args.precision, device):
                    out = net(batch)
                target = batch.y.view(-1)
                loss_sum = F.cross_entropy(
                    out.float(), target, reduction='sum',
                    label_smoothing=args.label_smoothing)
                # [count, loss sum, correct] of the global batch
                step = distributed.all_reduce_sum(torch.stack([
                    torch.tensor(float(target.numel()), dtype=torch.float64,
                                 device=device),
                    loss_sum.detach().double(),
                    (out.argmax(-1) == target).sum().double()]))
                if not torch.isfinite(step[1]):
                    # the settings diverge: the user's to change
                    raise UsageError(f"the training loss became "
                                     f"{float(step[1])} in epoch {epoch}; "
                                     f"lower --lr (the checkpoint of the "
                                     f"last evaluation is kept)")
                # the mean over the global batch: DDP averages the
                # gradients over the processes, so each one scales its sum
                # by world / n
                scaler.scale(loss_sum * (world / float(step[0]))).backward()
                scaler.step(optimizer)
                scaler.update()
                totals += step
                bar.set_postfix(loss=f'{float(totals[1] / totals[0]):.3f}')
        schedule.step()
        seen = max(float(totals[0]), 1.0)
        record = {'epoch': epoch, 'train_loss': float(totals[1]) / seen,
                  'train_accuracy': float(totals[2]) / seen,
                  'test_accuracy': None,
                  'seconds': time.perf_counter() - started}
        if epoch % args.eval_every == 0 or epoch == args.epochs:
            if has_batch_norm:
                # the running statistics of the current weights, so that
                # eval-mode inference scores what training does
                recalibrate_batch_norm(model, DataLoader(
                    train_set.items, batch_sampler=recalibration), device)
            # equal on every process after the recalibration; rank 0's
            # otherwise (per-process batch norm), as saved
            distributed.broadcast_buffers(model)
            scores = evaluate(model, test_loader, device, part_mask,
                              precision=args.precision)
            record['test_accuracy'] = scores['accuracy']
            if 'miou' in scores:
                record['test_miou'] = scores['miou']
            # with batch statistics (per shape at batch size 1): the same
            # by construction without batch norms
            if not has_batch_norm:
                record['test_accuracy_batch_statistics'] = \
                    scores['accuracy']
            elif shuffled_test_loader is not None:
                record['test_accuracy_batch_statistics'] = evaluate(
                    model, shuffled_test_loader, device, part_mask,
                    statistics='batch', precision=args.precision)['accuracy']
        history.append(record)
        if not main_process:
            continue
        mark_written('metrics.csv')
        write_metrics_csv(history, os.path.join(args.out, 'metrics.csv'))
        if record['test_accuracy'] is not None:
            say(f"epoch {epoch}: loss {record['train_loss']:.3f}, "
                f"train {record['train_accuracy']:.3f}, "
                f"test {record['test_accuracy']:.3f}"
                + statistics_gap(record))
            mark_written(CHECKPOINT)
            atomic_torch_save({'model': model.state_dict(),
                               'optimizer': optimizer.state_dict(),
                               'schedule': schedule.state_dict(),
                               'history': history, 'epoch': epoch,
                               'world_size': world,
                               'num_classes': num_classes,
                               'args': vars(args)}, checkpoint_path)
            mark_written('learning_curve.png')
            plot_history(history, os.path.join(args.out,
                                               'learning_curve.png'),
                         f'{args.model} on {args.dataset}')
    final = history[-1]['test_accuracy'] if history else None
    metrics = {'model': args.model, 'dataset': args.dataset,
               'final_test_accuracy_batch_statistics': history[-1].get(
                   'test_accuracy_batch_statistics') if history else None,
               'final_test_miou': history[-1].get('test_miou') if history
               else None,
               'protocol': args.protocol, 'parameters': num_params,
               'train_shapes': len(train_set), 'test_shapes': len(test_items),
               'final_test_accuracy': final,
               'best_test_accuracy': max(
                   (h['test_accuracy'] for h in history
                    if h['test_accuracy'] is not None), default=None),
               'world_size': world,
               'history': history, 'args': vars(args)}
    if main_process:
        mark_written('metrics.json')
        atomic_write_json(os.path.join(args.out, 'metrics.json'), metrics)
        say(f"final test accuracy: {final:.3f} (written to {args.out})")
    return metrics


class _Mapped(torch.utils.data.Dataset):
    """A list of examples with a random transform applied on access, its
    draws seeded by (seed, :attr:`epoch`, index): the same on any process
    and after any history. The global generators are left as they were."""
    def __init__(self, items, transform, seed: int):
        self.items, self.transform, self.seed = items, transform, seed
        self.epoch = 0

    def __len__(self):
        return len(self.items)

    def __getitem__(self, index):
        if self.transform is None:
            return self.items[index]
        saved = np.random.get_state(), random.getstate()
        with torch.random.fork_rng(devices=[]):
            seed_everything(distributed.derived_seed(self.seed, self.epoch,
                                                     index))
            try:
                return self.transform(self.items[index])
            finally:
                np.random.set_state(saved[0])
                random.setstate(saved[1])


def add_arguments(parser, model_and_dataset: bool = True):
    """The training options, shared by ``python -m tg_intrinsic.train``
    and ``tg-intrinsic train`` (which names the model and data set its own
    way: ``model_and_dataset=False``). Options marked "protocol" default
    to the protocol's value."""
    if model_and_dataset:
        parser.add_argument('--model', default=None, choices=MODELS,
                            help="default: the protocol's, else deltanet")
        parser.add_argument('--dataset', default=None, choices=DATASETS,
                            help='default: synthetic_modelnet for deltanet, '
                            'synthetic_shrec for hsn')
        parser.add_argument('--mesh-root', default=None,
                            help='root/<class>/<split>/*.off|obj|ply for '
                            'mesh_folder')
    add = parser.add_argument
    add('--protocol', default=None, choices=list(PROTOCOLS),
        help='the paper protocol whose values fill every option left out '
        '(default: deltanet-modelnet40, deltanet-shapenet-part, hsn-shrec11 '
        'or hsn-human-seg by model and task)')
    add('--task', default=None, choices=TASKS,
        help='protocol; segmentation: per-point (DeltaNet) or per-vertex '
        '(HSN) labels')
    add('--root', default='data',
        help='cache folder of the synthetic data sets and prepared inputs')
    add('--out', default=None,
        help='output folder (default: runs/<model>_<dataset>); a new run '
        'does not start over an earlier one there, nor beside files train '
        'did not write, unless --overwrite')
    add('--overwrite', action='store_true',
        help='start a new run in --out over an earlier one (deleting its '
        'checkpoint and metrics first), and write beside files train did '
        'not write (they are kept); with --resume and a checkpoint there, '
        'the run continues')
    add('--force-reload', action='store_true',
        help='re-read the files of a folder data set')
    add('--num-points', type=int, default=None,
        help='protocol; DeltaNet: points sampled per shape')
    add('--shapes-per-class', type=int, default=None,
        help='shrink the synthetic sets (quick runs)')
    add('--train-per-class', type=int, default=None,
        help='protocol; train on this many shapes of every class, drawn '
        'with --data-seed (classification)')
    add('--epochs', type=int, default=None, help='protocol')
    add('--batch-size', type=int, default=None,
        help='protocol; the global batch: under torchrun each of the N '
        'processes takes 1/N of it (a multiple of N)')
    add('--optimizer', default=None, choices=['adam', 'sgd'],
        help='protocol; sgd uses momentum 0.9')
    add('--lr', type=float, default=None, help='protocol')
    add('--schedule', default=None, choices=['cosine', 'step'],
        help='protocol; cosine to --lr-min, or step: times --gamma at '
        'every --milestones epoch')
    add('--lr-min', type=float, default=None, help='protocol')
    add('--milestones', type=int, nargs='*', default=None, help='protocol')
    add('--gamma', type=float, default=None, help='protocol')
    add('--weight-decay', type=float, default=None, help='protocol')
    add('--label-smoothing', type=float, default=None, help='protocol')
    add('--eval-every', type=int, default=5)
    add('--rotate', default=None, nargs='?', const='so3', choices=ROTATIONS,
        help='protocol; random rotations: so3 (uniform; the value of a bare '
        '--rotate), about one axis, or about x, y, z in turn (xyz)')
    add('--max-angle', type=float, default=None,
        help='protocol; largest angle about an axis, degrees')
    add('--scale', type=float, nargs=2, default=None, metavar=('LOW', 'HIGH'),
        help='protocol; random scale factors (1 1: none)')
    add('--anisotropic', default=None, action=argparse.BooleanOptionalAction,
        help='protocol; one scale factor per axis')
    add('--translate', type=float, default=None,
        help='protocol; largest random offset of the whole shape')
    add('--conv-channels', type=int, nargs='+', default=None,
        help='protocol; DeltaConv widths')
    add('--mlp-depth', type=int, default=None,
        help='protocol; DeltaConv MLP depth')
    add('--embedding-size', type=int, default=None, help='protocol')
    add('--k', type=int, default=None, help='protocol; DeltaNet neighbours')
    add('--regularizer', type=float, default=None,
        help='protocol; DeltaNet MLS regulariser lambda')
    add('--no-vector-stream', action='store_true',
        help='ablation: drop the vector stream')
    add('--hsn-channels', type=int, nargs=2, default=None,
        help='protocol; hsn features on levels 0, 1')
    add('--max-order', type=int, default=None,
        help='protocol; hsn: highest rotation order (0: one stream)')
    add('--rings', type=int, default=None, help='protocol')
    add('--hsn-norm', default=DEFAULT_COMPLEX_NORM,
        choices=[norm or 'none' for norm in COMPLEX_NORMS],
        help='hsn: normalisation in the blocks; instance (statistics per '
        'mesh, the same in training and evaluation), batch (running '
        'statistics in evaluation; with one mesh per batch they fit no '
        f'mesh) or none (default: {DEFAULT_COMPLEX_NORM})')
    add('--radius', type=float, default=None,
        help='protocol; hsn: disc radius on unit-area meshes')
    add('--resample-vertices', type=int, default=None,
        help='protocol; hsn: farthest-point resample meshes to this many '
        'vertices (0: keep them all)')
    add('--num-vertices', type=int, nargs=2, default=None,
        metavar=('LOW', 'HIGH'),
        help='hsn on synthetic_shrec: vertex range of the generated meshes '
        '(default 500 2000)')
    add('--logmap-method', default='fast', choices=['fast', 'vector_heat'])
    add('--seed', type=int, default=0)
    add('--data-seed', type=int, default=0,
        help='seeds the synthetic data, the point sampling and the '
        'per-class training split')
    add('--device', default='auto',
        help='auto (cuda when PyTorch finds a GPU, else cpu), cpu, cuda, '
        'cuda:N or mps (default: auto)')
    add('--threads', type=int, default=0)
    add('--compile', action='store_true',
        help='train with torch.compile(dynamic=True): the same results '
        'within float rounding, faster once compiled (the first batches '
        'compile)')
    add('--precision', default='32-true', choices=PRECISIONS,
        help='32-true (float32), bf16-mixed (autocast to bfloat16) or '
        '16-mixed (float16 with gradient scaling, CUDA only); sparse and '
        'complex maths stay float32 (default: 32-true)')
    add('--resume', action='store_true',
        help='continue from the checkpoint in --out (written by any number '
        'of processes) with the settings it was trained with, checked '
        'before the data are prepared; without a checkpoint there, start '
        'a new run at epoch 1')
    add('--allow-changes', default='', metavar='NAMES',
        help='with --resume: let these settings differ from the '
        "checkpoint's, comma-separated: epochs, eval-every, "
        'sync-batch-norm, dataset (a moved folder); a cosine schedule '
        "keeps the checkpoint's length. --quiet, --workers, --threads, "
        '--device, --backend, --on-disk, --root may always differ')
    add('--dropout', type=float, default=None,
        help="DeltaNet: dropout of the head (default: the model's, 0.5)")
    add('--backend', default='auto', choices=list(distributed.BACKENDS),
        help='under torchrun: the torch.distributed backend (auto: nccl on '
        'CUDA, gloo on the CPU)')
    add('--sync-batch-norm', action='store_true',
        help='under torchrun: batch norm statistics over the global batch '
        '(all processes); default: per process, as DDP does, which is '
        'faster but differs from one process with the same batch')
    if model_and_dataset:
        add('--quiet', action='store_true', help='no progress bar')
    add('--workers', type=int, default=1,
        help='processes that prepare the inputs (operators, log maps), one '
        'thread each; the inputs do not depend on it (default: 1)')
    add('--on-disk', action='store_true',
        help='keep the prepared inputs in an on-disk database '
        '(PrecomputedOnDisk under --root) and train from it, so memory '
        'stays bounded as the data set grows; same results as in memory')


def check_arguments(args, parser):
    """Fills the protocol's values and the default output folder, and
    rejects values and combinations no run can use (through
    ``parser.error``: one line, exit code 2) before any data is read."""
    try:
        resolve_protocol(args)
    except ValueError as error:
        parser.error(str(error))
    if args.dataset is None:
        args.dataset = DEFAULT_DATASET[args.model]
    supported = SUPPORTED[(args.model, args.task)]
    if args.dataset not in supported:
        combos = '; '.join(f"{m} {t}: {', '.join(d)}"
                           for (m, t), d in SUPPORTED.items())
        parser.error(f"{args.model} {args.task} cannot train on "
                     f"{args.dataset}; supported: {combos}")
    if args.out is None:
        args.out = os.path.join('runs', f'{args.model}_{args.dataset}')
    for name, value in (('mesh_root', None), ('overwrite', False),
                        ('allow_changes', '')):
        if not hasattr(args, name):  # arguments built by hand
            setattr(args, name, value)
    try:
        args.allow_changes = allowed_changes(args.allow_changes) \
            if isinstance(args.allow_changes, str) else \
            list(args.allow_changes)
        check_device(args.device, '--device')
    except ValueError as error:
        parser.error(str(error))
    if args.allow_changes and not args.resume:
        parser.error("--allow-changes applies when resuming; add --resume")
    for name in ('num_points', 'epochs', 'batch_size', 'eval_every', 'k',
                 'rings', 'mlp_depth', 'embedding_size'):
        if getattr(args, name) < 1:
            parser.error(f"--{name.replace('_', '-')} must be at least 1, "
                         f"got {getattr(args, name)}")
    for name in ('lr', 'radius', 'regularizer', 'gamma', 'max_angle'):
        if not getattr(args, name) > 0:
            parser.error(f"--{name.replace('_', '-')} must be positive, got "
                         f"{getattr(args, name)}")
    for name in ('weight_decay', 'label_smoothing', 'max_order', 'threads',
                 'translate', 'lr_min'):
        if getattr(args, name) < 0:
            parser.error(f"--{name.replace('_', '-')} must not be negative, "
                         f"got {getattr(args, name)}")
    if args.dropout is not None and not 0 <= args.dropout < 1:
        parser.error(f"--dropout must be in [0, 1), got {args.dropout}")
    try:
        world = distributed.launched_world_size()
    except ValueError as error:
        parser.error(str(error))
    if args.batch_size % world:
        parser.error(f"--batch-size {args.batch_size} is the global batch, "
                     f"split evenly over the {world} processes: make it a "
                     f"multiple of {world}")
    if args.task == 'classification' or args.dataset == 'synthetic_parts':
        # batch norm over per-shape features (with the part categories)
        problem = lone_shape_batches(args.model, args.batch_size, world)
        if problem:
            parser.error(problem)
    if args.resample_vertices == 0:
        args.resample_vertices = None
    for name in ('shapes_per_class', 'train_per_class', 'resample_vertices'):
        value = getattr(args, name)
        if value is not None and value < 1:
            parser.error(f"--{name.replace('_', '-')} must be at least 1, "
                         f"got {value}")
    if args.scale is not None and not 0 < args.scale[0] <= args.scale[1]:
        parser.error(f"--scale needs 0 < LOW <= HIGH, got {args.scale}")
    if args.scale is not None and list(args.scale) == [1.0, 1.0]:
        args.scale = None
    if args.max_angle > 180:
        parser.error(f"--max-angle must be at most 180, got {args.max_angle}")
    if min(args.conv_channels + args.hsn_channels) < 1:
        parser.error("channel counts must be at least 1")
    if args.workers < 1:
        parser.error(f"--workers must be at least 1, got {args.workers}")
    return args


def parse_args(argv=None):
    """The options of ``python -m tg_intrinsic.train`` (:func:`add_arguments`)
    parsed from ``argv`` (default: the command line)."""
    parser = argparse.ArgumentParser(
        description='Train DeltaNet or a Harmonic Surface Network.')
    add_arguments(parser)
    return check_arguments(parser.parse_args(argv), parser)


def main(argv=None):
    """``python -m tg_intrinsic.train``: :func:`train` with the options of
    :func:`parse_args`; returns its metrics."""
    return train(parse_args(argv))


if __name__ == '__main__':
    main()
