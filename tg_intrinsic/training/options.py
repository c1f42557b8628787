"""``train``'s options: the parser, the checks that run before any data is
read, and the entry point."""
import argparse
import os
from typing import Dict, List, Optional

from tg_intrinsic import distributed
from tg_intrinsic.devices import PRECISIONS, check_device
from tg_intrinsic.nn.harmonic_resnet_block import (COMPLEX_NORMS,
                                                   DEFAULT_COMPLEX_NORM)
from tg_intrinsic.protocols import PROTOCOLS
from tg_intrinsic.training.checkpoints import allowed_changes
from tg_intrinsic.training.loop import lone_shape_batches, train
from tg_intrinsic.training.sources import (DATASETS, DEFAULT_DATASET, MODELS,
                                           ROTATIONS, SUPPORTED, TASKS,
                                           resolve_protocol)


def protocol_defaults(field: str, model: Optional[str] = None) -> str:
    """What an option left out takes from ``--protocol``: its value in each
    protocol (those of ``model`` only, for a model's own options), equal
    values grouped, as ``train --help`` prints it."""
    def shown(value):
        if value is None or value == ():
            return 'none'
        if isinstance(value, bool):
            return 'on' if value else 'off'
        if isinstance(value, tuple):
            return ' '.join(shown(v) for v in value)
        return f'{value:g}' if isinstance(value, float) else str(value)
    groups: Dict[str, List[str]] = {}
    for name, protocol in PROTOCOLS.items():
        if model is None or protocol.model == model:
            groups.setdefault(shown(getattr(protocol, field)), []).append(name)
    if len(groups) == 1:
        return f'default from --protocol: {next(iter(groups))} in every one'
    return 'default from --protocol: ' + ', '.join(
        f"{value} ({', '.join(names)})" for value, names in groups.items())


def _protocol_option(add):
    """``add`` for an option whose default is the protocol's: its help ends
    with the value of every protocol (:func:`protocol_defaults`)."""
    def add_protocol_option(flag, help, model=None, **kwargs):
        field = flag.lstrip('-').replace('-', '_')
        add(flag, default=None,
            help=f'{help}; {protocol_defaults(field, model)}', **kwargs)
    return add_protocol_option


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
    _data_options(add)
    _optimisation_options(add)
    _augmentation_options(add)
    _model_options(add)
    _run_options(add, model_and_dataset)


def _data_options(add):
    """Options: the data, the cache and the output folder."""
    add('--protocol', default=None, choices=list(PROTOCOLS),
        help='the paper protocol whose values fill every option left out '
        '(default: deltanet-modelnet40, deltanet-shapenet-part, hsn-shrec11 '
        'or hsn-human-seg by model and task)')
    protocol = _protocol_option(add)
    protocol('--task', choices=TASKS,
             help='classification (one label per shape) or segmentation '
             '(per-point labels for DeltaNet, per-vertex for HSN)')
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
    protocol('--num-points', type=int, model='deltanet',
             help='DeltaNet: points sampled per shape')
    add('--shapes-per-class', type=int, default=None,
        help='shrink the synthetic sets (quick runs)')
    protocol('--train-per-class', type=int,
             help='train on this many shapes of every class, drawn with '
             '--data-seed (classification; none: all of them)')


def _optimisation_options(add):
    """Options: epochs, batches, the optimiser and its schedule."""
    protocol = _protocol_option(add)
    protocol('--epochs', type=int, help='epochs to train')
    protocol('--batch-size', type=int,
             help='the global batch: under torchrun each of the N '
             'processes takes 1/N of it (a multiple of N)')
    protocol('--optimizer', choices=['adam', 'sgd'],
             help='adam, or sgd with momentum 0.9')
    protocol('--lr', type=float, help='the learning rate at the start')
    protocol('--schedule', choices=['cosine', 'step'],
             help='cosine to --lr-min, or step: times --gamma at every '
             '--milestones epoch')
    protocol('--lr-min', type=float,
             help='the learning rate the cosine schedule ends at')
    protocol('--milestones', type=int, nargs='*',
             help='epochs at which the step schedule multiplies the '
             'learning rate by --gamma')
    protocol('--gamma', type=float,
             help="the step schedule's factor at each milestone")
    protocol('--weight-decay', type=float,
             help="the optimiser's weight decay")
    protocol('--label-smoothing', type=float,
             help='label smoothing of the cross-entropy loss')
    add('--eval-every', type=int, default=5,
        help='evaluate on the test set every N epochs, and after the last '
        '(default: %(default)s)')


def _augmentation_options(add):
    """Options: random rotations, scales and offsets."""
    protocol = _protocol_option(add)
    protocol('--rotate', nargs='?', const='so3', choices=ROTATIONS,
             help='random rotations: so3 (uniform; the value of a bare '
             '--rotate), about one axis, or about x, y, z in turn (xyz)')
    protocol('--max-angle', type=float,
             help='largest angle about an axis, degrees')
    protocol('--scale', type=float, nargs=2, metavar=('LOW', 'HIGH'),
             help='random scale factors (1 1: none)')
    protocol('--anisotropic', action=argparse.BooleanOptionalAction,
             help='one scale factor per axis')
    protocol('--translate', type=float,
             help='largest random offset of the whole shape')


def _model_options(add):
    """Options: the models' widths, orders, rings and discs."""
    protocol = _protocol_option(add)
    protocol('--conv-channels', type=int, nargs='+', model='deltanet',
             help='DeltaNet: the widths of its DeltaConv layers')
    protocol('--mlp-depth', type=int, model='deltanet',
             help="DeltaNet: the depth of each DeltaConv's MLPs")
    protocol('--embedding-size', type=int, model='deltanet',
             help='DeltaNet: the width of the global embedding')
    protocol('--k', type=int, model='deltanet',
             help='DeltaNet: neighbours of each point')
    protocol('--regularizer', type=float, model='deltanet',
             help="DeltaNet: the MLS operators' regulariser lambda")
    add('--no-vector-stream', action='store_true',
        help='ablation: drop the vector stream')
    protocol('--hsn-channels', type=int, nargs=2, model='hsn',
             help='HSN: features on levels 0 and 1')
    protocol('--max-order', type=int, model='hsn',
             help='HSN: highest rotation order (0: one stream)')
    protocol('--rings', type=int, model='hsn',
             help="HSN: radial rings of each kernel's disc")
    add('--hsn-norm', default=DEFAULT_COMPLEX_NORM,
        choices=[norm or 'none' for norm in COMPLEX_NORMS],
        help='hsn: normalisation in the blocks; instance (statistics per '
        'mesh, the same in training and evaluation), batch (running '
        'statistics in evaluation; with one mesh per batch they fit no '
        f'mesh) or none (default: {DEFAULT_COMPLEX_NORM})')
    protocol('--radius', type=float, model='hsn',
             help='HSN: disc radius on unit-area meshes')
    protocol('--resample-vertices', type=int, model='hsn',
             help='HSN: farthest-point resample meshes to this many '
             'vertices (0 or none: keep them all)')
    add('--num-vertices', type=int, nargs=2, default=None,
        metavar=('LOW', 'HIGH'),
        help='hsn on synthetic_shrec: vertex range of the generated meshes '
        '(default 500 2000)')
    add('--logmap-method', default='fast', choices=['fast', 'vector_heat'],
        help="HSN: how the log maps are computed; fast (the library's "
        "own) or vector_heat (geometry-central's vector heat method, "
        "needs potpourri3d) (default: %(default)s)")


def _run_options(add, model_and_dataset: bool):
    """Options: seeds, devices, precision, resuming, processes."""
    add('--seed', type=int, default=0,
        help='seeds the weights, the augmentation and the batch order '
        '(default: %(default)s)')
    add('--data-seed', type=int, default=0,
        help='seeds the synthetic data, the point sampling and the '
        'per-class training split')
    add('--device', default='auto',
        help='auto (cuda when PyTorch finds a GPU, else cpu), cpu, cuda, '
        'cuda:N or mps (default: auto)')
    add('--threads', type=int, default=0,
        help="torch's CPU threads; 0: the cores this process may use, "
        'shared among the processes torchrun starts on this machine '
        '(default: %(default)s)')
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
