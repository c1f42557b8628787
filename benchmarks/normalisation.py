"""Evaluation that matches training: which normalisation makes
``model.eval()`` score what the trained weights score (issue 29).

Every run trains with ``tg_intrinsic.train`` and then scores the saved
checkpoint on the test set three ways:

- **eval**: ``model.eval()``, the running statistics as training left
  them (what a user's inference gave before recalibration existed);
- **batch statistics**: batch norms normalise with each test batch's own
  statistics (HSN's protocol has one mesh per batch: per-shape
  statistics), on shuffled test batches of the protocol's size;
- **recalibrated**: ``model.eval()`` after
  :func:`tg_intrinsic.nn.recalibrate_batch_norm` over the training shapes
  (what ``train`` now does before every evaluation).

Two models, on generated data (the issue's reproduction):

1. HSN, protocol hsn-shrec11 (batch 1, Adam 1e-2, 15 epochs) on
   SyntheticSHREC (14 shapes per class, 300-500 vertices), for every
   normalisation of its blocks: ``batch`` (ComplexBatchNorm), ``instance``
   (ComplexInstanceNorm, per shape in both modes) and ``none`` (the
   authors' released code), over several seeds;
2. DeltaNet, protocol deltanet-modelnet40 (batch 32, SGD 0.1, cosine
   schedule) on SyntheticModelNet (16 shapes per class, 512 points):
   BatchNorm1d with and without recalibration, after 20 epochs (the
   weights still move) and after 60 (converged). Batch statistics depend
   on how the test set is cut into batches: five shuffles, their mean
   and range.

For the runs without recalibration, ``train``'s recalibration is switched
off (running statistics do not feed back into training, so the weights
are the same either way) and applied afterwards.

Usage: python benchmarks/normalisation.py [--seeds 0 1] [--root data]
Writes benchmarks/results/normalisation.json and .png.
"""
import argparse
import os
import time
from unittest import mock

import matplotlib
import torch

matplotlib.use('Agg')
import matplotlib.pyplot as plt  # noqa: E402
from torch_geometric.loader import DataLoader  # noqa: E402

from tg_intrinsic import distributed, train as training  # noqa: E402
from tg_intrinsic.nn import recalibrate_batch_norm  # noqa: E402
from tg_intrinsic.utils import atomic_write_json, machine_info  # noqa: E402

HERE = os.path.dirname(os.path.abspath(__file__))
HSN = ['--model', 'hsn', '--dataset', 'synthetic_shrec', '--shapes-per-class', '14',
       '--num-vertices', '300', '500', '--epochs', '15']
DELTANET = ['--model', 'deltanet', '--dataset', 'synthetic_modelnet',
            '--shapes-per-class', '16', '--num-points', '512']
DELTANET_EPOCHS = (20, 60)
SHUFFLES = 5


def score(argv, label: str, recalibrate_in_training: bool) -> dict:
    """Trains as ``argv`` says and scores its checkpoint (see the module
    docstring)."""
    args = training.parse_args(argv)
    start = time.perf_counter()
    if recalibrate_in_training:
        metrics = training.train(args)
    else:
        with mock.patch.object(training, 'recalibrate_batch_norm',
                               lambda *a, **k: 0):
            metrics = training.train(args)
    seconds = time.perf_counter() - start
    build = training.build_mesh_datasets if args.model == 'hsn' else \
        training.build_point_sets
    train_items, test_items, source = build(args)
    if args.train_per_class is not None:
        labels = [int(item.y) for item in train_items]
        train_items = [train_items[i] for i in training.select_per_class(
            labels, args.train_per_class, args.data_seed)]
    model = training.build_model(args.model, source.num_classes, args)
    state = torch.load(os.path.join(args.out, 'checkpoint.pt'),
                       weights_only=False)
    model.load_state_dict(state['model'])
    device = torch.device('cpu')
    ordered = DataLoader(test_items, args.batch_size)
    shuffles = []
    for shuffle in range(SHUFFLES if args.batch_size > 1 else 1):
        order = torch.randperm(len(test_items), generator=torch.Generator()
                               .manual_seed(shuffle)).tolist()
        shuffles.append(training.evaluate(
            model, DataLoader([test_items[i] for i in order],
                              args.batch_size), device,
            statistics='batch')['accuracy'])
    out = {'argv': argv, 'train_seconds': seconds, 'epochs': args.epochs,
           'reported_test_accuracy': metrics['final_test_accuracy'],
           'train_accuracy': metrics['history'][-1]['train_accuracy'],
           'eval': training.evaluate(model, ordered, device)['accuracy'],
           'batch_statistics': sum(shuffles) / len(shuffles),
           'batch_statistics_shuffles': shuffles}
    batches = distributed.epoch_batches(len(train_items), args.batch_size,
                                        args.seed, 0)
    used = recalibrate_batch_norm(model, DataLoader(
        train_items, batch_sampler=batches[:training.RECALIBRATION_BATCHES]))
    out['recalibrated'] = training.evaluate(model, ordered, device)[
        'accuracy'] if used else out['eval']
    out['recalibration_batches'] = used
    print(f"  {label}: eval {out['eval']:.3f}, batch statistics "
          f"{out['batch_statistics']:.3f} ({min(shuffles):.3f}-"
          f"{max(shuffles):.3f}), recalibrated "
          f"{out['recalibrated']:.3f} ({seconds:.0f} s)", flush=True)
    return out


def main():
    parser = argparse.ArgumentParser()
    parser.add_argument('--root', default='data')
    parser.add_argument('--runs', default=os.path.join('runs',
                                                       'normalisation'))
    parser.add_argument('--seeds', type=int, nargs='+', default=[0, 1])
    parser.add_argument('--out', default=os.path.join(HERE, 'results'))
    args = parser.parse_args()
    common = ['--root', args.root, '--quiet', '--threads', '2']
    results = {'machine': machine_info(), 'hsn_argv': HSN,
               'deltanet_argv': DELTANET, 'deltanet_epochs': DELTANET_EPOCHS,
               'shuffles': SHUFFLES, 'seeds': args.seeds, 'runs': []}
    for seed in args.seeds:
        for norm in ('batch', 'instance', 'none'):
            out = os.path.join(args.runs, f'hsn_{norm}_{seed}')
            run = score(HSN + common + ['--hsn-norm', norm, '--seed',
                                        str(seed), '--out', out,
                                        '--overwrite'],
                        f'hsn {norm} seed {seed}',
                        recalibrate_in_training=norm != 'batch')
            run.update(model='hsn', norm=norm, seed=seed)
            results['runs'].append(run)
    seed = args.seeds[0]
    for epochs in DELTANET_EPOCHS:
        out = os.path.join(args.runs, f'deltanet_{epochs}_{seed}')
        run = score(DELTANET + common + ['--epochs', str(epochs), '--seed',
                                         str(seed), '--out', out,
                                         '--overwrite'],
                    f'deltanet {epochs} epochs seed {seed}',
                    recalibrate_in_training=False)
        run.update(model='deltanet', norm='batch', seed=seed)
        results['runs'].append(run)
    os.makedirs(args.out, exist_ok=True)
    atomic_write_json(os.path.join(args.out, 'normalisation.json'), results)
    plot(results, os.path.join(args.out, 'normalisation.png'))


def plot(results, path):
    runs = results['runs']
    labels = []
    groups = {}
    for run in runs:
        label = f"{run['model']} {run['norm']}" if run['model'] == 'hsn' \
            else f"{run['model']} {run['epochs']} epochs"
        if label not in groups:
            labels.append(label)
            groups[label] = []
        groups[label].append(run)
    kinds = (('eval', 'eval (running statistics)'),
             ('recalibrated', 'eval, recalibrated'),
             ('batch_statistics', 'batch statistics'))
    fig, ax = plt.subplots(figsize=(9, 4))
    width = 0.27
    for k, (key, name) in enumerate(kinds):
        means = [sum(r[key] for r in groups[g]) / len(groups[g])
                 for g in labels]
        ax.bar([i + (k - 1) * width for i in range(len(labels))], means,
               width, label=name)
    ax.set_xticks(range(len(labels)))
    ax.set_xticklabels(labels)
    ax.set_ylabel('test accuracy (mean over seeds)')
    ax.set_ylim(0, 1.05)
    ax.legend(loc='lower left')
    ax.set_title('the same weights scored three ways')
    fig.tight_layout()
    fig.savefig(path, dpi=120)


if __name__ == '__main__':
    main()
