"""DeltaNet accuracy on SyntheticSHREC and SyntheticModelNet with the
paper's ablation: vector stream on versus off at a matched parameter count
(the scalar-only network gets wider convolutions until it has at least as
many parameters).

Protocol, the same for both sets: 10 training shapes per class (the
paper's SHREC protocol; SyntheticModelNet is cut to 10 train + 10 test per
class), points sampled from the surfaces, xyz input, random rotations
(uniform on SO(3)) and scales as training augmentation, Adam with a cosine
schedule. Convolution widths follow the original experiments: 32, 32, 32,
32 for SHREC and 64, 64, 128, 256 for ModelNet. SyntheticSHREC shapes come
in random orientations; SyntheticModelNet test shapes are upright.

CPU budget: the defaults (512 points) keep the four runs to about 35
minutes on 2 cores; pass --num-points 1024 for the paper's density.

Usage: python benchmarks/deltanet_accuracy.py [--epochs-shrec 100]
    [--epochs-modelnet 60] [--num-points 512]
Writes benchmarks/results/deltanet_accuracy.json and .png.
"""
import argparse
import os

import matplotlib

matplotlib.use('Agg')
import matplotlib.pyplot as plt  # noqa: E402

from tg_intrinsic.datasets import SyntheticModelNet, SyntheticSHREC  # noqa
from tg_intrinsic.nn.models import DeltaNetClassification  # noqa: E402
from tg_intrinsic.train import main as train  # noqa: E402
from tg_intrinsic.utils import atomic_write_json, machine_info  # noqa: E402

HERE = os.path.dirname(os.path.abspath(__file__))
CHANNELS = {'synthetic_shrec': (32, 32, 32, 32),
            'synthetic_modelnet': (64, 64, 128, 256)}


def count(model):
    return sum(p.numel() for p in model.parameters())


def matched_channels(base, num_classes):
    """Widths of the scalar-only network with at least the parameters of
    the two-stream network."""
    target = count(DeltaNetClassification(3, num_classes, base))
    scale = 1.0
    while True:
        channels = tuple(int(round(c * scale)) for c in base)
        model = DeltaNetClassification(3, num_classes, channels,
                                       vector_stream=False)
        if count(model) >= target:
            return channels, count(model), target
        scale += 0.02


def main():
    parser = argparse.ArgumentParser()
    parser.add_argument('--root', default='data')
    parser.add_argument('--runs', default=os.path.join('runs', 'accuracy'))
    parser.add_argument('--num-points', type=int, default=512)
    parser.add_argument('--epochs-shrec', type=int, default=100)
    parser.add_argument('--epochs-modelnet', type=int, default=60)
    parser.add_argument('--out', default=os.path.join(HERE, 'results'))
    args = parser.parse_args()
    results = {'machine': machine_info(), 'num_points': args.num_points,
               'protocol': '10 training shapes per class, xyz input, '
                           'SO(3) rotation + scale augmentation, Adam 1e-3 '
                           'cosine, batch 16',
               'dataset_versions': {
                   'synthetic_shrec': SyntheticSHREC.version,
                   'synthetic_modelnet': SyntheticModelNet.version},
               'runs': []}
    for dataset, epochs, num_classes in (
            ('synthetic_shrec', args.epochs_shrec, 12),
            ('synthetic_modelnet', args.epochs_modelnet, 12)):
        base = CHANNELS[dataset]
        wide, wide_params, params = matched_channels(base, num_classes)
        for vector in (True, False):
            channels = base if vector else wide
            name = f"{dataset}_{'vector' if vector else 'scalar_only'}"
            argv = ['--dataset', dataset, '--root', args.root,
                    '--out', os.path.join(args.runs, name), '--overwrite',
                    '--num-points', str(args.num_points),
                    '--epochs', str(epochs), '--batch-size', '16',
                    '--eval-every', str(max(1, epochs // 10)), '--quiet',
                    '--shapes-per-class', '20', '--rotate', 'so3',
                    '--optimizer', 'adam', '--lr', '1e-3', '--lr-min', '1e-5',
                    '--schedule', 'cosine', '--weight-decay', '1e-4',
                    '--label-smoothing', '0', '--scale', '0.667', '1.5',
                    '--no-anisotropic', '--translate', '0',
                    '--conv-channels', *map(str, channels)]
            if not vector:
                argv.append('--no-vector-stream')
            metrics = train(argv)
            results['runs'].append({
                'dataset': dataset, 'vector_stream': vector,
                'conv_channels': list(channels),
                'parameters': metrics['parameters'],
                'final_test_accuracy': metrics['final_test_accuracy'],
                'best_test_accuracy': metrics['best_test_accuracy'],
                'epochs': epochs,
                'history': metrics['history']})
            atomic_write_json(os.path.join(args.out,
                                           'deltanet_accuracy.json'), results)

    fig, axes = plt.subplots(1, 2, figsize=(11, 4))
    for ax, dataset in zip(axes, ('synthetic_shrec', 'synthetic_modelnet')):
        for run in results['runs']:
            if run['dataset'] != dataset:
                continue
            tested = [h for h in run['history']
                      if h['test_accuracy'] is not None]
            label = ('vector stream' if run['vector_stream']
                     else 'scalar only') + f" ({run['parameters'] / 1e6:.2f}M)"
            ax.plot([h['epoch'] for h in tested],
                    [h['test_accuracy'] for h in tested], 'o-', label=label)
        ax.set_title(f'DeltaNet on {dataset} ({args.num_points} points)')
        ax.set_xlabel('epoch')
        ax.set_ylabel('test accuracy')
        ax.set_ylim(0, 1)
        ax.legend()
    fig.tight_layout()
    fig.savefig(os.path.join(args.out, 'deltanet_accuracy.png'), dpi=120)


if __name__ == '__main__':
    main()
