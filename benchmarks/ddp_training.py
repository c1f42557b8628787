"""Data-parallel training on this machine's CPU cores: the time of one
training epoch (after a warm-up epoch) with ``torchrun`` processes against
one process, at the same global batch and seed.

Protocol. Each configuration is a separate launch of the training command
(``python -m tg_intrinsic.train``, under ``python -m torch.distributed.run
--standalone --nproc_per_node N`` for N processes, gloo backend) on the
same prepared inputs (the cache is built once, before the timed launches),
two epochs, the test set scored after the second only; the time of epoch 2
is read from the run's metrics.json (``seconds`` is taken before the
evaluation). Configurations, on the CPU:

1. 1 process x 2 threads (torch and numba),
2. 1 process x 1 thread,
3. 2 processes x 1 thread each, per-process batch norm (DDP's default),
4. 2 processes x 1 thread each, ``--sync-batch-norm``.

The speed-up of 2 processes is epoch(1 process x 2 threads) / epoch(2
processes) - both use the two cores - and against 1 thread. Models:
DeltaNet classification (deltanet-shrec11 widths 32, 32, 32, 32 on
SyntheticModelNet, 1024 points, 96 training shapes, global batch 16) and
HSN classification (hsn-shrec11 on SyntheticSHREC meshes of 200-300
vertices, 36 training shapes, global batch 8: HSN's paper batch of 1
cannot be split over processes). No augmentation and no dropout (identical
draws everywhere); the losses are recorded: one process and sync BN agree
to float32 rounding amplified over the steps, per-process BN differs.
With CUDA, 1 GPU against all GPUs (``--device cuda``) is timed as well;
without, the JSON says "no GPU". About 5 minutes on 2 cores.

Usage: python benchmarks/ddp_training.py [--quick] [--root data]
Writes benchmarks/results/ddp_training.json and .png.
"""
import argparse
import json
import os
import subprocess
import sys
import time

import matplotlib
import torch

matplotlib.use('Agg')
import matplotlib.pyplot as plt  # noqa: E402

from tg_intrinsic.utils import atomic_write_json, machine_info  # noqa: E402

HERE = os.path.dirname(os.path.abspath(__file__))
ROOT = os.path.dirname(HERE)
MODELS = {
    'deltanet': ['--model', 'deltanet', '--protocol', 'deltanet-shrec11',
                 '--dataset', 'synthetic_modelnet', '--num-points', '1024',
                 '--shapes-per-class', '16', '--train-per-class', '8',
                 '--batch-size', '16', '--dropout', '0'],
    'hsn': ['--model', 'hsn', '--dataset', 'synthetic_shrec',
            '--num-vertices', '200', '300', '--shapes-per-class', '6',
            '--batch-size', '8']}
QUICK = {'deltanet': ['--num-points', '256', '--shapes-per-class', '4',
                      '--batch-size', '8'],
         'hsn': ['--shapes-per-class', '2', '--num-vertices', '120', '160',
                 '--batch-size', '4']}
COMMON = ['--epochs', '2', '--eval-every', '2', '--optimizer', 'sgd',
          '--lr', '0.01', '--schedule', 'step', '--milestones', '100',
          '--rotate', 'none', '--scale', '1', '1', '--translate', '0',
          '--quiet', '--seed', '0']


def launch(model, processes, threads, root, out, extra=(), quick=False,
           device='cpu'):
    """Runs one configuration; returns its timings and final scores."""
    argv = MODELS[model] + (QUICK[model] if quick else []) + COMMON + [
        '--root', root, '--out', out, '--overwrite', '--threads', str(threads),
        '--device', device, *extra]
    if processes == 1:
        command = [sys.executable, '-m', 'tg_intrinsic.train'] + argv
    else:
        command = [sys.executable, '-m', 'torch.distributed.run',
                   '--standalone', '--nproc_per_node', str(processes),
                   '-m', 'tg_intrinsic.train'] + argv
    env = {**os.environ, 'OMP_NUM_THREADS': str(threads),
           'NUMBA_NUM_THREADS': str(threads),
           'PYTHONPATH': ROOT + os.pathsep + os.environ.get('PYTHONPATH',
                                                            '')}
    start = time.perf_counter()
    done = subprocess.run(command, env=env, capture_output=True, text=True,
                          cwd=ROOT)
    wall = time.perf_counter() - start
    if done.returncode:
        raise RuntimeError(f"{' '.join(command)} failed:\n"
                           f"{done.stdout[-2000:]}\n{done.stderr[-3000:]}")
    with open(os.path.join(out, 'metrics.json')) as f:
        metrics = json.load(f)
    history = metrics['history']
    return {'processes': processes, 'threads_per_process': threads,
            'sync_batch_norm': '--sync-batch-norm' in extra,
            'device': device, 'world_size': metrics['world_size'],
            'epoch_seconds': history[1]['seconds'] - history[0]['seconds'],
            'warmup_epoch_seconds': history[0]['seconds'],
            'launch_wall_seconds': wall,
            'train_loss': [h['train_loss'] for h in history],
            'final_test_accuracy': metrics['final_test_accuracy'],
            'train_shapes': metrics['train_shapes'],
            'command': ' '.join(['python'] + command[1:])}


def main():
    parser = argparse.ArgumentParser()
    parser.add_argument('--root', default='data')
    parser.add_argument('--runs', default=os.path.join('runs', 'ddp'))
    parser.add_argument('--models', nargs='+', default=list(MODELS),
                        choices=list(MODELS))
    parser.add_argument('--quick', action='store_true',
                        help='smoke test: tiny sets, nothing written')
    parser.add_argument('--out', default=os.path.join(HERE, 'results'))
    args = parser.parse_args()
    root = os.path.abspath(args.root)
    runs = os.path.abspath(args.runs)
    configurations = [('1 process x 2 threads', 1, 2, ()),
                      ('1 process x 1 thread', 1, 1, ()),
                      ('2 processes x 1 thread', 2, 1, ()),
                      ('2 processes x 1 thread, sync BN', 2, 1,
                       ('--sync-batch-norm', ))]
    protocol = __doc__.split('\n\nUsage')[0].split('\n\n', 1)[1]
    results = {'machine': machine_info(),
               'protocol': ' '.join(protocol.split()), 'models': {}}
    for model in args.models:
        # the inputs are prepared (and cached) once, untimed
        launch(model, 1, 2, root, os.path.join(runs, model, 'prepare'),
               quick=args.quick)
        rows = []
        for label, processes, threads, extra in configurations:
            row = launch(model, processes, threads, root,
                         os.path.join(runs, model, label.replace(' ', '_')
                                      .replace(',', '')), extra, args.quick)
            row['label'] = label
            rows.append(row)
            print(f"{model}, {label}: {row['epoch_seconds']:.2f} s per "
                  f"epoch, losses {row['train_loss']}", flush=True)
        one = {r['label']: r['epoch_seconds'] for r in rows}
        results['models'][model] = {
            'train_shapes': rows[0]['train_shapes'],
            'configurations': rows,
            'speedup_2_processes_vs_1_process_2_threads':
                one['1 process x 2 threads'] / one['2 processes x 1 thread'],
            'speedup_2_processes_vs_1_process_1_thread':
                one['1 process x 1 thread'] / one['2 processes x 1 thread'],
            'speedup_2_processes_sync_bn_vs_1_process_2_threads':
                one['1 process x 2 threads']
                / one['2 processes x 1 thread, sync BN']}
    if torch.cuda.is_available():
        count = torch.cuda.device_count()
        gpu = {'devices': count, 'name': torch.cuda.get_device_name(0)}
        for model in args.models:
            rows = [launch(model, n, 1, root, os.path.join(
                runs, model, f'cuda_{n}'), quick=args.quick, device='cuda')
                for n in sorted({1, count})]
            gpu[model] = rows
        results['gpu'] = gpu
    else:
        results['gpu'] = 'no GPU'
    if args.quick:
        print(json.dumps(results['models'], indent=1)[:3000])
        print('quick run: nothing written')
        return
    os.makedirs(args.out, exist_ok=True)
    atomic_write_json(os.path.join(args.out, 'ddp_training.json'), results)
    fig, axes = plt.subplots(1, len(results['models']),
                             figsize=(5 * len(results['models']), 3.8),
                             squeeze=False)
    for ax, (model, data) in zip(axes[0], results['models'].items()):
        rows = data['configurations']
        ax.barh([r['label'] for r in rows],
                [r['epoch_seconds'] for r in rows], color='tab:blue')
        ax.invert_yaxis()
        ax.set_xlabel('seconds per training epoch')
        ax.set_title(f"{model}: {data['train_shapes']} shapes, "
                     f"{os.cpu_count()} CPU cores")
        ax.grid(axis='x', alpha=0.3)
    fig.tight_layout()
    fig.savefig(os.path.join(args.out, 'ddp_training.png'), dpi=110)
    print(f"written to {args.out}")


if __name__ == '__main__':
    main()
