"""Where the data come from: the data sets and models ``train`` knows, the
protocol that fills the options left out, the train/test sources and the
per-class training split."""
import os
from typing import List

import numpy as np

from tg_intrinsic.errors import UsageError
from tg_intrinsic.protocols import DEFAULT_PROTOCOL, get_protocol


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
