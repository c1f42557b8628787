"""Benchmark: which views to keep (Wiersma et al., SIGGRAPH 2025, Fig. 5.8,
"guiding capture"): entropy and recovery error against the number of views,
for views chosen greedily by expected entropy reduction
(``SelectViews``) and for random ones.

Scene: an icosphere of 642 vertices with 'mixed' materials (roughness
0.2-0.8) under the scene generator's sun + sky (seed 1; and the first HDR
map of ``../shared/data/envmaps`` when present), seen by 50 candidate
cameras on a Fibonacci sphere. Every selection starts from camera 0 and
grows one view at a time, so the sets of the smaller counts are prefixes
of the larger ones:

- ``greedy``: ``SelectViews(max_views)`` once; the light band-limited for
  ``max_views`` during the selection, candidates' photos never read.
- ``random``: camera 0, then a random order of the others (several seeds:
  mean and spread).
- ``farthest``: camera 0, then the camera farthest (in direction) from
  those chosen: plain coverage, which needs no estimate at all.

For each count, the chosen views alone are recovered
(``FitSphericalHarmonics(l_max=5)`` with its default band limit for that
count, ``SpectralUncertainty``, ``FrequencySVBRDF.fit(solver='lm')``);
reported over the points the full 50-view capture sees: roughness MAE,
base colour RMSE, mean entropy, and for greedy the mean entropy it expected
before each view was taken.

Writes ``benchmarks/results/svbrdf_views.json`` and ``.png``.

    python benchmarks/svbrdf_views.py [--quick]
"""
import argparse
import os
import sys
import time

import matplotlib
import numpy as np
import torch

matplotlib.use('Agg')
import matplotlib.pyplot as plt  # noqa: E402

sys.path.insert(0, os.path.join(os.path.dirname(__file__), '..'))
from tg_intrinsic.datasets import svbrdf_scene  # noqa: E402
from tg_intrinsic.geometry.appearance.cameras import (  # noqa: E402
    camera_centers)
from tg_intrinsic.nn import FrequencySVBRDF  # noqa: E402
from tg_intrinsic.transforms import (FitSphericalHarmonics,  # noqa: E402
                                     SelectViews, SpectralUncertainty,
                                     keep_views)
from tg_intrinsic.utils import atomic_write, atomic_write_json  # noqa: E402
from tg_intrinsic.utils import machine_info  # noqa: E402

HERE = os.path.dirname(os.path.abspath(__file__))
sys.path.insert(0, HERE)
from svbrdf_accuracy import real_envmaps  # noqa: E402
METRICS = ('roughness_mae', 'base_color_rmse', 'mean_entropy')


def lightings(quick):
    maps = {'sun_sky (scene)': 'sun_sky'}
    if not quick:
        maps.update(list(real_envmaps().items())[:1])
    return maps


def farthest_views(data, num_views, first=0):
    """Camera 0, then greedily the camera whose direction is farthest from
    the chosen ones (coverage only)."""
    direction = camera_centers(data.extrinsics.double())
    direction = direction / direction.norm(dim=-1, keepdim=True)
    chosen = [first]
    distance = 1 - direction @ direction[first]
    for _ in range(num_views - 1):
        distance[chosen] = -1
        view = int(distance.argmax())
        chosen.append(view)
        distance = torch.minimum(distance, 1 - direction @ direction[view])
    return chosen


def random_views(num_total, num_views, seed, first=0):
    rng = np.random.default_rng(seed)
    others = [v for v in rng.permutation(num_total).tolist() if v != first]
    return [first] + others[:num_views - 1]


def evaluate(data, views, seen):
    kept = keep_views(data, views)
    prepared = SpectralUncertainty()(FitSphericalHarmonics(l_max=5)(kept))
    result = FrequencySVBRDF(data.num_nodes).fit(prepared, solver='lm',
                                                 progress=False)
    return {
        'roughness_mae': float((result.roughness - data.roughness)[seen]
                               .abs().mean()),
        'base_color_rmse': float(((result.base_color - data.base_color)[seen]
                                  ** 2).mean().sqrt()),
        'mean_entropy': float(prepared.entropy[seen].mean()),
        'points_seen': float(kept.obs_mask.any(1)[seen].double().mean()),
    }


def run_lighting(name, envmap, counts, random_seeds, num_candidates):
    data = svbrdf_scene('sphere', num_views=num_candidates,
                        materials='mixed', roughness_range=(0.2, 0.8),
                        resolution=3, render_images=False,
                        dtype=torch.float64, envmap=envmap, seed=1)
    seen = data.obs_mask.any(1)
    top = max(counts)
    start = time.perf_counter()
    greedy = SelectViews(top, seed_views=[0])(data)
    select_seconds = time.perf_counter() - start
    orders = {'greedy': greedy.view_index.tolist(),
              'farthest': farthest_views(data, top)}
    for seed in random_seeds:
        orders[f'random {seed}'] = random_views(num_candidates, top, seed)
    curves = {}
    for method, order in orders.items():
        curves[method] = []
        for k in counts:
            row = evaluate(data, order[:k], seen)
            row['views'] = k
            curves[method].append(row)
            print(f"{name:>16} {method:>10} {k:3d} views: rough MAE "
                  f"{row['roughness_mae']:.3f}  base RMSE "
                  f"{row['base_color_rmse']:.3f}  H "
                  f"{row['mean_entropy']:.3f}  seen "
                  f"{row['points_seen']:.2f}", flush=True)
    randoms = [curves[f'random {s}'] for s in random_seeds]
    summary = {'random_mean': [], 'random_std': []}
    for i, k in enumerate(counts):
        summary['random_mean'].append({key: float(np.mean(
            [c[i][key] for c in randoms])) for key in METRICS})
        summary['random_std'].append({key: float(np.std(
            [c[i][key] for c in randoms])) for key in METRICS})
    expected = greedy.selection_entropy.tolist()  # after 1, 2, ... views
    return {
        'envmap': name, 'orders': orders, 'curves': curves,
        'random': summary, 'select_seconds': select_seconds,
        'greedy_expected_mean_entropy': {
            str(k): expected[k - 1] for k in counts},
        # per count, is greedy at or below the random mean?
        'greedy_vs_random_mean': {
            key: [curves['greedy'][i][key]
                  - summary['random_mean'][i][key]
                  for i in range(len(counts))] for key in METRICS},
    }


def plot(runs, counts, path):
    fig, axes = plt.subplots(len(runs), 3, figsize=(14, 3.6 * len(runs)),
                             squeeze=False)
    for row, run in zip(axes, runs):
        for ax, key, title in zip(row, METRICS, (
                'roughness MAE', 'base colour RMSE', 'mean entropy')):
            mean = np.array([m[key] for m in run['random']['random_mean']])
            std = np.array([s[key] for s in run['random']['random_std']])
            ax.fill_between(counts, mean - std, mean + std, color='0.85')
            ax.plot(counts, mean, 'k--', label='random (mean, +-1 std)')
            for method, style in (('greedy', 'o-'), ('farthest', 's:')):
                ax.plot(counts, [r[key] for r in run['curves'][method]],
                        style, label=method)
            if key == 'mean_entropy':
                ax.plot(counts, [run['greedy_expected_mean_entropy'][str(k)]
                                 for k in counts], 'x-', color='C0',
                        alpha=0.5, label='greedy, expected')
            ax.set_xlabel('views')
            ax.set_title(f"{title}, {run['envmap']}", fontsize=9)
        row[0].legend(fontsize=8)
    fig.tight_layout()
    atomic_write(path, lambda f: fig.savefig(f, format='png', dpi=120), 'wb')


def main():
    parser = argparse.ArgumentParser()
    parser.add_argument('--quick', action='store_true')
    parser.add_argument('--candidates', type=int, default=50)
    parser.add_argument('--random-seeds', type=int, default=5)
    parser.add_argument('--out', default=os.path.join(HERE, 'results'))
    args = parser.parse_args()
    counts = (4, 8, 12) if args.quick else (4, 6, 8, 10, 13, 16, 20, 25)
    seeds = list(range(2 if args.quick else args.random_seeds))
    runs = [run_lighting(name, envmap, counts, seeds, args.candidates)
            for name, envmap in lightings(args.quick).items()]
    os.makedirs(args.out, exist_ok=True)
    atomic_write_json(os.path.join(args.out, 'svbrdf_views.json'), {
        'machine': machine_info(),
        'timings_note': 'select_seconds was taken pinned to one shared '
                        'core, under load from other processes',
        'quick': args.quick, 'candidates': args.candidates,
        'counts': list(counts), 'random_seeds': seeds,
        'scene': "icosphere 642 vertices, 'mixed' materials, roughness "
                 "0.2-0.8, seed 1",
        'recovery': "FitSphericalHarmonics(l_max=5), SpectralUncertainty, "
                    "FrequencySVBRDF.fit(solver='lm')",
        'runs': runs})
    plot(runs, counts, os.path.join(args.out, 'svbrdf_views.png'))


if __name__ == '__main__':
    main()
