"""PyG's machinery where it matters: ``torch.compile`` and mixed precision
on a training step of every model family, side by side with eager float32
in the same run.

1. Speed: one training step (forward, cross-entropy, backward, SGD) of
   DeltaNet and HSN, classification and segmentation, on SHREC11-sized
   SyntheticSHREC batches prepared by ``train``'s own pipelines (the
   protocols deltanet-shrec11 and hsn-shrec11: 2048 points per shape for
   DeltaNet; all vertices of 200-300-vertex meshes for HSN): eager float32,
   compiled (``torch.compile(dynamic=True)``, after its warm-up), eager
   under bfloat16 autocast, and compiled under it. The median over the
   timed steps, every arm on the same batches in turn.
2. Agreement: the eval-mode logits of each arm against eager float32, the
   largest difference relative to the largest logit.
3. Accuracy: ``train`` runs of DeltaNet and HSN on a generated data set
   with ``--precision 32-true`` and ``--precision bf16-mixed``, everything
   else equal, over several seeds: the mean final test accuracies (the
   goal: within 1 point) and the spread the seed alone causes.

Usage: python benchmarks/compile_precision.py [--steps 8] [--seeds 4]
       [--quick] [--accuracy-only]
Writes benchmarks/results/compile_precision.json and .png.
"""
import argparse
import json
import os
import statistics
import time

import matplotlib

matplotlib.use('Agg')
import matplotlib.pyplot as plt  # noqa: E402
import torch  # noqa: E402
import torch.nn.functional as F  # noqa: E402
from torch_geometric.loader import DataLoader  # noqa: E402

from tg_intrinsic import train as training  # noqa: E402
from tg_intrinsic.devices import autocast  # noqa: E402
from tg_intrinsic.io.figures import save_figure  # noqa: E402
from tg_intrinsic.utils import atomic_write_json, machine_info  # noqa: E402

HERE = os.path.dirname(os.path.abspath(__file__))
#: arm -> (compiled, precision); the first is the baseline
ARMS = {'eager': (False, '32-true'), 'compiled': (True, '32-true'),
        'bf16': (False, 'bf16-mixed'), 'compiled_bf16': (True, 'bf16-mixed')}
CPU = torch.device('cpu')
CONFIGS = (('deltanet', 'classification'), ('deltanet', 'segmentation'),
           ('hsn', 'classification'), ('hsn', 'segmentation'))


def batches_of(model_name, task, root, count, quick):
    """``count`` training batches of the protocol (repeated if it has
    fewer), and its arguments."""
    argv = ['--model', model_name, '--task', task, '--dataset',
            'synthetic_shrec', '--root', root, '--num-vertices', '200', '300',
            '--quiet', '--shapes-per-class', '2' if quick else '6']
    if quick and model_name == 'deltanet':
        argv += ['--num-points', '512', '--batch-size', '4']
    args = training.parse_args(argv)
    build = training.build_mesh_datasets if model_name == 'hsn' else \
        training.build_point_sets
    items, _, source = build(args)
    loader = DataLoader(items, min(args.batch_size, len(items)),
                        shuffle=True, drop_last=True,
                        generator=torch.Generator().manual_seed(0))
    batches = list(loader)
    return [batches[i % len(batches)] for i in range(count)], source, args


def train_step(model, forward, batch, precision, device, optimizer=None):
    """One training step of ``model`` through ``forward`` (the model or
    its compiled version) at ``precision``."""
    model.train()
    (optimizer or model).zero_grad()
    with autocast(precision, device):
        out = forward(batch)
    F.cross_entropy(out.float(), batch.y.view(-1)).backward()
    if optimizer is not None:
        optimizer.step()


def logits_gap(model, forward, batch, precision, reference, device):
    """The largest difference of the eval-mode logits from ``reference``,
    relative to its largest logit."""
    model.eval()
    with torch.no_grad(), autocast(precision, device):
        out = forward(batch).float()
    return float((out - reference.float()).abs().max()
                 / reference.abs().max())


def time_steps(model, forward, batches, precision):
    optimizer = torch.optim.SGD(model.parameters(), lr=1e-4)
    seconds = []
    for batch in [batches[0]] + batches:   # the first warms up (compiles)
        start = time.perf_counter()
        train_step(model, forward, batch, precision, CPU, optimizer)
        seconds.append(time.perf_counter() - start)
    return statistics.median(seconds[1:])


def measure(model_name, task, root, steps, quick):
    batches, source, args = batches_of(model_name, task, root, steps, quick)
    torch.manual_seed(0)
    model = training.build_model(model_name, source.num_classes, args)
    state = {k: v.clone() for k, v in model.state_dict().items()}
    compiled = torch.compile(model, dynamic=True)
    row = {'batch_size': batches[0].num_graphs, 'steps': steps,
           'points_per_batch': batches[0].num_nodes}
    model.eval()
    with torch.no_grad():
        reference = model(batches[0])
    for arm, (compile_it, precision) in ARMS.items():
        forward = compiled if compile_it else model
        model.load_state_dict(state)   # every arm from the same weights
        row[f'{arm}_step_seconds'] = time_steps(model, forward, batches,
                                                precision)
        model.load_state_dict(state)
        row[f'{arm}_logits_gap'] = logits_gap(
            model, forward, batches[0], precision, reference, CPU)
    for arm in list(ARMS)[1:]:
        row[f'{arm}_speedup'] = row['eager_step_seconds'] / \
            row[f'{arm}_step_seconds']
    torch._dynamo.reset()
    return row


#: the generated accuracy benchmark of each family: converged runs whose
#: test accuracy is limited by few training shapes, not by epochs
ACCURACY_RUNS = {
    'deltanet': ['--model', 'deltanet', '--dataset', 'synthetic_modelnet',
                 '--num-points', '256', '--shapes-per-class', '34',
                 '--train-per-class', '4', '--batch-size', '8',
                 '--epochs', '50', '--optimizer', 'adam', '--lr', '0.01'],
    'hsn': ['--model', 'hsn', '--dataset', 'synthetic_shrec',
            '--shapes-per-class', '12', '--num-vertices', '150', '200',
            '--epochs', '10'],
}
QUICK_ACCURACY = {'deltanet': ['--shapes-per-class', '4', '--epochs', '3'],
                  'hsn': ['--shapes-per-class', '4', '--epochs', '2']}


def accuracy_runs(root, out, seeds, quick):
    """Final test accuracy of float32 and bf16-mixed training runs, paired
    by seed (the same initial weights and batch order): per seed, their
    mean and spread, and the mean of the paired differences. One run's
    accuracy moves by several points with the seed alone, so the
    precisions are compared over several seeds."""
    results = {}
    for name, argv in ACCURACY_RUNS.items():
        if quick:   # later options win in argparse
            argv = argv + QUICK_ACCURACY[name]
        row = results[name] = {'argv': argv, 'seeds': list(seeds)}
        for precision in ('32-true', 'bf16-mixed'):
            row[precision] = [training.main(argv + [
                '--root', root, '--precision', precision, '--quiet',
                '--seed', str(seed), '--eval-every', '1000', '--overwrite',
                '--out', os.path.join(out, f'{name}_{precision}_{seed}')]
            )['final_test_accuracy'] for seed in seeds]
            row[f'{precision}_mean'] = statistics.mean(row[precision])
            row[f'{precision}_stdev'] = statistics.stdev(row[precision]) \
                if len(seeds) > 1 else 0.0
        differences = [b - a for a, b in zip(row['32-true'],
                                              row['bf16-mixed'])]
        row['points_apart'] = 100 * abs(statistics.mean(differences))
        row['paired_stdev_points'] = 100 * statistics.stdev(differences) \
            if len(seeds) > 1 else 0.0
    return results


def plot(results, path):
    fig, ax = plt.subplots(figsize=(7.5, 3.6))
    names = [f'{m}\n{t}' for m, t in CONFIGS]
    width = 0.27
    for k, arm in enumerate(list(ARMS)[1:]):
        values = [results['speed'][f'{m}_{t}'][f'{arm}_speedup']
                  for m, t in CONFIGS]
        ax.bar([i + (k - 1) * width for i in range(len(names))], values,
               width, label=arm.replace('_', ' + '))
    ax.axhline(1.0, color='black', lw=0.8)
    ax.set_xticks(range(len(names)), names)
    ax.set_ylabel('training step speed-up over eager float32')
    ax.set_title('torch.compile and bfloat16 autocast, CPU')
    ax.legend(frameon=False)
    fig.tight_layout()
    save_figure(fig, path)


def main():
    parser = argparse.ArgumentParser()
    parser.add_argument('--steps', type=int, default=8)
    parser.add_argument('--threads', type=int, default=2)
    parser.add_argument('--quick', action='store_true')
    parser.add_argument('--seeds', type=int, default=4,
                        help='training runs per precision for the accuracy')
    parser.add_argument('--accuracy-only', action='store_true',
                        help='keep the speed results of the stored json')
    parser.add_argument('--root', default=os.path.join('data', 'machinery'))
    parser.add_argument('--out', default=os.path.join(HERE, 'results'))
    parser.add_argument('--conditions', default='idle machine',
                        help='what else ran during the timing (stored)')
    options = parser.parse_args()
    torch.set_num_threads(options.threads)
    path = os.path.join(options.out, 'compile_precision.json')
    results = {'machine': machine_info(), 'threads': options.threads,
               'conditions': options.conditions, 'quick': options.quick,
               'speed': {}}
    if options.accuracy_only:
        with open(path) as stored:
            results['speed'] = json.load(stored)['speed']
    for model_name, task in CONFIGS * (not options.accuracy_only):
        row = measure(model_name, task, options.root, options.steps,
                      options.quick)
        results['speed'][f'{model_name}_{task}'] = row
        print(model_name, task, {k: round(v, 4) for k, v in row.items()
                                 if isinstance(v, float)})
    results['accuracy'] = accuracy_runs(
        options.root, os.path.join(options.root, 'runs'),
        range(options.seeds), options.quick)
    print(results['accuracy'])
    os.makedirs(options.out, exist_ok=True)
    atomic_write_json(path, results)
    plot(results, os.path.join(options.out, 'compile_precision.png'))


if __name__ == '__main__':
    main()
