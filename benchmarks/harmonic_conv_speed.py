"""HarmonicConv: neighbourhood aggregation through one sparse operator
(ours) versus per-edge messages (the original Harmonic Surface Networks'
layout, E x rings x channels x orders^2 messages), same outputs.

Per configuration, forward + backward time (best of a few runs, operator
build included for ours) and the peak memory, measured as the growth of the
resident set size in a fresh process per variant (CPU) or
torch.cuda.max_memory_allocated (GPU).

Usage: python benchmarks/harmonic_conv_speed.py [--vertices 2500]
Writes benchmarks/results/harmonic_conv_speed.json and .png.
"""
import argparse
import json
import os
import resource
import subprocess
import sys
import time

import matplotlib
import torch
import trimesh

matplotlib.use('Agg')
import matplotlib.pyplot as plt  # noqa: E402

from torch_geometric.data import Data  # noqa: E402

from tg_intrinsic.nn import HarmonicConv  # noqa: E402
from tg_intrinsic.transforms import (HarmonicPrecompute, LogMap,  # noqa: E402
                                     NormalizeArea)
from tg_intrinsic.utils import atomic_write_json, machine_info  # noqa: E402

HERE = os.path.dirname(os.path.abspath(__file__))
CONFIGS = [  # (channels in, channels out, prev_order, max_order)
    (16, 16, 1, 1), (32, 32, 1, 1), (16, 16, 2, 2)]


def mesh_data(vertices, radius, rings, max_order):
    sub = 1
    while 10 * 4 ** sub + 2 < vertices:
        sub += 1
    mesh = trimesh.creation.icosphere(subdivisions=sub)
    # a bumpy sphere: irregular discs, as on real shapes
    rng = torch.Generator().manual_seed(0)
    pos = torch.tensor(mesh.vertices, dtype=torch.float32)
    pos = pos * (1 + 0.1 * torch.rand(pos.size(0), 1, generator=rng))
    face = torch.tensor(mesh.faces).t().contiguous()
    data = NormalizeArea()(Data(pos=pos, face=face))
    data = LogMap(radius)(data)
    return HarmonicPrecompute(rings, max_order)(data)


def current_rss() -> int:
    with open('/proc/self/statm') as f:
        return int(f.read().split()[1]) * os.sysconf('SC_PAGE_SIZE')


def one_variant(args):
    """Runs in a fresh process: time and peak memory of one variant."""
    torch.manual_seed(0)
    data = torch.load(args.data, weights_only=False)
    c_in, c_out, p, o = args.config
    conv = HarmonicConv(c_in, c_out, o, args.rings, p).to(args.device)
    data = data.to(args.device)
    x = torch.randn(data.num_nodes, p + 1, c_in, dtype=torch.complex64,
                    device=args.device, requires_grad=True)
    harmonic = data.harmonic[:, :, :max(p, o) + 1]

    def step():
        out = conv(x, data.edge_index, harmonic, data.transport,
                   backend=args.backend)
        out.abs().sum().backward()
        return out

    def sync():
        if args.device == 'cuda':
            torch.cuda.synchronize()

    if args.device == 'cuda':
        torch.cuda.reset_peak_memory_stats()
        base = torch.cuda.memory_allocated()
    else:
        base = current_rss()
    out = step()  # warm up (and the peak)
    sync()
    times = []
    for _ in range(args.repeat):
        start = time.perf_counter()
        out = step()
        sync()
        times.append(time.perf_counter() - start)
    if args.device == 'cuda':
        peak = torch.cuda.max_memory_allocated() - base
    else:  # growth of the resident set over the steps
        peak = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss * 1024
        peak = max(peak - base, 0)
    print(json.dumps({'seconds': min(times), 'peak_bytes': peak,
                      'edges': data.edge_index.size(1),
                      'vertices': data.num_nodes,
                      'checksum': out.detach().abs().sum().item()}))


def run_variant(args, config, backend):
    cmd = [sys.executable, __file__, '--child', '--backend', backend,
           '--config', *map(str, config), '--data', args.data,
           '--rings', str(args.rings),
           '--repeat', str(args.repeat), '--device', args.device]
    out = subprocess.run(cmd, capture_output=True, text=True, check=True)
    return json.loads(out.stdout.strip().splitlines()[-1])


def main():
    parser = argparse.ArgumentParser()
    parser.add_argument('--vertices', type=int, default=2500)
    parser.add_argument('--radius', type=float, default=0.2)
    parser.add_argument('--rings', type=int, default=6)
    parser.add_argument('--repeat', type=int, default=3)
    parser.add_argument('--device', default='cuda' if torch.cuda.is_available()
                        else 'cpu')
    parser.add_argument('--out', default=os.path.join(HERE, 'results'))
    parser.add_argument('--child', action='store_true')
    parser.add_argument('--backend', default='sparse')
    parser.add_argument('--config', type=int, nargs=4, default=None)
    parser.add_argument('--data', default=None)
    args = parser.parse_args()
    if args.child:
        return one_variant(args)
    import tempfile
    folder = tempfile.mkdtemp()
    args.data = os.path.join(folder, 'mesh.pt')
    torch.save(mesh_data(args.vertices, args.radius, args.rings, 2),
               args.data)
    results = {'machine': machine_info(), 'device': args.device,
               'radius': args.radius, 'rings': args.rings, 'runs': []}
    for config in CONFIGS:
        ours = run_variant(args, config, 'sparse')
        naive = run_variant(args, config, 'message')
        results['runs'].append({
            'channels_in': config[0], 'channels_out': config[1],
            'prev_order': config[2], 'max_order': config[3],
            'vertices': ours['vertices'], 'edges': ours['edges'],
            'ours_s': ours['seconds'], 'naive_s': naive['seconds'],
            'speedup': naive['seconds'] / ours['seconds'],
            'ours_peak_mb': ours['peak_bytes'] / 2 ** 20,
            'naive_peak_mb': naive['peak_bytes'] / 2 ** 20,
            'memory_ratio': naive['peak_bytes'] / max(ours['peak_bytes'], 1),
            'outputs_agree': abs(ours['checksum'] - naive['checksum'])
            <= 1e-3 * abs(naive['checksum'])})
        print(results['runs'][-1])
        atomic_write_json(os.path.join(args.out, 'harmonic_conv_speed.json'),
                          results)
    labels = [f"{r['channels_in']}ch, M<={r['max_order']}"
              for r in results['runs']]
    fig, axes = plt.subplots(1, 2, figsize=(10, 3.8))
    x = range(len(labels))
    for ax, key, unit in ((axes[0], 's', 'forward + backward (s)'),
                          (axes[1], 'peak_mb', 'peak memory (MiB)')):
        ax.bar([i - 0.2 for i in x], [r[f'ours_{key}'] for r in
                                      results['runs']], 0.4, label='ours')
        ax.bar([i + 0.2 for i in x], [r[f'naive_{key}'] for r in
                                      results['runs']], 0.4,
               label='per-edge messages')
        ax.set_xticks(list(x), labels)
        ax.set_ylabel(unit)
        ax.legend()
    fig.suptitle(f"HarmonicConv on {results['runs'][0]['vertices']} "
                 f"vertices, {results['runs'][0]['edges']} edges "
                 f"({args.device})")
    fig.tight_layout()
    fig.savefig(os.path.join(args.out, 'harmonic_conv_speed.png'), dpi=120)


if __name__ == '__main__':
    main()
