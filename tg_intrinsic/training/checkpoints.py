"""Checkpoints: reading one, and checking that a resumed run may continue
it with the settings given."""
import os
from typing import Dict, List

import torch

from tg_intrinsic import distributed
from tg_intrinsic.errors import UsageError


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
