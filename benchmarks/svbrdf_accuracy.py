"""Benchmark: accuracy and time of frequency-domain SVBRDF recovery against
ground truth that does not come from the method's own approximation.

Scene: an icosphere (642 vertices) of spatially varying metals, roughness
0.2-0.8, rendered by ``tg_intrinsic.geometry.appearance.lighting.render_radiance`` (the
full reflection integral: Lambert + GGX with Smith G and Schlick F,
multiple importance sampled over the environment map), seen by 10, 25, 50
and 100 cameras, under each HDR map in ``../shared/data/envmaps``
(area-downsampled to 128 x 256) and a procedural sun + sky.

Methods (all on the same observations), and ``constant 0.5`` (grey, half
metallic, roughness 0.5 everywhere: the baseline a recovery must beat):

- ``spectrum``: the grid search on power spectra alone (eq. 5.19; l* = 5),
  maps from its argmax.
- ``mixed``: gradient descent on eq. 5.11 (l* = 5) from constant 0.5.
- ``mixed+spectrum``: the same, initialised from the spectrum (the paper's
  method).
- ``split_sum+spectrum``: our variant: l* = 8 and the specular term as the
  exact GGX directional albedo times the prefiltered light in the dominant
  direction, initialised from the spectrum.
- ``..., metal known``: the last two with ``fit(metallic=1)``, for a
  capture known to be metal (the scene is all metal).
- ``default (recover)``: what ``tg-intrinsic svbrdf`` runs without flags,
  ``FrequencySVBRDF.recover``: SH fit and spectrum, then the refinement
  against the full integral (tables over roughness, the mesh's
  visibility), metallic recovered; checked against issue 32's goals
  (roughness MAE <= 0.04, base RMSE <= 0.06 on every run). Its
  uncertainty ``roughness_std`` is checked against the goal Spearman >=
  0.4 with the per-point roughness error, next to a reference: the
  Spearman of the spread of the roughness over refinements with 8 seeds
  of the tables' Monte Carlo samples (the default's own run and 7 more)
  against the same error, i.e. how far the part of the error that chance
  in those samples makes can be ranked at all (it costs 8 refinements;
  ``roughness_std`` comes from one).

Metrics over the points seen by at least one view: roughness MAE, base
colour RMSE, metallic MAE, wall time (SH fit + uncertainty + descent),
relighting PSNR (the recovered and true materials rendered by the same
independent renderer under a held-out environment map, from 24 novel
viewpoints; peak = the 99th percentile of the true radiance), and the
Spearman correlation between each uncertainty (the spectrum's entropy, the
fit's ``roughness_std``) and the per-point roughness error.

Writes ``benchmarks/results/svbrdf_accuracy.json`` and ``.png``.

    python benchmarks/svbrdf_accuracy.py [--quick] [--steps 300]
"""
import argparse
import inspect
import math
import os
import sys
import time

import matplotlib
import torch
from scipy.stats import spearmanr

matplotlib.use('Agg')
import matplotlib.pyplot as plt  # noqa: E402

sys.path.insert(0, os.path.join(os.path.dirname(__file__), '..'))
from tg_intrinsic.datasets import svbrdf_scene  # noqa: E402
from tg_intrinsic.geometry.appearance.cameras import look_at_cameras  # noqa
from tg_intrinsic.geometry.appearance.cameras import (  # noqa: E402
    camera_centers)
from tg_intrinsic.geometry.appearance.envmap import (  # noqa: E402
    downsample_envmap, sun_sky_envmap)
from tg_intrinsic.geometry.appearance.lighting import render_radiance  # noqa
from tg_intrinsic.geometry.appearance.raster import point_visibility  # noqa
from tg_intrinsic.geometry.appearance.sh import fibonacci_sphere  # noqa: E402
from tg_intrinsic.io import read_envmap  # noqa: E402
from tg_intrinsic.nn import FrequencySVBRDF  # noqa: E402
from tg_intrinsic.transforms import (FitSphericalHarmonics,  # noqa: E402
                                     SpectralUncertainty)
from tg_intrinsic.utils import atomic_write, atomic_write_json  # noqa: E402
from tg_intrinsic.utils import machine_info  # noqa: E402

HERE = os.path.dirname(os.path.abspath(__file__))
ENVMAPS = os.path.join(HERE, '..', '..', 'shared', 'data', 'envmaps')
DEFAULT = 'default (recover)'
METHODS = ('constant 0.5', 'spectrum', 'mixed', 'mixed+spectrum',
           'split_sum+spectrum', 'mixed+spectrum, metal known',
           'split_sum+spectrum, metal known', DEFAULT)
GOALS = {'roughness_mae': 0.05, 'base_color_rmse': 0.03}
# issue 32: the command's defaults, metallic recovered too
DEFAULT_GOALS = {'roughness_mae': 0.04, 'base_color_rmse': 0.06}
SPEARMAN_GOAL = 0.4  # issue 32: roughness_std against the roughness error
ENSEMBLE_SEEDS = 8


def real_envmaps(rows: int = 128) -> dict:
    """The HDR maps of ``shared/data/envmaps`` by name (``potsdamer_platz``,
    ...), box-downsampled to about ``rows`` rows, float64; empty (with a
    message) when the folder is missing. Shared by the SVBRDF benchmarks."""
    maps = {}
    if not os.path.isdir(ENVMAPS):
        print(f'{ENVMAPS} not found: only procedural maps are used')
        return maps
    for name in sorted(os.listdir(ENVMAPS)):
        if name.endswith(('.hdr', '.exr')):
            env = read_envmap(os.path.join(ENVMAPS, name))
            maps[name.split('_1k')[0].split('.')[0]] = downsample_envmap(
                env.double(), max(1, env.size(0) // rows))
    return maps


def load_envmaps(quick):
    maps = {'sun_sky': sun_sky_envmap(
        128, 256, sun_angular_radius=0.3, dtype=torch.float64)}
    maps.update(real_envmaps())
    if quick:
        maps = dict(list(maps.items())[:2])
    return maps


def novel_views(data, num_views=24, distance=2.75, seed=7):
    """Directions to 24 cameras on a randomly rotated Fibonacci sphere."""
    g = torch.Generator().manual_seed(seed)
    q, _ = torch.linalg.qr(torch.randn(3, 3, generator=g,
                                       dtype=torch.float64))
    direction = fibonacci_sphere(num_views).double() @ q.t()
    fov = 2 * math.degrees(math.asin(1 / distance)) * 1.1
    intrinsics, extrinsics = look_at_cameras(distance * direction,
                                             fov_degrees=fov)
    pos = data.pos.double()
    to_camera = camera_centers(extrinsics)[None] - pos[:, None]
    view_dirs = to_camera / to_camera.norm(dim=-1, keepdim=True)
    facing = (view_dirs * data.normal.double()[:, None]).sum(-1) > 0
    visible = point_visibility(pos, pos, data.face, intrinsics, extrinsics,
                               256, 256)
    return view_dirs, facing & visible


def relight(data, base_color, metallic, roughness, envmap, views):
    view_dirs, mask = views
    return render_radiance(
        data.normal.double(), base_color.double().clamp(0, 1),
        metallic.double().clamp(0, 1), roughness.double().clamp(0, 1),
        view_dirs, envmap, specular_samples=128, light_samples=128,
        mask=mask, seed=3)[mask]


def psnr(estimate, truth):
    peak = torch.quantile(truth.flatten(), 0.99)
    mse = ((estimate.clamp_max(peak) - truth.clamp_max(peak)) ** 2).mean()
    return float(10 * torch.log10(peak ** 2 / mse))


def run_one(data, envmap_name, views, heldout, heldout_truth, steps):
    rows = []
    seen = data.obs_mask.any(1)
    prepared = {}
    for l_max in (5, 8):
        start = time.perf_counter()
        prepared[l_max] = SpectralUncertainty()(
            FitSphericalHarmonics(l_max=l_max)(data.clone()))
        prepared[l_max].prep_seconds = time.perf_counter() - start
    for method in METHODS:
        prep = prepared[8 if method.startswith('split_sum') else 5]
        if method == 'constant 0.5':  # the baseline every map must beat
            half = torch.full((data.num_nodes, ), 0.5, dtype=torch.float64)
            maps = (half[:, None].expand(-1, 3), half, half)
            seconds = 0.0
            result = None
        elif method == DEFAULT:  # what 'tg-intrinsic svbrdf' runs
            start = time.perf_counter()
            result, prep = FrequencySVBRDF(data.num_nodes).recover(
                data.clone(), progress=False)
            maps = (result.base_color, result.metallic, result.roughness)
            seconds = time.perf_counter() - start
            seed_spread = seed_spread_spearman(prep, result, data, seen)
        elif method == 'spectrum':
            maps = (prep.init_base_color, prep.init_metallic,
                    prep.init_roughness)
            seconds = prep.prep_seconds
            result = None
        else:
            model = FrequencySVBRDF(
                data.num_nodes, specular_model='split_sum'
                if method.startswith('split_sum') else 'eq5.11')
            result = model.fit(
                prep, steps=steps, lr=0.02, tv_weight=0.02,
                init='constant' if method == 'mixed' else 'spectrum',
                metallic=1.0 if method.endswith('metal known') else None,
                progress=False)
            maps = (result.base_color, result.metallic, result.roughness)
            seconds = prep.prep_seconds + result.seconds
        base_color, metallic, roughness = (m.detach().double() for m in maps)
        rough_error = (roughness - data.roughness.double())[seen].abs()
        row = {
            'envmap': envmap_name, 'views': views, 'method': method,
            'roughness_mae': float(rough_error.mean()),
            'base_color_rmse': float(
                ((base_color - data.base_color.double())[seen] ** 2
                 ).mean().sqrt()),
            'metallic_mae': float(
                (metallic - data.metallic.double())[seen].abs().mean()),
            'seconds': seconds,
            'relight_psnr': psnr(relight(data, base_color, metallic,
                                         roughness, *heldout), heldout_truth),
            'spearman_entropy_roughness_error': float(spearmanr(
                prep.entropy[seen].numpy(), rough_error.numpy()
            ).correlation),
            'spearman_roughness_std_roughness_error': None
            if result is None else float(spearmanr(
                result.roughness_std[seen].numpy(), rough_error.numpy()
            ).statistic),
        }
        if method == DEFAULT:
            row['spearman_seed_spread'] = seed_spread
        rows.append(row)
        print(f"{envmap_name:>10} {views:3d} views {method:>32}: rough MAE "
              f"{row['roughness_mae']:.3f}  base RMSE "
              f"{row['base_color_rmse']:.3f}  metal MAE "
              f"{row['metallic_mae']:.3f}  PSNR {row['relight_psnr']:.1f} dB"
              f"  rho {row['spearman_entropy_roughness_error']:+.2f}"
              + ('' if result is None else f" / std "
                 f"{row['spearman_roughness_std_roughness_error']:+.2f}")
              + (f" (seed spread {seed_spread:+.2f})" if method == DEFAULT
                 else '')
              + f"  {seconds:.1f} s", flush=True)
    return rows


def seed_spread_spearman(prepared, result, data, seen) -> float:
    """Spearman of the per-point spread of the default's roughness over
    refinements with :data:`ENSEMBLE_SEEDS` seeds of the tables' samples
    (the default's own result first) against the default's roughness
    error: how far chance in those samples explains the error."""
    tv_weight = inspect.signature(FrequencySVBRDF.recover).parameters[
        'tv_weight'].default
    roughness = [result.roughness]  # seed 0
    for seed in range(1, ENSEMBLE_SEEDS):
        model = FrequencySVBRDF(data.num_nodes)
        model.initialize(prepared)
        roughness.append(model.refine(prepared, seed=seed,
                                      tv_weight=tv_weight,
                                      progress=False).roughness)
    spread = torch.stack(roughness).std(0)
    error = (result.roughness - data.roughness).abs()
    return float(spearmanr(spread[seen].numpy(),
                           error[seen].numpy()).statistic)


def plot(rows, envmaps, view_counts, path):
    fig, axes = plt.subplots(1, 3, figsize=(13, 3.8))
    for ax, key, title in ((axes[0], 'roughness_mae', 'roughness MAE'),
                           (axes[1], 'base_color_rmse', 'base colour RMSE'),
                           (axes[2], 'relight_psnr',
                            'relighting PSNR (dB), held-out light')):
        for method, style in zip(METHODS, ('k:', 'o:', 's--', '^-', 'D-',
                                           'v-.', 'P-.', '*-')):
            mean = [sum(r[key] for r in rows if r['method'] == method
                        and r['views'] == v) / len(envmaps)
                    for v in view_counts]
            ax.plot(view_counts, mean, style, label=method)
        if key in GOALS:
            ax.axhline(GOALS[key], color='k', lw=0.8, label='goal')
        ax.set_xscale('log')
        ax.set_xticks(view_counts, [str(v) for v in view_counts])
        ax.set_xlabel('views')
        ax.set_title(f'{title}, mean over {len(envmaps)} envmaps',
                     fontsize=9)
    axes[0].legend(fontsize=8)
    fig.tight_layout()
    atomic_write(path, lambda f: fig.savefig(f, format='png', dpi=120), 'wb')


def main():
    parser = argparse.ArgumentParser()
    parser.add_argument('--quick', action='store_true')
    parser.add_argument('--steps', type=int, default=300)
    parser.add_argument('--out', default=os.path.join(HERE, 'results'))
    args = parser.parse_args()
    torch.set_num_threads(os.cpu_count())
    envmaps = load_envmaps(args.quick)
    # compile the numba kernels (renderer, uncertainty) outside the timings
    small = svbrdf_scene('sphere', num_views=4, resolution=1,
                         render_images=False, dtype=torch.float64,
                         envmap=envmaps['sun_sky'])
    small = SpectralUncertainty()(FitSphericalHarmonics(l_max=5)(small))
    for model in ('eq5.11', 'split_sum'):
        FrequencySVBRDF(small.num_nodes, specular_model=model).fit(
            small, steps=2, progress=False)
    view_counts = (10, 25) if args.quick else (10, 25, 50, 100)
    names = list(envmaps)
    rows = []
    for index, (name, envmap) in enumerate(envmaps.items()):
        heldout_env = envmaps[names[(index + 1) % len(names)]]
        for views in view_counts:
            data = svbrdf_scene('sphere', num_views=views, materials='metals',
                                roughness_range=(0.2, 0.8), resolution=3,
                                render_images=False, dtype=torch.float64,
                                envmap=envmap, seed=1)
            heldout = (heldout_env, novel_views(data))
            truth = relight(data, data.base_color, data.metallic,
                            data.roughness, *heldout)
            rows.extend(run_one(data, name, views, heldout, truth,
                                args.steps))
    best = {}
    for method in METHODS:
        at_most = [r for r in rows if r['method'] == method
                   and r['views'] == max(view_counts)]
        best[method] = {
            key: sum(r[key] for r in at_most) / len(at_most)
            for key in ('roughness_mae', 'base_color_rmse', 'metallic_mae',
                        'relight_psnr', 'seconds',
                        'spearman_entropy_roughness_error',
                        'spearman_roughness_std_roughness_error')
            if at_most[0].get(key) is not None}
    goals = {key: {'goal': value, 'met_by': [
        f"{r['method']} / {r['envmap']} / {r['views']} views" for r in rows
        if r['method'] not in ('spectrum', 'constant 0.5', DEFAULT)
        and r[key] <= value]}
        for key, value in GOALS.items()}
    default_runs = [r for r in rows if r['method'] == DEFAULT]
    default_goals = {key: {'goal': value, 'missed_by': [
        f"{r['envmap']} / {r['views']} views ({r[key]:.3f})"
        for r in default_runs if r[key] > value], 'runs': len(default_runs)}
        for key, value in DEFAULT_GOALS.items()}
    default_uncertainty = {
        'goal': SPEARMAN_GOAL, 'runs': len(default_runs),
        'met_in': sum(r['spearman_roughness_std_roughness_error']
                      >= SPEARMAN_GOAL for r in default_runs),
        'seed_spread_met_in': sum(r['spearman_seed_spread']
                                  >= SPEARMAN_GOAL for r in default_runs),
        'ensemble_seeds': ENSEMBLE_SEEDS}
    os.makedirs(args.out, exist_ok=True)
    atomic_write_json(os.path.join(args.out, 'svbrdf_accuracy.json'), {
        'machine': machine_info(), 'quick': args.quick, 'steps': args.steps,
        'scene': 'icosphere 642 vertices, metals, roughness 0.2-0.8, seed 1',
        'held_out': 'next envmap in the list, 24 novel views',
        'rows': rows, f'mean_at_{max(view_counts)}_views': best,
        'goals': goals, 'default_goals': default_goals,
        'default_uncertainty': default_uncertainty})
    plot(rows, names, view_counts,
         os.path.join(args.out, 'svbrdf_accuracy.png'))


if __name__ == '__main__':
    main()
