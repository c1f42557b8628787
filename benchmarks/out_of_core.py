"""Out-of-core training data: the peak memory of one DeltaNet training
epoch as the data set grows, with the prepared examples held in memory (a
list, what training holds without --on-disk) or in a PrecomputedOnDisk
database (PyG's OnDiskDataset, SQLite; what --on-disk trains from); and
the preparation time with 1 and 2 worker processes.

Protocol: SyntheticModelNet point clouds of 1024 points (generated once,
by 2 workers, and cached under --root), DeltaConv's MLS operators (k =
20) precomputed into a database (about 0.7 MB per example) twice, by 1
and by 2 worker processes: both timed (on an otherwise idle machine: run
it under the project's lock) and compared row by row. For every size N
(4 sizes, doubling; default 375 to 3000 shapes, an in-memory list of
about 2.1 GB at the largest) and each of the two arms, a fresh Python
process (one torch thread) builds the network, then holds the first N
examples as a list read from the database (in memory) or opens the
database (on disk), and trains one epoch: shuffled batches of 16
(seeded), a tiny DeltaNet (one DeltaConv block of width 4, embedding 32,
so that the CPU budget goes to the data, not the network) with Adam. The
peak resident memory of that process is read from /proc/self/status
(VmHWM, what the kernel counts; tracemalloc does not see torch tensors),
its resident memory before the data is touched is the baseline. The two
arms of a size run side by side (one core each), so epoch times are for
two busy cores; both arms must end with the same training loss (the same
batches). On this machine (2 cores) the default run takes about 11
minutes.

Usage: python benchmarks/out_of_core.py [--sizes 375 750 1500 3000]
    [--root data/out_of_core] [--quick]
Writes benchmarks/results/out_of_core.json and .png.
"""
import argparse
import json
import os
import sqlite3
import subprocess
import sys
import time

import numpy as np

HERE = os.path.dirname(os.path.abspath(__file__))
NUM_POINTS, K, BATCH = 1024, 20, 16
ARMS = ('in_memory', 'on_disk')


def status_mb(field: str) -> float:
    """A memory line of /proc/self/status (kB) in MB."""
    with open('/proc/self/status') as f:
        for line in f:
            if line.startswith(field + ':'):
                return int(line.split()[1]) / 1024
    raise RuntimeError(f'no {field} in /proc/self/status')


def measure(arm: str, size: int, database: str) -> dict:
    """One epoch in this (fresh) process; its peak memory."""
    import torch
    import torch.nn.functional as F
    from torch_geometric.loader import DataLoader
    from tg_intrinsic.datasets import PrecomputedOnDisk
    from tg_intrinsic.nn.models import DeltaNetClassification
    torch.set_num_threads(1)
    torch.manual_seed(0)
    model = DeltaNetClassification(3, 12, (4, ), k=K, embedding_size=32)
    optimizer = torch.optim.Adam(model.parameters(), lr=1e-3)
    baseline = status_mb('VmRSS')
    dataset = PrecomputedOnDisk(database, None, log=False)
    examples = [dataset[i] for i in range(size)] if arm == 'in_memory' \
        else dataset[:size]
    loader = DataLoader(examples, BATCH, shuffle=True,
                        generator=torch.Generator().manual_seed(0))
    start = time.perf_counter()
    loss_sum = 0.0
    model.train()
    for batch in loader:
        optimizer.zero_grad()
        loss = F.cross_entropy(model(batch), batch.y)
        loss.backward()
        optimizer.step()
        loss_sum += float(loss.detach()) * batch.num_graphs
    seconds = time.perf_counter() - start
    return {'arm': arm, 'size': size, 'baseline_mb': baseline,
            'peak_mb': status_mb('VmHWM'), 'epoch_seconds': seconds,
            'mean_loss': loss_sum / size}


def run_pair(size: int, database: str) -> list:
    """Both arms of one size, each in its own fresh process."""
    procs = [subprocess.Popen(
        [sys.executable, os.path.abspath(__file__), '--measure', arm,
         str(size), database], stdout=subprocess.PIPE, text=True)
        for arm in ARMS]
    rows = []
    for proc in procs:
        out, _ = proc.communicate()
        if proc.returncode != 0:
            raise RuntimeError(f'measurement failed: {out}')
        rows.append(json.loads(out.strip().splitlines()[-1]))
    return rows


def same_rows(first: str, second: str) -> bool:
    """Whether two databases hold the same rows, byte for byte (read
    row by row)."""
    query = 'SELECT * FROM PrecomputedOnDisk ORDER BY id'
    with sqlite3.connect(first) as a, sqlite3.connect(second) as b:
        rows_a, rows_b = a.execute(query), b.execute(query)
        while True:
            x, y = rows_a.fetchone(), rows_b.fetchone()
            if x != y:
                return False
            if x is None:
                return True


class First:
    """The first ``n`` items of a data set."""
    def __init__(self, dataset, n):
        self.dataset, self.n = dataset, n

    def __len__(self):
        return self.n

    def __getitem__(self, i):
        if not 0 <= i < self.n:
            raise IndexError(i)
        return self.dataset[i]


def slope(rows: list, arm: str) -> float:
    """Least-squares MB per 1000 shapes of the peak."""
    x = np.array([r['size'] for r in rows if r['arm'] == arm], float)
    y = np.array([r['peak_mb'] for r in rows if r['arm'] == arm])
    return float(np.polyfit(x, y, 1)[0] * 1000)


def main():
    parser = argparse.ArgumentParser()
    parser.add_argument('--sizes', type=int, nargs='+',
                        default=[375, 750, 1500, 3000])
    parser.add_argument('--root', default=os.path.join('data',
                                                       'out_of_core'))
    parser.add_argument('--out', default=os.path.join(HERE, 'results'))
    parser.add_argument('--quick', action='store_true',
                        help='sizes 48 96 192: a check that it runs')
    parser.add_argument('--measure', nargs=3, metavar=('ARM', 'N', 'DB'),
                        help=argparse.SUPPRESS)
    args = parser.parse_args()
    if args.measure:
        arm, size, database = args.measure
        print(json.dumps(measure(arm, int(size), database)))
        return
    import torch
    from tg_intrinsic.datasets import PrecomputedOnDisk, SyntheticModelNet
    from tg_intrinsic.transforms import MLSOperators
    from tg_intrinsic.utils import atomic_write_json, machine_info
    sizes = [48, 96, 192] if args.quick else sorted(args.sizes)
    largest = max(sizes)
    results = {'machine': machine_info(), 'quick': args.quick,
               'protocol': __doc__.split('Usage:')[0].strip(),
               'num_points': NUM_POINTS, 'k': K, 'batch_size': BATCH,
               'sizes': sizes}
    start = time.perf_counter()
    source = SyntheticModelNet(
        os.path.join(args.root, 'source'), num_points=NUM_POINTS,
        num_per_class=(-(-largest // 12), 1), workers=2, log=False)
    results['generation_seconds'] = time.perf_counter() - start
    operators = MLSOperators(k=K)
    torch.set_num_threads(1)

    prep, datasets = {}, {}
    for workers in (1, 2):
        path = os.path.join(args.root, f'mls_k{K}_workers{workers}')
        start = time.perf_counter()
        datasets[workers] = PrecomputedOnDisk(
            path, First(source, max(sizes)), operators, workers=workers,
            log=False, force_reload=True)
        prep[workers] = time.perf_counter() - start
        datasets[workers].close()
        print(f'prepared {max(sizes)} shapes with {workers} worker(s) in '
              f'{prep[workers]:.1f} s', flush=True)
    database = os.path.join(args.root, f'mls_k{K}_workers2')
    results['preparation'] = {
        'shapes': max(sizes),
        'seconds': {str(w): s for w, s in prep.items()},
        'speedup': prep[1] / prep[2],
        'identical': same_rows(datasets[1].processed_paths[0],
                               datasets[2].processed_paths[0])}
    results['database'] = {
        'shapes': max(sizes),
        'megabytes': os.path.getsize(datasets[2].processed_paths[0])
        / 2 ** 20}
    rows = []
    for size in sizes:
        pair = run_pair(size, database)
        rows += pair
        for r in pair:
            print(f"{r['arm']:9s} N={size:5d}: peak {r['peak_mb']:7.0f} MB "
                  f"(baseline {r['baseline_mb']:.0f} MB), epoch "
                  f"{r['epoch_seconds']:.0f} s, loss {r['mean_loss']:.4f}",
                  flush=True)
    results['rows'] = rows
    results['same_loss'] = all(
        a['mean_loss'] == b['mean_loss'] for a, b in zip(rows[::2],
                                                          rows[1::2]))
    results['mb_per_1000_shapes'] = {arm: slope(rows, arm) for arm in ARMS}
    results['example_megabytes'] = results['database']['megabytes'] / \
        results['database']['shapes']
    os.makedirs(args.out, exist_ok=True)
    atomic_write_json(os.path.join(args.out, 'out_of_core.json'), results)
    plot(results, os.path.join(args.out, 'out_of_core.png'))
    print(json.dumps({k: results[k] for k in (
        'mb_per_1000_shapes', 'same_loss', 'preparation')}, indent=1))


def plot(results, path):
    import matplotlib
    matplotlib.use('Agg')
    import matplotlib.pyplot as plt
    rows = results['rows']
    fig, ax = plt.subplots(1, 2, figsize=(10, 3.8),
                           gridspec_kw={'width_ratios': [2, 1]})
    for arm, label in zip(ARMS, ('in memory (list)',
                                 'on disk (PrecomputedOnDisk)')):
        mine = [r for r in rows if r['arm'] == arm]
        ax[0].plot([r['size'] for r in mine], [r['peak_mb'] for r in mine],
                   'o-', label=f"{label}: "
                   f"{results['mb_per_1000_shapes'][arm]:.0f} MB / 1000")
    ax[0].set_xlabel('training shapes (1024 points, MLS operators k = 20)')
    ax[0].set_ylabel('peak resident memory of the epoch (MB)')
    ax[0].set_title('one DeltaNet training epoch')
    ax[0].grid(alpha=0.3)
    ax[0].legend()
    prep = results['preparation']
    ax[1].bar(['1 worker', '2 workers'],
              [prep['seconds']['1'], prep['seconds']['2']])
    ax[1].set_ylabel('seconds')
    ax[1].set_title(f"preparing {prep['shapes']} shapes "
                    f"({prep['speedup']:.2f}x)")
    fig.tight_layout()
    fig.savefig(path, dpi=120)
    plt.close(fig)


if __name__ == '__main__':
    main()
