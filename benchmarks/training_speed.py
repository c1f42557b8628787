"""Training speed on a laptop CPU: one SHREC11-sized epoch (300 training
shapes) of DeltaNet (2048 points per shape) and of HSN (all vertices of
~250-vertex meshes), with the papers' protocols (deltanet-shrec11,
hsn-shrec11), side by side with the slower paths in the same run:

1. DeltaNet with operators prepared once per shape and cached (what
   ``train`` does) against operators rebuilt for every batch (what
   DeltaNet did before, and still does under per-axis scaling);
2. DeltaNet's fused embedding and pooling (one numba operation on the
   CPU) against PyG's layers (the embedding MLP on ``[N, C]``, PyG's
   global max and mean pooling), both with cached operators;
3. HSN, batch 1 (the paper's) and batch 8;
4. the one-off preparation per shape (sampling + operators; HSN discs,
   log maps, transport and harmonic terms).

The shapes are SyntheticSHREC meshes of 200-300 vertices (the size of
MeshCNN's simplified SHREC11 copy). Timings are one epoch after a warm-up
epoch, on whatever threads torch uses (``--threads``; the goal is 2).

Usage: python benchmarks/training_speed.py [--threads 2] [--root data]
Writes benchmarks/results/training_speed.json and .png.
"""
import argparse
import os
import time

import matplotlib
import torch
import torch.nn.functional as F

matplotlib.use('Agg')
import matplotlib.pyplot as plt  # noqa: E402
from torch_geometric.loader import DataLoader  # noqa: E402

from tg_intrinsic import train as training  # noqa: E402
from tg_intrinsic.utils import atomic_write_json, machine_info  # noqa: E402

HERE = os.path.dirname(os.path.abspath(__file__))
OPERATOR_KEYS = ('edge_index', 'frame', 'grad_weight', 'div_weight')


def epoch_seconds(model, items, args, transform=None, parts=None) -> float:
    """Seconds of one training epoch over ``items`` (after one warm-up
    batch), with the protocol's optimiser and loss. ``parts`` (a dict), if
    given, receives the seconds spent loading batches, in the forward pass
    and in the backward pass + optimiser step."""
    optimizer = torch.optim.SGD(model.parameters(), lr=1e-3, momentum=0.9)
    loader = DataLoader(items, args.batch_size, shuffle=True, drop_last=True,
                        generator=torch.Generator().manual_seed(0))
    model.train()
    spent = {'loading': 0.0, 'forward': 0.0, 'backward_and_step': 0.0}

    def step(batch):
        start = time.perf_counter()
        if transform is not None:
            batch = transform(batch)
        optimizer.zero_grad()
        loss = F.cross_entropy(model(batch), batch.y.view(-1),
                               label_smoothing=args.label_smoothing)
        middle = time.perf_counter()
        loss.backward()
        optimizer.step()
        spent['forward'] += middle - start
        spent['backward_and_step'] += time.perf_counter() - middle

    step(next(iter(loader)))
    spent = dict.fromkeys(spent, 0.0)
    start = time.perf_counter()
    batches = iter(loader)
    while True:
        fetch = time.perf_counter()
        batch = next(batches, None)
        spent['loading'] += time.perf_counter() - fetch
        if batch is None:
            break
        step(batch)
    total = time.perf_counter() - start
    if parts is not None:
        parts.update(spent)
    return total


def without_operators(batch):
    batch = batch.clone()
    for key in OPERATOR_KEYS:
        del batch[key]
    return batch


def prepared(model_name, root, shapes):
    """Train items of a protocol on ``shapes`` SyntheticSHREC meshes, the
    seconds it took to prepare them, and the parsed arguments."""
    per_class = shapes // 12 + 1
    args = training.parse_args([
        '--protocol', f'{model_name}-shrec11', '--dataset', 'synthetic_shrec',
        '--root', root, '--num-vertices', '200', '300',
        '--shapes-per-class', str(2 * per_class), '--quiet'])
    import shutil
    shutil.rmtree(os.path.join(root, f'{model_name}_cache'),
                  ignore_errors=True)   # time the preparation itself
    start = time.perf_counter()
    build = training.build_mesh_datasets if model_name == 'hsn' else \
        training.build_point_sets
    items, test_items, source = build(args)
    seconds = time.perf_counter() - start
    per_shape = seconds / (len(items) + len(test_items))
    return items[:shapes], per_shape, source, args


def main():
    parser = argparse.ArgumentParser()
    parser.add_argument('--threads', type=int, default=2)
    parser.add_argument('--shapes', type=int, default=300)
    parser.add_argument('--root', default=os.path.join('data', 'speed'))
    parser.add_argument('--out', default=os.path.join(HERE, 'results'))
    parser.add_argument('--conditions', default='idle machine',
                        help='what else ran during the timing (stored)')
    options = parser.parse_args()
    torch.set_num_threads(options.threads)
    torch.manual_seed(0)
    results = {'machine': machine_info(), 'threads': options.threads,
               'conditions': options.conditions,
               'shapes': options.shapes, 'goal_seconds_per_epoch': 60}

    items, prep, source, args = prepared('deltanet', options.root,
                                         options.shapes)
    results['deltanet'] = {
        'protocol': args.protocol, 'points': args.num_points,
        'batch_size': args.batch_size, 'conv_channels': args.conv_channels,
        'prepare_seconds_per_shape': prep}
    model = training.build_model('deltanet', source.num_classes, args)
    timings = results['deltanet']
    timings['epoch_parts'] = {}
    timings['epoch_cached_operators'] = epoch_seconds(
        model, items, args, parts=timings['epoch_parts'])
    timings['epoch_operators_per_batch'] = epoch_seconds(
        model, items, args, without_operators)
    # PyG's layers in place of the fused embedding, same model and data.
    from torch_geometric.nn import global_max_pool, global_mean_pool

    def pyg_embed_and_pool(x, size, count):
        x = model.embedding(x)
        batch = torch.arange(size).repeat_interleave(count)
        return torch.cat([global_max_pool(x, batch, size),
                          global_mean_pool(x, batch, size)], dim=1)

    model._embed_and_pool_equal = pyg_embed_and_pool
    try:
        timings['epoch_pyg_embedding_pool'] = epoch_seconds(model, items,
                                                            args)
    finally:
        del model._embed_and_pool_equal
    print('deltanet', {k: round(v, 3) if isinstance(v, float) else v
                       for k, v in timings.items()})

    items, prep, source, args = prepared('hsn', options.root,
                                         options.shapes)
    results['hsn'] = {'protocol': args.protocol,
                      'batch_size': args.batch_size,
                      'mean_vertices': sum(i.num_nodes for i in items)
                      / len(items), 'prepare_seconds_per_shape': prep}
    model = training.build_model('hsn', source.num_classes, args)
    results['hsn']['epoch_parts'] = {}
    results['hsn']['epoch_batch_1'] = epoch_seconds(
        model, items, args, parts=results['hsn']['epoch_parts'])
    args.batch_size = 8
    results['hsn']['epoch_batch_8'] = epoch_seconds(model, items, args)
    print('hsn', {k: round(v, 3) if isinstance(v, float) else v
                  for k, v in results['hsn'].items()})

    os.makedirs(options.out, exist_ok=True)
    atomic_write_json(os.path.join(options.out, 'training_speed.json'),
                      results)
    bars = [('DeltaNet, cached operators', results['deltanet']
             ['epoch_cached_operators']),
            ('DeltaNet, operators per batch', results['deltanet']
             ['epoch_operators_per_batch']),
            ('DeltaNet, PyG embedding + pooling', results['deltanet']
             ['epoch_pyg_embedding_pool']),
            ('HSN, batch 1 (paper)', results['hsn']['epoch_batch_1']),
            ('HSN, batch 8', results['hsn']['epoch_batch_8'])]
    fig, ax = plt.subplots(figsize=(8, 3.6))
    ax.barh([b[0] for b in bars], [b[1] for b in bars], color='tab:blue')
    ax.axvline(60, color='tab:red', ls='--', label='goal: 60 s')
    ax.set_xlabel(f'seconds per epoch ({options.shapes} shapes, '
                  f'{options.threads} threads)')
    ax.set_title('SHREC11-sized training epoch on CPU')
    ax.invert_yaxis()
    ax.legend()
    fig.tight_layout()
    from tg_intrinsic.io.figures import save_figure
    save_figure(fig, os.path.join(options.out, 'training_speed.png'))


if __name__ == '__main__':
    main()
