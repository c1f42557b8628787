"""Harmonic Surface Network accuracy on SyntheticSHREC, classification (10
training shapes per class) and segmentation (6 parts per vertex), with the
paper's ablation: two streams (rotation orders M = 0, 1; 16 then 32
features) against one stream (M = 0) with twice the features, i.e. four
times the parameters of a one-stream net of the same width, and as many as
the two-stream net.

Protocol: meshes of 300-500 vertices (the CPU budget; the paper's SHREC
meshes are of this size too), unit area, discs of radius 0.2 and 0.4 on
two levels (a quarter of the vertices), 'fast' log maps, random rotations
as augmentation, Adam 1e-2 with a cosine schedule, batch 8.

Usage: python benchmarks/hsn_accuracy.py [--epochs 40]
Writes benchmarks/results/hsn_accuracy.json and .png.
"""
import argparse
import json
import os

import matplotlib

matplotlib.use('Agg')
import matplotlib.pyplot as plt  # noqa: E402

from tg_intrinsic.train import main as train  # noqa: E402
from tg_intrinsic.utils import atomic_write_json, machine_info  # noqa: E402

HERE = os.path.dirname(os.path.abspath(__file__))
VARIANTS = (('two streams (M = 0, 1)', 1, (16, 32)),
            ('one stream (M = 0), 2x width', 0, (32, 64)))


def main():
    parser = argparse.ArgumentParser()
    parser.add_argument('--root', default='data')
    parser.add_argument('--runs', default=os.path.join('runs', 'hsn'))
    parser.add_argument('--epochs', type=int, default=40)
    parser.add_argument('--method', default='fast')
    parser.add_argument('--out', default=os.path.join(HERE, 'results'))
    parser.add_argument('--plot-only', action='store_true',
                        help='redraw the PNG from the JSON')
    args = parser.parse_args()
    if args.plot_only:
        with open(os.path.join(args.out, 'hsn_accuracy.json')) as f:
            return plot(json.load(f), args.out)
    results = {'machine': machine_info(), 'epochs': args.epochs,
               'protocol': 'SyntheticSHREC meshes of 300-500 vertices, 10 '
                           'training shapes per class, radii 0.2 / 0.4, '
                           f'{args.method} log maps, rotation augmentation, '
                           'Adam 1e-2 cosine, batch 8',
               'runs': []}
    for task in ('classification', 'segmentation'):
        for name, order, channels in VARIANTS:
            argv = ['--model', 'hsn', '--task', task,
                    '--dataset', 'synthetic_shrec', '--root', args.root,
                    '--num-vertices', '300', '500',
                    '--out', os.path.join(args.runs, f'{task}_M{order}'),
                    '--overwrite',
                    '--epochs', str(args.epochs), '--batch-size', '8',
                    '--optimizer', 'adam', '--lr', '1e-2', '--lr-min', '1e-4',
                    '--schedule', 'cosine', '--weight-decay', '1e-4',
                    '--scale', '1', '1', '--resample-vertices', '0',
                    '--max-order', str(order),
                    '--hsn-channels', *map(str, channels), '--rotate', 'so3',
                    '--logmap-method', args.method,
                    '--eval-every', str(max(1, args.epochs // 10)),
                    '--quiet']
            metrics = train(argv)
            results['runs'].append({
                'task': task, 'variant': name, 'max_order': order,
                'channels': list(channels),
                'parameters': metrics['parameters'],
                'final_test_accuracy': metrics['final_test_accuracy'],
                'best_test_accuracy': metrics['best_test_accuracy'],
                'seconds': metrics['history'][-1]['seconds'],
                'history': metrics['history']})
            atomic_write_json(os.path.join(args.out, 'hsn_accuracy.json'),
                              results)
    plot(results, args.out)


def plot(results, out):
    fig, axes = plt.subplots(1, 2, figsize=(11, 4))
    for ax, task in zip(axes, ('classification', 'segmentation')):
        for run in results['runs']:
            if run['task'] != task:
                continue
            tested = [h for h in run['history']
                      if h['test_accuracy'] is not None]
            ax.plot([h['epoch'] for h in tested],
                    [h['test_accuracy'] for h in tested], 'o-',
                    label=f"{run['variant']} ({run['parameters']} params)")
        ax.set_title(f'HSN on SyntheticSHREC {task}')
        ax.set_xlabel('epoch')
        ax.set_ylabel('test accuracy')
        ax.set_ylim(0, 1)
        ax.legend()
    fig.tight_layout()
    fig.savefig(os.path.join(out, 'hsn_accuracy.png'), dpi=120)


if __name__ == '__main__':
    main()
