"""Benchmark: ``tg-intrinsic svbrdf`` as the capture grows (issue 42's
capture size: 100 photographs of 1600 x 1200 of a 250k-vertex mesh in at
most 10 minutes and 8 GiB on 2 cores, with --texture 2048).

For every number of views and mesh size, the synthetic capture
(``svbrdf --write-example``: an icosphere of metals under a sun and sky) is
written as a COLMAP model of 8-bit JPEG-like PNG photographs, then recovered
with the defaults and ``--texture 2048`` in a fresh process; its
report.json gives each stage's seconds and the peak memory, and the maps
are scored against the ground truth.

Writes ``benchmarks/results/svbrdf_capture_size.json`` and
``svbrdf_capture_size.png``.

    python benchmarks/svbrdf_capture_size.py [--views 25 50 100]
        [--subdivisions 5 6] [--image-size 300 400]
"""
import argparse
import json
import os
import subprocess
import sys
import tempfile
import time

import matplotlib

matplotlib.use('Agg')
import matplotlib.pyplot as plt  # noqa: E402

sys.path.insert(0, os.path.join(os.path.dirname(__file__), '..'))
from tg_intrinsic.utils import (atomic_write, atomic_write_json,  # noqa: E402
                                machine_info)

RESULTS = os.path.join(os.path.dirname(os.path.abspath(__file__)), 'results')
COMMAND = [sys.executable, '-m', 'tg_intrinsic']
# the goals
GOAL_SECONDS, GOAL_GIB = 600, 8


def run_one(work: str, views: int, subdivisions: int, size) -> dict:
    capture = os.path.join(work, f'v{views}_s{subdivisions}')
    start = time.perf_counter()
    written = subprocess.run(
        COMMAND + ['svbrdf', '--write-example', capture, '--format',
                   'colmap', '--ldr', '--example-views', str(views),
                   '--example-image-size', str(size[0]),
                   '--example-subdivisions', str(subdivisions)],
        capture_output=True, text=True, check=True)
    write_seconds = time.perf_counter() - start
    # the example prints the command that recovers it, with --exposure
    line = written.stdout.strip().splitlines()[-1].split('next: ')[1]
    exposure = line.split('--exposure ')[1].split()[0]
    out = os.path.join(work, f'out_v{views}_s{subdivisions}')
    start = time.perf_counter()
    subprocess.run(COMMAND + ['svbrdf', capture, '--exposure', exposure,
                              '--texture', '2048', '--out', out, '--quiet'],
                   check=True)
    wall = time.perf_counter() - start
    report = json.loads(open(os.path.join(out, 'report.json')).read())
    return {'views': views, 'points': report['points'],
            'image_size': report['image_size'],
            'wall_s': round(wall, 2), 'write_example_s': round(write_seconds,
                                                               2),
            'seconds': report['seconds'],
            'peak_memory_gib': report['peak_memory_gib'],
            'pixels_left_out': report['capture']['pixels_left_out'],
            'ground_truth': report['ground_truth']}


def plot(runs, path):
    fig, axes = plt.subplots(1, 2, figsize=(10, 4))
    for points in sorted({r['points'] for r in runs}):
        rows = sorted((r for r in runs if r['points'] == points),
                      key=lambda r: r['views'])
        views = [r['views'] for r in rows]
        axes[0].plot(views, [r['wall_s'] for r in rows], 'o-',
                     label=f'{points:,} points')
        axes[1].plot(views, [r['peak_memory_gib'] for r in rows], 'o-',
                     label=f'{points:,} points')
    axes[0].set_ylabel('seconds (recovery, --texture 2048)')
    axes[1].set_ylabel('peak memory (GiB)')
    for ax in axes:
        ax.set_xlabel('views')
        ax.legend()
        ax.grid(alpha=0.3)
    size = runs[0]['image_size']
    fig.suptitle(f"svbrdf on 2 CPU cores as the capture grows "
                 f"({size[0]} x {size[1]} photographs, COLMAP, 8-bit)")
    fig.tight_layout()
    atomic_write(path, lambda f: fig.savefig(f, format='png', dpi=110),
                 'wb')


def main():
    parser = argparse.ArgumentParser(description=__doc__.split('\n')[0])
    parser.add_argument('--views', type=int, nargs='+', default=[25, 50])
    parser.add_argument('--subdivisions', type=int, nargs='+',
                        default=[5, 6], help='icosphere subdivisions: 5 '
                        'gives 10,242 points, 6 40,962, 7 163,842')
    parser.add_argument('--image-size', type=int, default=300,
                        help='side of the square photographs (the issue: '
                        '1600 x 1200)')
    args = parser.parse_args()
    runs = []
    with tempfile.TemporaryDirectory(prefix='capture-size-') as work:
        for subdivisions in args.subdivisions:
            for views in args.views:
                run = run_one(work, views, subdivisions,
                              (args.image_size, args.image_size))
                print(json.dumps({k: run[k] for k in (
                    'views', 'points', 'wall_s', 'peak_memory_gib')}),
                    flush=True)
                runs.append(run)
    os.makedirs(RESULTS, exist_ok=True)
    atomic_write_json(os.path.join(RESULTS, 'svbrdf_capture_size.json'), {
        'machine': machine_info(), 'goal': {
            'views': 100, 'image_size': [1200, 1600], 'points': 250000,
            'seconds': GOAL_SECONDS, 'peak_memory_gib': GOAL_GIB},
        'runs': runs})
    plot(runs, os.path.join(RESULTS, 'svbrdf_capture_size.png'))


if __name__ == '__main__':
    main()
