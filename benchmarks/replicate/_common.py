"""What every replication script shares: the command line, the check of the
data folder, the loop over repeats (one :func:`tg_intrinsic.train.main`
run each), the summary table, and the JSON and PNG written to ``--out``.

A row script names a :class:`Row` (its protocol, the reader its data
layout opens with, the layout in one line, its smoke data writer and what
it does differently from the paper) and calls :func:`main`::

    python benchmarks/replicate/<row>.py PATH [--out DIR] [--repeats N]
        [--epochs N] [--smoke] [-- EXTRA TRAIN FLAGS]

Repeat ``r`` (0, 1, ...) runs ``tg_intrinsic.train.main`` with
``--protocol <row> --dataset mesh_folder --mesh-root PATH --data-seed r
--seed r --out OUT/run_<r> --root OUT/cache --quiet``, so it draws its own
training split when the protocol trains on so many shapes per class.
Every other option is the protocol's, unless given after ``--`` (e.g.
``-- --eval-every 1 --device cuda``; ``-- --resume`` continues interrupted
repeats from their checkpoints).

Writes ``OUT/<row>.json`` (the protocol, every repeat's metrics and
settings, the summary, the machine; rewritten after every repeat) and
``OUT/<row>.png`` (every repeat's test metric and training loss against
the epoch). A missing PATH or one in another layout is one line on stderr
and exit code 2.
"""
import argparse
import os
import os.path as osp
import shutil
import sys
import time
from dataclasses import dataclass, field
from typing import Callable, Dict, List, Optional, Sequence, Tuple

import numpy as np

# Markers by which tg_intrinsic.datasets.open_folder tells the layouts of
# the releases apart (file or folder names in PATH itself). Checked before
# anything is read, so that a folder of the wrong data set is refused at
# once instead of being read (and cached) first.
MARKERS = {
    'ModelNetResampled': ('modelnet40_shape_names.txt',
                          'modelnet10_shape_names.txt'),
    'ShapeNetPartNormal': ('synsetoffset2category.txt', ),
    'ScanObjectNN': ('h5_files', 'main_split', 'main_split_nobg'),
}
# Options a row script sets itself: not to be given after '--'.
RESERVED = ('--protocol', '--model', '--dataset', '--mesh-root', '--out',
            '--root', '--seed', '--data-seed', '--task', '--epochs')
# Smoke runs: small sizes, one epoch; everything else stays the protocol's.
SMOKE_FLAGS = {
    'deltanet': ['--num-points', '64', '--k', '8', '--conv-channels', '8',
                 '8', '--embedding-size', '32', '--batch-size', '4'],
    'hsn': ['--hsn-channels', '4', '8', '--rings', '3', '--batch-size', '2',
            '--radius', '0.3'],
}
SMOKE_EPOCHS = 1
# Largest difference (points) between eval-mode and batch-statistics test
# accuracy before a replication warns.
GAP_POINTS = 2.0
SMOKE_REPEATS = 2
SMOKE_TRAIN_PER_CLASS = 2       # of the 3 training shapes per class
SMOKE_RESAMPLE_VERTICES = 60    # of the ~150 vertices per mesh


# Layouts and deviations shared by several rows (one owner each).
SHREC16_LAYOUT = ("MeshCNN's shrec_16/<class>/{train,test}/T<id>.obj "
                  "(shrec_16.tar.gz)")
HUMAN_SEG_LAYOUT = ("MeshCNN's human_seg/{train,test}/*.obj with seg/*.eseg "
                    "(and sseg/*.seseg) (human_seg.tar.gz)")
HUMAN_SEG_COPY = ("the paper used HSN's repackaging of Maron et al. "
                  "(shapeseg.zip, per-vertex labels); this reads MeshCNN's "
                  "remeshed copy (human_seg, per-edge labels voted to "
                  "vertices), so the numbers are not directly comparable")
EUCLIDEAN_FPS = ('points: 8x as many area samples, then Euclidean farthest '
                 'point sampling (the paper: geodesic farthest point '
                 'sampling)')
FAST_LOG_MAPS = ("log maps and transport by tg_intrinsic's 'fast' method "
                 "(the paper: the Vector Heat Method; pass -- "
                 "--logmap-method vector_heat for it)")


@dataclass(frozen=True)
class Row:
    """One paper table row: the protocol (a key of
    :data:`tg_intrinsic.protocols.PROTOCOLS`), the reader that
    :func:`~tg_intrinsic.datasets.open_folder` must pick for its data
    folder, that folder's layout in one line, the writer of its smoke data
    (``writer(parent) -> data folder``) and what the run does differently
    from the paper (printed and recorded)."""
    protocol: str
    reader: str
    layout: str
    smoke_data: Callable[[str], str]
    notes: Tuple[str, ...] = field(default=())

    @property
    def name(self) -> str:
        return self.protocol


def _parser(row: Row, doc: Optional[str]) -> argparse.ArgumentParser:
    parser = argparse.ArgumentParser(
        prog=row.name.replace('-', '_') + '.py',
        description=' '.join((doc or '').strip().split('\n\n')[0].split()),
        epilog=f"PATH: {row.layout}. Flags after '--' go to "
        f"tg_intrinsic.train (except {', '.join(RESERVED)}).")
    parser.add_argument('path', nargs='?', metavar='PATH',
                        help='your local copy of the data set (nothing is '
                        'downloaded); not needed with --smoke')
    parser.add_argument('--out', default=None,
                        help=f'output folder (default: runs/replicate/'
                        f'{row.name})')
    parser.add_argument('--repeats', type=int, default=None,
                        help="runs with seeds 0..N-1 (default: the "
                        f"protocol's; {SMOKE_REPEATS} with --smoke)")
    parser.add_argument('--epochs', type=int, default=None,
                        help="epochs per run (default: the protocol's; "
                        f"{SMOKE_EPOCHS} with --smoke)")
    parser.add_argument('--smoke', action='store_true',
                        help='write a tiny data set in the same format to '
                        'OUT/smoke_data and run the protocol on it with '
                        'small sizes (seconds)')
    return parser


def split_argv(argv: Sequence[str]) -> Tuple[List[str], List[str]]:
    """The script's own arguments and the training flags after ``--``."""
    argv = list(argv)
    if '--' in argv:
        at = argv.index('--')
        return argv[:at], argv[at + 1:]
    return argv, []


def smoke_flags(protocol) -> List[str]:
    """The small sizes of a smoke run of :obj:`protocol`."""
    flags = list(SMOKE_FLAGS[protocol.model])
    if protocol.train_per_class is not None:
        flags += ['--train-per-class', str(SMOKE_TRAIN_PER_CLASS)]
    if protocol.resample_vertices is not None:
        flags += ['--resample-vertices', str(SMOKE_RESAMPLE_VERTICES)]
    return flags


def check_layout(path: str, row: Row, task: str) -> str:
    """Raises a :class:`ValueError` naming the expected layout unless
    :obj:`path` is a folder that ``open_folder`` opens with
    :obj:`row.reader`; returns the path with ``~`` expanded."""
    from tg_intrinsic.datasets import open_folder
    path = osp.expanduser(path)
    if not osp.isdir(path):
        raise ValueError(f"'{path}' is not a folder; expected {row.layout}")
    names = set(os.listdir(path))
    found = [reader for reader, marks in MARKERS.items()
             if names & set(marks)]
    wanted = MARKERS.get(row.reader)
    other = [reader for reader in found if reader != row.reader]
    if other:
        marks = sorted(names & set(MARKERS[other[0]]))
        raise ValueError(f"'{path}' is in the {other[0]} layout (it has "
                         f"{', '.join(marks)}); expected {row.layout}")
    if wanted and not found:
        raise ValueError(f"'{path}' has no {' or '.join(wanted)}; "
                         f"expected {row.layout}")
    try:
        dataset = open_folder(path, 'train', task=task)
    except ValueError as error:
        raise ValueError(f"{error} (this row expects {row.layout})") \
            from error
    if type(dataset).__name__ != row.reader:
        raise ValueError(f"'{path}' is read as {type(dataset).__name__}, "
                         f"not {row.reader}; expected {row.layout}")
    return path


def metric_keys(protocol) -> Tuple[str, str]:
    """The history key and the final key of the protocol's metric."""
    if 'miou' in protocol.metric.lower():
        return 'test_miou', 'final_test_miou'
    return 'test_accuracy', 'final_test_accuracy'


def summarize(protocol, runs: List[Dict], seconds: float,
              smoke: bool) -> Dict:
    """Mean and sample standard deviation (in %) of the final metric over
    the repeats, with the sizes of the runs."""
    _, final = metric_keys(protocol)
    values = [100.0 * run[final] for run in runs]
    # eval-mode accuracy (what inference on the checkpoint gives) against
    # the same weights with batch statistics (per shape at batch size 1)
    pairs = [(100.0 * run['final_test_accuracy'],
              100.0 * run['final_test_accuracy_batch_statistics'])
             for run in runs
             if run.get('final_test_accuracy_batch_statistics') is not None]
    return {
        'eval_accuracy': float(np.mean([a for a, _ in pairs]))
        if pairs else None,
        'batch_statistics_accuracy': float(np.mean([b for _, b in pairs]))
        if pairs else None,
        'largest_statistics_gap': max((abs(a - b) for a, b in pairs),
                                      default=None),
        'row': protocol.name, 'metric': protocol.metric,
        'reported': protocol.reported,
        'mean': float(np.mean(values)) if values else None,
        'std': float(np.std(values, ddof=1)) if len(values) > 1 else 0.0,
        'std_ddof': 1, 'values': values, 'unit': '%',
        'repeats': len(runs),
        'epochs': runs[0]['settings']['epochs'] if runs else None,
        'train_shapes': sorted({run['train_shapes'] for run in runs}),
        'test_shapes': sorted({run['test_shapes'] for run in runs}),
        'minutes': seconds / 60, 'smoke': smoke,
    }


def statistics_warning(summary: Dict, points: float = GAP_POINTS
                       ) -> Optional[str]:
    """A warning when eval-mode test accuracy and the batch-statistics
    one differ by more than :obj:`points` points in any repeat: then
    ``model.eval()`` inference does not give what the weights learned."""
    gap = summary.get('largest_statistics_gap')
    if gap is None or gap <= points:
        return None
    return (f"warning: in eval mode the test accuracy differs from the "
            f"same weights' with batch statistics by {gap:.1f} points "
            f"(more than {points:g}): mean {summary['eval_accuracy']:.1f} "
            f"vs {summary['batch_statistics_accuracy']:.1f} %")


def _span(values: Sequence[int]) -> str:
    return '?' if not values else str(values[0]) if len(values) == 1 \
        else f'{values[0]}-{values[-1]}'


def format_table(summary: Dict) -> str:
    """The summary as a two-line table."""
    reported = summary['reported']
    cells = {
        'row': summary['row'], 'metric': summary['metric'],
        'paper': 'not verified' if reported is None else f'{reported:.1f} %',
        'measured': f"{summary['mean']:.1f} \u00b1 {summary['std']:.1f} %",
        'repeats': str(summary['repeats']), 'epochs': str(summary['epochs']),
        'train/test shapes': f"{_span(summary['train_shapes'])}/"
                             f"{_span(summary['test_shapes'])}",
        'minutes': f"{summary['minutes']:.1f}",
    }
    if summary.get('eval_accuracy') is not None:
        cells['accuracy eval/batch stats'] = (
            f"{summary['eval_accuracy']:.1f}/"
            f"{summary['batch_statistics_accuracy']:.1f} %")
    widths = {k: max(len(k), len(v)) for k, v in cells.items()}
    return '\n'.join('  '.join(text.ljust(widths[k]) for k, text in
                               zip(cells, line)).rstrip()
                     for line in (list(cells), list(cells.values())))


def plot(path: str, protocol, runs: List[Dict], summary: Dict):
    """Every repeat's test metric (%) and training loss against the
    epoch, the paper's number as a dashed line."""
    import matplotlib
    matplotlib.use('Agg')
    import matplotlib.pyplot as plt
    from matplotlib.ticker import MaxNLocator

    from tg_intrinsic.io.figures import save_figure
    key, _ = metric_keys(protocol)
    fig, ax = plt.subplots(1, 2, figsize=(11, 4))
    for run in runs:
        label = f"repeat {run['repeat']} (seed {run['settings']['seed']})"
        tested = [h for h in run['history'] if h.get(key) is not None]
        ax[0].plot([h['epoch'] for h in tested],
                   [100 * h[key] for h in tested], 'o-', ms=3, label=label)
        ax[1].plot([h['epoch'] for h in run['history']],
                   [h['train_loss'] for h in run['history']], '.-',
                   label=label)
    if protocol.reported is not None:
        ax[0].axhline(protocol.reported, color='k', ls='--', lw=1,
                      label=f'paper: {protocol.reported:.1f} %')
    ax[0].set_ylim(0, 100)
    ax[0].set_ylabel(f'test {protocol.metric} (%)')
    ax[0].set_title(f'test {protocol.metric}')
    ax[1].set_ylabel('training loss')
    ax[1].set_title('training loss')
    last = max((h['epoch'] for run in runs for h in run['history']),
               default=1)
    for axis in ax:
        axis.set_xlim(0, last + 1)
        axis.set_xlabel('epoch')
        axis.xaxis.set_major_locator(MaxNLocator(integer=True))
        axis.grid(alpha=0.3)
        axis.legend(fontsize=7)
    smoke = ' [smoke run]' if summary['smoke'] else ''
    fig.suptitle(f"{protocol.summary}{smoke}\n{summary['mean']:.1f} "
                 f"\u00b1 {summary['std']:.1f} % over {summary['repeats']} "
                 f"repeat(s), {summary['epochs']} epoch(s) each")
    fig.tight_layout()
    save_figure(fig, path)


def _record(metrics: Dict, repeat: int, argv: List[str]) -> Dict:
    """A run's metrics without the bulky ``args``; the options that set
    the run (the protocol's, the seeds, the device) become ``settings``."""
    from tg_intrinsic.train import PROTOCOL_OPTIONS
    args = metrics['args']
    settings = {k: args.get(k) for k in PROTOCOL_OPTIONS + (
        'seed', 'data_seed', 'eval_every', 'logmap_method', 'device',
        'no_vector_stream')}
    out = {'repeat': repeat, 'argv': argv, 'settings': settings}
    out.update({k: v for k, v in metrics.items() if k != 'args'})
    return out


def versions() -> Dict:
    from tg_intrinsic.utils import machine_info
    import tg_intrinsic
    info = machine_info()
    info['tg_intrinsic'] = getattr(tg_intrinsic, '__version__', None)
    for name in ('h5py', 'trimesh', 'matplotlib'):
        try:
            info[name] = __import__(name).__version__
        except ImportError:
            info[name] = None
    return info


def run(row: Row, argv: Optional[Sequence[str]] = None,
        doc: Optional[str] = None) -> Dict:
    """Parses :obj:`argv`, runs the repeats and writes the outputs; returns
    the JSON's content. Errors (a bad PATH, a file the reader refuses)
    raise :class:`ValueError` or :class:`OSError`; :func:`main` turns them
    into one line and exit code 2."""
    from tg_intrinsic.protocols import get_protocol
    from tg_intrinsic.train import main as train
    from tg_intrinsic.utils import atomic_write_json

    own, extra = split_argv(sys.argv[1:] if argv is None else argv)
    parser = _parser(row, doc)
    args = parser.parse_args(own)
    if args.path is None and not args.smoke:
        parser.error('PATH is required (your copy of the data set), '
                     'unless --smoke')
    for flag in extra:
        if flag.split('=')[0] in RESERVED:
            parser.error(f"{flag.split('=')[0]} is set by this script; "
                         f"drop it from the flags after '--'")
    for name in ('repeats', 'epochs'):
        if getattr(args, name) is not None and getattr(args, name) < 1:
            parser.error(f'--{name} must be at least 1')
    protocol = get_protocol(row.protocol)
    repeats = args.repeats or (SMOKE_REPEATS if args.smoke
                               else protocol.repeats)
    epochs = args.epochs or (SMOKE_EPOCHS if args.smoke else None)
    out = args.out or osp.join('runs', 'replicate', row.name)

    print(f"{row.name}: {protocol.summary}")
    for note in protocol.notes + row.notes:
        print(f"  note: {note}")
    if args.smoke:
        smoke_root = osp.join(out, 'smoke_data')
        if osp.isdir(smoke_root):
            shutil.rmtree(smoke_root)
        os.makedirs(smoke_root)
        data = row.smoke_data(smoke_root)
        print(f"  smoke run: tiny data in the real format at {data}"
              + (f" (PATH {args.path} is not read)" if args.path else ''))
    else:
        data = args.path
    data = check_layout(data, row, protocol.task)
    common = ['--protocol', protocol.name,
              '--dataset', 'mesh_folder', '--mesh-root', data,
              '--root', osp.join(out, 'cache'), '--quiet']
    if args.smoke:
        common += smoke_flags(protocol)
    if epochs is not None:
        common += ['--epochs', str(epochs)]

    result = {'row': row.name, 'protocol': protocol.to_dict(),
              'row_notes': list(row.notes), 'data': osp.abspath(data),
              'command': list(sys.argv[1:] if argv is None else argv),
              'machine': versions(), 'complete': False, 'runs': []}
    json_path = osp.join(out, f'{row.name}.json')
    runs, seconds = [], 0.0
    for r in range(repeats):
        argv_r = common + ['--data-seed', str(r), '--seed', str(r),
                           '--out', osp.join(out, f'run_{r}'),
                           '--overwrite'] + extra  # a rerun starts over
        print(f"--- repeat {r + 1}/{repeats} (seed {r})")
        started = time.perf_counter()
        metrics = train(argv_r)
        took = time.perf_counter() - started
        seconds += took
        runs.append(dict(_record(metrics, r, argv_r), seconds=took))
        result.update(runs=runs, summary=summarize(protocol, runs, seconds,
                                                   args.smoke),
                      complete=r + 1 == repeats)
        atomic_write_json(json_path, result)
    summary = result['summary']
    plot(osp.join(out, f'{row.name}.png'), protocol, runs, summary)
    print()
    print(format_table(summary))
    warning = statistics_warning(summary)
    if warning:
        print(warning)
    print(f"written: {json_path}, {osp.join(out, row.name + '.png')}")
    return result


def main(row: Row, argv: Optional[Sequence[str]] = None,
         doc: Optional[str] = None) -> Dict:
    """:func:`run`, with a bad data folder reported as one line on stderr
    and exit code 2 (no traceback)."""
    try:
        return run(row, argv, doc)
    except (ValueError, OSError) as error:
        message = ' '.join(str(error).split())
        print(f"{row.name.replace('-', '_')}.py: error: {message}",
              file=sys.stderr)
        sys.exit(2)
