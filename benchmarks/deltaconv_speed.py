"""DeltaConv speed, side by side in one run:

1. operator construction for a batch of 32 x 1024 points (k = 20): ours
   (numba MLS kernel) against the original authors' implementation of the
   same operators (``pcdiff``, numpy, one cloud at a time), with normals
   given and estimated; plus the gradient error of both on a sphere;
2. forward and backward of DeltaNetClassification against a DGCNN of the
   same depth and width built from PyG's EdgeConv (static k-nn graph, same
   k), with the graph / operator build timed separately;
3. torch.compile against eager for DeltaNet.

Usage: python benchmarks/deltaconv_speed.py [--repeat 3] [--no-compile]
Writes benchmarks/results/deltaconv_speed.json and .png.
"""
import argparse
import math
import os
import time

import matplotlib
import numpy as np
import torch

matplotlib.use('Agg')
import matplotlib.pyplot as plt  # noqa: E402
from torch_geometric.data import Batch, Data  # noqa: E402
from torch_geometric.nn import (MLP, EdgeConv, global_max_pool,  # noqa: E402
                                global_mean_pool)

from tg_intrinsic.geometry import knn  # noqa: E402
from tg_intrinsic.geometry.pointcloud.mls import (  # noqa: E402
    build_mls_operators)
from tg_intrinsic.nn.models import DeltaNetClassification  # noqa: E402
from tg_intrinsic.utils import atomic_write_json, machine_info  # noqa: E402

HERE = os.path.dirname(os.path.abspath(__file__))
B, N, K = 32, 1024, 20


def best_of(fn, repeat):
    fn()  # warm-up (numba compilation, allocator)
    times = []
    for _ in range(repeat):
        start = time.perf_counter()
        fn()
        times.append(time.perf_counter() - start)
    return min(times)


def clouds(seed=0):
    """32 bumpy spheres (ModelNet-sized) with their normals."""
    g = torch.Generator().manual_seed(seed)
    data = []
    for b in range(B):
        unit = torch.randn(N, 3, generator=g)
        unit = unit / unit.norm(dim=-1, keepdim=True)
        bump = 1 + 0.15 * torch.sin(3 * unit[:, 0] + b) * unit[:, 1]
        data.append(Data(pos=unit * bump[:, None], normal=unit,
                         y=torch.tensor([b % 10])))
    return Batch.from_data_list(data)


def construction(batch, repeat):
    out = {}
    out['ours_with_normals_s'] = best_of(lambda: build_mls_operators(
        batch.pos, K, batch.batch, normal=batch.normal), repeat)
    out['ours_estimated_normals_s'] = best_of(lambda: build_mls_operators(
        batch.pos, K, batch.batch), repeat)
    try:
        import pcdiff
    except ImportError:  # pip install pcdiff scikit-learn
        out['original_pcdiff_s'] = None
        return out
    pos = batch.pos.double().numpy()
    normal = batch.normal.double().numpy()

    def original(estimate):
        for b in range(B):
            p = pos[b * N:(b + 1) * N]
            edge_index = pcdiff.knn_graph(p, K)
            if estimate:
                basis = pcdiff.estimate_basis(p, edge_index)
            else:
                n = normal[b * N:(b + 1) * N]
                basis = (n, ) + tuple(pcdiff.build_tangent_basis(n))
            pcdiff.build_grad_div(p, *basis, edge_index, regularizer=1e-3)

    out['original_pcdiff_with_normals_s'] = best_of(lambda: original(False),
                                                    max(1, repeat - 1))
    out['original_pcdiff_estimated_normals_s'] = best_of(
        lambda: original(True), max(1, repeat - 1))
    out['speedup_with_normals'] = (out['original_pcdiff_with_normals_s']
                                   / out['ours_with_normals_s'])
    out['speedup_estimated_normals'] = (
        out['original_pcdiff_estimated_normals_s']
        / out['ours_estimated_normals_s'])
    out.update(sphere_accuracy(pcdiff))
    return out


def sphere_accuracy(pcdiff):
    """Max error of the gradient of the coordinate functions on a sphere
    (analytic: the tangential part of e_x, e_y, e_z), both methods."""
    from tg_intrinsic.geometry import tangent_frames
    from tg_intrinsic.geometry.pointcloud.mls import mls_grad_div
    from tg_intrinsic.geometry.pointcloud.operators import grad
    i = np.arange(4000) + 0.5
    phi, theta = np.arccos(1 - 2 * i / 4000), math.pi * (1 + 5 ** 0.5) * i
    p = np.stack([np.cos(theta) * np.sin(phi), np.sin(theta) * np.sin(phi),
                  np.cos(phi)], 1)
    pos = torch.tensor(p)
    frame = tangent_frames(pos)
    ei = knn(pos, K, loop=True)
    gw, _ = mls_grad_div(pos, frame, ei, normalized=False)
    ours = grad(pos, ei, gw)  # [N, 3, 2]
    edge_index = pcdiff.knn_graph(p, K)
    e_u, e_v = (frame[:, 0].numpy(), frame[:, 1].numpy())
    G, _ = pcdiff.build_grad_div(p, p, e_u, e_v, edge_index,
                                 regularizer=1e-3)
    theirs = (G @ p).reshape(-1, 2, 3).transpose(0, 2, 1)  # [N, 3, 2]
    exact = np.stack([np.eye(3) @ e_u.T, np.eye(3) @ e_v.T], -1)
    exact = exact.transpose(1, 0, 2)  # [N, 3 coordinates, 2]
    return {
        'sphere_gradient_max_error_ours':
            float(np.abs(ours.numpy() - exact).max()),
        'sphere_gradient_max_error_original':
            float(np.abs(theirs - exact).max()),
    }


def mlp(channels):
    return MLP(channels, act='leaky_relu', act_kwargs={'negative_slope': 0.2},
               norm='batch_norm', bias=False)


class DGCNN(torch.nn.Module):
    """DGCNN with a static graph, DeltaNet's widths and head."""
    def __init__(self, num_classes=10, channels=(64, 64, 128, 256)):
        super().__init__()
        ch = (3, ) + channels
        self.convs = torch.nn.ModuleList(
            EdgeConv(mlp([2 * a, b]), aggr='max')
            for a, b in zip(ch[:-1], ch[1:]))
        self.embedding = mlp([sum(channels), 1024])
        self.head = torch.nn.Sequential(
            mlp([2048, 512]), torch.nn.Dropout(0.5), mlp([512, 256]),
            torch.nn.Dropout(0.5), torch.nn.Linear(256, num_classes))

    def forward(self, data):
        x, outs = data.pos, []
        for conv in self.convs:
            x = conv(x, data.edge_index)
            outs.append(x)
        x = self.embedding(torch.cat(outs, 1))
        return self.head(torch.cat([global_max_pool(x, data.batch),
                                    global_mean_pool(x, data.batch)], 1))


def train_step_times(model, data, repeat):
    loss_fn = torch.nn.functional.cross_entropy

    def fwd():
        return loss_fn(model(data), data.y)

    def fwd_bwd():
        model.zero_grad()
        fwd().backward()

    forward = best_of(fwd, repeat)
    total = best_of(fwd_bwd, repeat)
    return forward, total - forward


def networks(batch, repeat):
    torch.manual_seed(0)
    delta = DeltaNetClassification(3, 10, k=K).train()
    dgcnn = DGCNN(10).train()
    out = {'deltanet_parameters': sum(p.numel() for p in delta.parameters()),
           'dgcnn_parameters': sum(p.numel() for p in dgcnn.parameters())}
    out['deltanet_build_s'] = best_of(lambda: build_mls_operators(
        batch.pos, K, batch.batch, normal=batch.normal), repeat)
    out['dgcnn_build_s'] = best_of(
        lambda: knn(batch.pos, K, batch.batch, loop=True), repeat)
    ei, frame, gw, dw = build_mls_operators(batch.pos, K, batch.batch,
                                            normal=batch.normal)
    with_ops = batch.clone()
    with_ops.edge_index, with_ops.grad_weight, with_ops.div_weight = \
        ei, gw, dw
    out['deltanet_forward_s'], out['deltanet_backward_s'] = \
        train_step_times(delta, with_ops, repeat)
    out['dgcnn_forward_s'], out['dgcnn_backward_s'] = \
        train_step_times(dgcnn, with_ops, repeat)
    for part in ('build', 'forward', 'backward'):
        out[f'speedup_{part}'] = out[f'dgcnn_{part}_s'] / \
            out[f'deltanet_{part}_s']
    ours = sum(out[f'deltanet_{p}_s'] for p in ('build', 'forward',
                                                 'backward'))
    theirs = sum(out[f'dgcnn_{p}_s'] for p in ('build', 'forward',
                                                'backward'))
    out['speedup_training_step'] = theirs / ours
    return out, with_ops


def compiled(with_ops, repeat):
    torch.manual_seed(0)
    model = DeltaNetClassification(3, 10, k=K).train()
    loss_fn = torch.nn.functional.cross_entropy

    def step(m):
        m.zero_grad()
        loss_fn(m(with_ops), with_ops.y).backward()

    eager = best_of(lambda: step(model), repeat)
    fast = torch.compile(model)
    start = time.perf_counter()
    step(fast)
    compile_s = time.perf_counter() - start
    return {'eager_step_s': eager, 'compiled_step_s': best_of(
        lambda: step(fast), repeat), 'compile_s': compile_s,
        'compile_speedup': eager / best_of(lambda: step(fast), repeat)}


def main():
    parser = argparse.ArgumentParser()
    parser.add_argument('--repeat', type=int, default=3)
    parser.add_argument('--no-compile', action='store_true')
    parser.add_argument('--out', default=os.path.join(HERE, 'results'))
    args = parser.parse_args()
    batch = clouds()
    result = {'machine': machine_info(), 'batch': f'{B} x {N} points',
              'k': K}
    result['construction'] = construction(batch, args.repeat)
    print('construction', result['construction'])
    result['networks'], with_ops = networks(batch, args.repeat)
    print('networks', result['networks'])
    if not args.no_compile:
        result['compile'] = compiled(with_ops, args.repeat)
        print('compile', result['compile'])
    atomic_write_json(os.path.join(args.out, 'deltaconv_speed.json'), result)

    c, n = result['construction'], result['networks']
    fig, ax = plt.subplots(1, 2, figsize=(11, 4))
    labels = ['normals given', 'normals estimated']
    x = np.arange(2)
    ax[0].bar(x - 0.2, [c['ours_with_normals_s'],
                        c['ours_estimated_normals_s']], 0.4,
              label='tg_intrinsic')
    if c.get('original_pcdiff_with_normals_s'):
        ax[0].bar(x + 0.2, [c['original_pcdiff_with_normals_s'],
                            c['original_pcdiff_estimated_normals_s']], 0.4,
                  label='original (pcdiff)')
    ax[0].set_xticks(x, labels)
    ax[0].set_ylabel('seconds per batch (32 x 1024, k=20)')
    ax[0].set_yscale('log')
    ax[0].set_title('operator construction')
    ax[0].legend()
    parts = ['build', 'forward', 'backward']
    x = np.arange(3)
    ax[1].bar(x - 0.2, [n[f'deltanet_{p}_s'] for p in parts], 0.4,
              label='DeltaNet')
    ax[1].bar(x + 0.2, [n[f'dgcnn_{p}_s'] for p in parts], 0.4,
              label='DGCNN (EdgeConv)')
    ax[1].set_xticks(x, parts)
    ax[1].set_ylabel('seconds per training step')
    ax[1].set_title('training step, same batch and k')
    ax[1].legend()
    fig.tight_layout()
    fig.savefig(os.path.join(args.out, 'deltaconv_speed.png'), dpi=120)


if __name__ == '__main__':
    main()
