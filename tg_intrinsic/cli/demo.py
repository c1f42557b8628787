"""Shows all four methods on data generated on the spot, and writes what
they did to one folder: summary.json, a readable summary.md and PNG
figures.

1. DeltaConv: a small DeltaNet trained on SyntheticModelNet point clouds,
   and a Harmonic Surface Network on SyntheticSHREC meshes in random poses,
   each next to trivial baselines (nearest centroid on bounding-box
   extents; for the meshes also on the Laplacian spectrum, Shape-DNA).
2. Gravo MG: a hierarchy on a generated bumpy torus (204,800 vertices;
   12,800 with --quick), implicit smoothing of a noisy signal and a
   screened Poisson problem with a known solution, next to scipy's direct
   solve and pyamg (smoothed aggregation + CG) on the same systems.
3. Frequency-domain SVBRDF recovery: a synthetic capture of a sphere of
   metals rendered by an independent renderer, recovered from its images
   with an uncertainty per point; errors against the ground truth and the
   correlation of entropy with the error.

On a 2-core CPU the demo takes a few minutes (--quick: under a minute, a
smoke test that every method runs and learns); the synthetic data sets
are cached under --root.
"""
import os
import time

import numpy as np

HELP = 'run all four methods on generated data; figures and a summary'
EXAMPLE = """examples:
  tg-intrinsic demo                      # writes runs/demo/summary.md, figures
  tg-intrinsic demo --quick --out /tmp/d # smaller everything, under a minute
  tg-intrinsic demo --only gravo svbrdf  # some parts only
"""

PARTS = ('deltanet', 'hsn', 'gravo', 'svbrdf')

# The training recipe of the demo (not a paper protocol): Adam with a cosine
# schedule, small models, few epochs.
RECIPE = dict(
    deltanet=['--optimizer', 'adam', '--schedule', 'cosine',
              '--weight-decay', '1e-4', '--label-smoothing', '0',
              '--scale', '0.667', '1.5', '--no-anisotropic', '--translate',
              '0', '--rotate', 'none'],
    hsn=['--optimizer', 'adam', '--schedule', 'cosine', '--weight-decay',
         '1e-4', '--scale', '1', '1', '--rotate', 'so3'])
# Sizes of each part, full and --quick. Chosen so the full demo stays
# under 10 minutes and --quick under 2 on a 2-core CPU (measured: see
# README); the quick mode is the suite's smoke test, not a result.
SETTINGS = {
    False: dict(
        deltanet=['--num-points', '256', '--shapes-per-class', '20',
                  '--epochs', '10', '--conv-channels', '32', '32', '64',
                  '--k', '16', '--batch-size', '8', '--lr', '3e-3',
                  '--lr-min', '3e-5'],
        hsn=['--num-vertices', '300', '400', '--shapes-per-class', '16',
             '--epochs', '16', '--lr', '1e-2', '--lr-min', '1e-4',
             '--batch-size', '8'],
        torus_vertices=204800,
        svbrdf=dict(resolution=3, num_views=50, image_size=(128, 128),
                    samples=32)),
    True: dict(
        # chosen so that each network learns within seconds (measured:
        # DeltaNet 50-67% over 3 seeds against 32% for the bounding boxes,
        # in about 11 s of training; HSN 75% against 19% and chance 8%, in
        # about 20 s, while the Laplacian spectrum reaches 85% on 8 shapes
        # per class: HSN passes it only with the full demo's data)
        deltanet=['--num-points', '256', '--shapes-per-class', '10',
                  '--epochs', '8', '--conv-channels', '16', '16',
                  '--k', '12', '--batch-size', '8', '--lr', '3e-3',
                  '--lr-min', '1e-5'],
        hsn=['--num-vertices', '150', '200', '--shapes-per-class', '8',
             '--epochs', '16', '--lr', '2e-2', '--lr-min', '1e-4',
             '--batch-size', '8', '--hsn-channels', '8', '16'],
        torus_vertices=12800,
        svbrdf=dict(resolution=3, num_views=24, image_size=(96, 96),
                    samples=16)),
}


def add_arguments(parser):
    parser.add_argument('--out', default=os.path.join('runs', 'demo'),
                        help='output folder (default: runs/demo); the '
                        'results replace those of an earlier demo there '
                        'only once all of them are written')
    parser.add_argument('--overwrite', action='store_true',
                        help='write into --out even when it holds files '
                        'the demo did not write (they are kept)')
    parser.add_argument('--root', default='data',
                        help='cache folder of the synthetic data sets '
                        '(default: data)')
    parser.add_argument('--quick', action='store_true',
                        help='smaller data and fewer epochs (under a minute; '
                        'a smoke test that every method runs and learns, not '
                        'results)')
    parser.add_argument('--only', nargs='+', choices=PARTS, default=None,
                        metavar='PART',
                        help=f"run only these parts: {', '.join(PARTS)}")


# ------------------------------------------------------------ baselines


def nearest_centroid(train_x, train_y, test_x, test_y) -> float:
    """Accuracy of a nearest-centroid classifier on standardised
    features: the trivial baseline the networks are shown against."""
    mean, std = train_x.mean(0), train_x.std(0) + 1e-12
    train_x, test_x = (train_x - mean) / std, (test_x - mean) / std
    classes = np.unique(train_y)
    centroids = np.stack([train_x[train_y == c].mean(0) for c in classes])
    dist = ((test_x[:, None] - centroids[None]) ** 2).sum(-1)
    return float((classes[dist.argmin(1)] == test_y).mean())


def bounding_box_features(pos) -> np.ndarray:
    """Sorted, normalised bounding-box extents: a pose-dependent, purely
    extrinsic description of a shape."""
    extent = (pos.max(0).values - pos.min(0).values).sort().values
    return (extent / extent.norm()).numpy()


def baseline_accuracies(train_set, test_set, spectrum: bool) -> dict:
    from tg_intrinsic.geometry import laplacian_spectrum
    features = {}
    for split, dataset in (('train', train_set), ('test', test_set)):
        box, dna, label = [], [], []
        for data in dataset:
            box.append(bounding_box_features(data.pos))
            if spectrum:
                dna.append(np.log(laplacian_spectrum(data.pos, data.face,
                                                     12).numpy()))
            label.append(int(data.y.view(-1)[0]))
        features[split] = (np.stack(box), np.stack(dna) if spectrum else
                           None, np.array(label))
    (box_tr, dna_tr, y_tr), (box_te, dna_te, y_te) = features['train'], \
        features['test']
    out = {'bounding_box_nearest_centroid': nearest_centroid(
        box_tr, y_tr, box_te, y_te)}
    if spectrum:
        out['shape_dna_nearest_centroid'] = nearest_centroid(
            dna_tr, y_tr, dna_te, y_te)
    out['chance'] = 1.0 / len(np.unique(y_tr))
    return out


# ------------------------------------------------------------ the parts


def learning_part(model: str, args, out: str) -> dict:
    """Trains ``model`` with the library's training loop and compares it
    with the baselines on the same test shapes."""
    from tg_intrinsic.training.loop import train
    from tg_intrinsic.training.options import parse_args
    from tg_intrinsic.training.sources import source_splits
    from tg_intrinsic.io.figures import line_figure
    dataset = 'synthetic_modelnet' if model == 'deltanet' else \
        'synthetic_shrec'
    argv = ['--model', model, '--dataset', dataset, '--root', args.root,
            '--out', os.path.join(out, model), '--eval-every', '1',
            *RECIPE[model], *SETTINGS[args.quick][model]]
    if args.quiet:
        argv.append('--quiet')
    options = parse_args(argv)
    metrics = train(options)
    # The shapes the network saw, without its prepared inputs.
    train_set, test_set = source_splits(options)
    baselines = baseline_accuracies(train_set, test_set,
                                    spectrum=model == 'hsn')
    history = metrics['history']
    epochs = [h['epoch'] for h in history]
    names = {'bounding_box_nearest_centroid': 'bounding box, nearest '
             'centroid', 'shape_dna_nearest_centroid': 'Laplacian spectrum '
             '(Shape-DNA), nearest centroid', 'chance': 'chance'}
    styles = {'bounding_box_nearest_centroid': '--',
              'shape_dna_nearest_centroid': '-.', 'chance': ':'}
    title = ('DeltaNet on SyntheticModelNet point clouds' if model ==
             'deltanet' else 'HSN on SyntheticSHREC meshes, random poses')
    figure = line_figure(
        os.path.join(out, f'{model}_learning_curve.png'),
        [('train', epochs, [h['train_accuracy'] for h in history], 'o-'),
         ('test', epochs, [h['test_accuracy'] for h in history], 's-')],
        title, 'epoch', 'accuracy', integer_x=True, ylim=(0, 1.02),
        hlines=[(f'{names[k]} (test)', v, styles[k])
                for k, v in baselines.items()])
    return {'model': model, 'dataset': dataset,
            'train_shapes': len(train_set), 'test_shapes': len(test_set),
            'classes': int(train_set.num_classes),
            'parameters': metrics['parameters'], 'epochs': len(history),
            'test_accuracy': metrics['final_test_accuracy'],
            'best_test_accuracy': metrics['best_test_accuracy'],
            'baselines': baselines,
            'train_seconds': round(history[-1]['seconds'], 1),
            'figures': [os.path.basename(figure)],
            'run_folder': model}  # relative to the demo's folder


def _pyamg_solve(A, b, tol):
    """pyamg's smoothed aggregation as a CG preconditioner: solution,
    relative residuals per iteration and their times (setup included)."""
    import pyamg
    start = time.perf_counter()
    ml = pyamg.smoothed_aggregation_solver(A)
    setup = time.perf_counter() - start
    times = []
    residuals = []
    x = ml.solve(b, tol=tol, accel='cg', residuals=residuals,
                 callback=lambda _: times.append(time.perf_counter() -
                                                 start))
    total = time.perf_counter() - start
    norm = np.linalg.norm(b)
    relative = [float(r / norm) for r in residuals[1:]]
    return x, relative, times[:len(relative)], setup, total


def _direct_solve(A, b):
    import scipy.sparse.linalg as sla
    start = time.perf_counter()
    x = sla.spsolve(A.tocsc(), b)
    return x, time.perf_counter() - start


def gravo_part(args, out: str, say) -> dict:
    """Gravo MG on a large generated surface, next to scipy and pyamg."""
    import scipy.sparse as sp
    from tg_intrinsic.datasets import bumpy_torus
    from tg_intrinsic.io.figures import draw_surface, line_figure
    from tg_intrinsic.solvers import GravoMG, stiffness_and_mass
    from tg_intrinsic.transforms import GravoHierarchy
    tol = 1e-8
    surface = bumpy_torus(SETTINGS[args.quick]['torus_vertices'])
    n = surface.pos.size(0)
    say(f"bumpy torus: {n:,} vertices, {surface.face.size(1):,} triangles")
    start = time.perf_counter()
    S, mass = stiffness_and_mass(surface)
    assembly_seconds = time.perf_counter() - start
    start = time.perf_counter()
    hierarchy = GravoHierarchy()(surface)
    solver = GravoMG.from_data(hierarchy)
    hierarchy_seconds = time.perf_counter() - start
    levels = [n] + [hierarchy[f'pos_{k}'].size(0)
                    for k in range(1, 20) if f'pos_{k}' in hierarchy]
    say(f"cotan Laplacian and masses in {assembly_seconds:.1f} s; "
        f"hierarchy (once per surface): levels {levels} in "
        f"{hierarchy_seconds:.1f} s")
    u, v = surface.uv[:, 0].numpy(), surface.uv[:, 1].numpy()
    clean = np.sin(3 * u) * np.cos(2 * v)
    noisy = clean + 0.3 * np.random.default_rng(0).standard_normal(n)
    M = sp.diags(mass)
    alpha = 2e-3
    problems = {
        # (M + alpha S) x = M y: the noisy signal, smoothed
        'smoothing': ((M + alpha * S).tocsr(), mass * noisy, None),
        # (S + eta M) x = b with b made from a known x*
        'poisson': None}
    eta = 1e-2
    A_poisson = (S + eta * M).tocsr()
    exact = np.cos(u + 0.5) * np.sin(3 * v) + 0.5 * np.sin(2 * u)
    problems['poisson'] = (A_poisson, A_poisson @ exact, exact)
    results = {}
    curves = {}
    for name, (A, b, known) in problems.items():
        say(f"{name}: Gravo MG (V-cycles to relative residual {tol:g})")
        x = solver.solve(A, b, tol=tol)
        info = solver.info
        say(f"{name}: scipy direct solve (SuperLU)")
        x_direct, direct_seconds = _direct_solve(A, b)
        say(f"{name}: pyamg smoothed aggregation + CG")
        x_amg, amg_residuals, amg_times, amg_setup, amg_seconds = \
            _pyamg_solve(A, b, tol)
        entry = {
            'gravo': {'cycles': info.iterations,
                      'relative_residual': info.residuals[-1],
                      'converged': info.converged,
                      'setup_seconds': round(info.setup_time, 3),
                      'solve_seconds': round(info.solve_time, 3),
                      'seconds_with_hierarchy': round(
                          hierarchy_seconds + info.setup_time +
                          info.solve_time, 3),
                      'max_difference_to_direct': float(
                          np.abs(x - x_direct).max())},
            'scipy_direct': {'seconds': round(direct_seconds, 3),
                             'relative_residual': float(
                                 np.linalg.norm(b - A @ x_direct) /
                                 np.linalg.norm(b))},
            'pyamg_sa_cg': {'iterations': len(amg_residuals),
                            'relative_residual': amg_residuals[-1],
                            'setup_seconds': round(amg_setup, 3),
                            'seconds': round(amg_seconds, 3),
                            'max_difference_to_direct': float(
                                np.abs(x_amg - x_direct).max())}}
        if known is not None:
            entry['gravo']['max_error_to_known_solution'] = float(
                np.abs(x - known).max() / np.abs(known).max())
        else:
            entry['noise_rms_before'] = float(np.sqrt(np.mean(
                (noisy - clean) ** 2)))
            entry['noise_rms_after'] = float(np.sqrt(np.mean(
                (x - clean) ** 2)))
            smoothed = x
        results[name] = entry
        curves[name] = (info.residuals, info.times, amg_residuals, amg_times,
                        direct_seconds)
    figures = []
    series_cycles, series_time = [], []
    for name, (g_res, g_time, a_res, a_time, direct) in curves.items():
        series_cycles += [(f'Gravo MG, {name}', range(1, len(g_res) + 1),
                           g_res, 'o-'),
                          (f'pyamg SA + CG, {name}',
                           range(1, len(a_res) + 1), a_res, 'x--')]
        series_time += [(f'Gravo MG, {name} (after the hierarchy)',
                         g_time, g_res, 'o-'),
                        (f'pyamg SA + CG, {name} (incl. setup)',
                         a_time, a_res, 'x--')]
    figures.append(line_figure(
        os.path.join(out, 'gravo_residual_vs_cycles.png'), series_cycles,
        f'Residual per iteration, bumpy torus ({n:,} vertices)',
        'cycles (Gravo) / CG iterations (pyamg)',
        'relative residual |b - Ax| / |b|', logy=True, integer_x=True))
    figures.append(line_figure(
        os.path.join(out, 'gravo_residual_vs_time.png'), series_time,
        f'Residual against time, bumpy torus ({n:,} vertices)',
        'seconds', 'relative residual |b - Ax| / |b|', logy=True,
        vlines=[(f'scipy direct solve, {name}', curves[name][4], style)
                for name, style in (('smoothing', ':'),
                                    ('poisson', '-.'))]))
    limits = dict(vmin=float(noisy.min()), vmax=float(noisy.max()))
    for key, values, label in (('noisy', noisy, 'noisy signal'),
                               ('smoothed', smoothed,
                                f'smoothed, (M + {alpha:g} S) x = M y')):
        figures.append(draw_surface(
            os.path.join(out, f'gravo_{key}_signal.png'), surface.pos,
            surface.face, values=values, cmap='coolwarm',
            title=f'{label}, solved with Gravo MG on {n:,} vertices',
            label='signal value (unitless)', **limits))
    return {'vertices': n, 'triangles': int(surface.face.size(1)),
            'levels': levels, 'assembly_seconds': round(assembly_seconds, 3),
            'hierarchy_seconds': round(hierarchy_seconds, 3),
            'tolerance': tol, 'alpha': alpha, 'eta': eta,
            'problems': results,
            'figures': [os.path.basename(f) for f in figures]}


def svbrdf_part(args, out: str, say) -> dict:
    """Frequency-domain SVBRDF recovery with uncertainty on a synthetic
    capture whose ground truth comes from an independent renderer."""
    import torch
    from scipy.stats import spearmanr
    from tg_intrinsic.datasets import svbrdf_scene
    from tg_intrinsic.io.figures import draw_surface
    from tg_intrinsic.nn import FrequencySVBRDF
    setting = SETTINGS[args.quick]['svbrdf']
    start = time.perf_counter()
    say(f"rendering {setting['num_views']} views of a sphere of metals "
        f"(independent renderer, sun and sky)")
    # seed 1: the scene of benchmarks/svbrdf_accuracy.py
    scene = svbrdf_scene('sphere', num_views=setting['num_views'],
                         image_size=setting['image_size'],
                         materials='metals', resolution=setting['resolution'],
                         image_specular_samples=setting['samples'],
                         image_light_samples=setting['samples'],
                         dtype=torch.float64, seed=1)
    render_seconds = time.perf_counter() - start
    start = time.perf_counter()
    # the command's default pipeline (tg-intrinsic svbrdf): projection,
    # harmonic fits, spectrum and entropy, then the refinement
    model = FrequencySVBRDF(scene.num_nodes)
    result, data = model.recover(scene, progress=not args.quiet)
    fit_seconds = time.perf_counter() - start
    rough_error = (result.roughness - scene.roughness).abs()
    base_error = (result.base_color - scene.base_color)
    constant_rough = float((0.5 - scene.roughness).abs().mean())
    constant_base = float((0.5 - scene.base_color).pow(2).mean().sqrt())
    seen = data.obs_mask.sum(1)
    rho = spearmanr(result.entropy.numpy(), rough_error.numpy())
    figures = []
    pos, face = scene.pos, scene.face
    for key, values, title, label, cmap, limits in (
            ('roughness_truth', scene.roughness, 'ground-truth roughness',
             'roughness (unitless, 0-1)', 'viridis', (0, 1)),
            ('roughness_recovered', result.roughness, 'recovered roughness',
             'roughness (unitless, 0-1)', 'viridis', (0, 1)),
            ('entropy', result.entropy, 'uncertainty: normalised entropy of '
             'the spectral fit', 'entropy (0 certain - 1 uniform)', 'turbo',
             (0, 1)),
            ('roughness_error', rough_error, 'roughness error |recovered - '
             'truth|', 'absolute error (roughness units)', 'magma',
             (0, None))):
        figures.append(draw_surface(
            os.path.join(out, f'svbrdf_{key}.png'), pos, face,
            values=values.numpy(), title=title, label=label, cmap=cmap,
            vmin=limits[0], vmax=limits[1]))
    for key, colors, title in (
            ('base_color_truth', scene.base_color, 'ground-truth base '
             'colour'),
            ('base_color_recovered', result.base_color,
             'recovered base colour')):
        figures.append(draw_surface(
            os.path.join(out, f'svbrdf_{key}.png'), pos, face,
            colors=colors.numpy(), title=title))
    return {'points': int(data.num_nodes), 'views': setting['num_views'],
            'image_size': list(setting['image_size']),
            'observations_per_point': {'min': int(seen.min()),
                                       'median': float(seen.float().median()),
                                       'max': int(seen.max())},
            'model': 'FrequencySVBRDF.recover with its defaults (as '
                     'tg-intrinsic svbrdf)',
            'roughness_mae': float(rough_error.mean()),
            'base_color_rmse': float(base_error.pow(2).mean().sqrt()),
            'constant_0.5_roughness_mae': constant_rough,
            'constant_0.5_base_color_rmse': constant_base,
            'mean_entropy': float(result.entropy.mean()),
            'spearman_entropy_vs_roughness_error': float(rho.statistic),
            'render_seconds': round(render_seconds, 2),
            'recovery_seconds': round(fit_seconds, 2),
            'figures': [os.path.basename(f) for f in figures]}


# ------------------------------------------------------------ reporting


#: what --quick's numbers are, said in its summary
QUICK_NOTE = ('--quick: small data and few epochs, a smoke test that every '
              'method runs and learns, not results; the full demo (without '
              '--quick) and benchmarks/ give the numbers to quote.')


def markdown(summary: dict) -> str:
    """The summary as a page a person reads first."""
    lines = ['# tg_intrinsic demo', '',
             f"Mode: {'quick' if summary['quick'] else 'full'}; "
             f"{summary['seconds']:.0f} s on {summary['machine']['cpu_count']}"
             f" CPU cores ({summary['machine']['platform']}).", '']
    if summary['quick']:
        lines += [QUICK_NOTE, '']
    for model in ('deltanet', 'hsn'):
        part = summary.get(model)
        if not part:
            continue
        name = {'deltanet': 'DeltaConv: DeltaNet on SyntheticModelNet point '
                'clouds', 'hsn': 'Harmonic Surface Network on SyntheticSHREC '
                'meshes in random poses'}[model]
        lines += [f'## {name}', '',
                  f"{part['classes']} classes, {part['train_shapes']} "
                  f"training / {part['test_shapes']} test shapes, "
                  f"{part['parameters']:,} parameters, {part['epochs']} "
                  f"epochs in {part['train_seconds']:.0f} s.", '',
                  '| classifier | test accuracy |', '|---|---|',
                  f"| {model} (last epoch) | {part['test_accuracy']:.1%} |"]
        for key, value in part['baselines'].items():
            lines.append(f"| {key.replace('_', ' ')} | {value:.1%} |")
        lines += ['', f"![learning curve]({part['figures'][0]})", '']
    part = summary.get('gravo')
    if part:
        lines += ['## Gravo MG', '',
                  f"Bumpy torus, {part['vertices']:,} vertices; hierarchy "
                  f"{part['levels']} built once in "
                  f"{part['hierarchy_seconds']:.1f} s (the cotan Laplacian "
                  f"in {part['assembly_seconds']:.1f} s, for all solvers); "
                  f"tolerance {part['tolerance']:g} (relative residual); "
                  f"setup is per matrix.", '',
                  '| problem | solver | iterations | relative residual | '
                  'seconds |', '|---|---|---|---|---|']
        for name, entry in part['problems'].items():
            g, d, a = entry['gravo'], entry['scipy_direct'], \
                entry['pyamg_sa_cg']
            lines += [
                f"| {name} | Gravo MG | {g['cycles']} cycles | "
                f"{g['relative_residual']:.1e} | {g['solve_seconds']:.2f} "
                f"(+ {g['setup_seconds']:.2f} setup) |",
                f"| {name} | scipy direct (SuperLU) | - | "
                f"{d['relative_residual']:.1e} | {d['seconds']:.2f} |",
                f"| {name} | pyamg SA + CG | {a['iterations']} | "
                f"{a['relative_residual']:.1e} | {a['seconds']:.2f} "
                f"(with setup) |"]
        smoothing = part['problems']['smoothing']
        poisson = part['problems']['poisson']
        lines += ['', f"Smoothing (alpha = {part['alpha']:g}) lowers the "
                  f"noise from RMS {smoothing['noise_rms_before']:.3f} to "
                  f"{smoothing['noise_rms_after']:.3f}; the Poisson solution "
                  f"(eta = {part['eta']:g}) matches the known one to "
                  f"{poisson['gravo']['max_error_to_known_solution']:.1e} "
                  f"(max relative).", '']
        lines += [f'![{f}]({f})' for f in part['figures']] + ['']
    part = summary.get('svbrdf')
    if part:
        obs = part['observations_per_point']
        lines += ['## Frequency-domain SVBRDF recovery', '',
                  f"Sphere of {part['points']} points, metals, "
                  f"{part['views']} views of {part['image_size'][0]} x "
                  f"{part['image_size'][1]} pixels (seen by {obs['min']}-"
                  f"{obs['max']} views per point); {part['model']}; "
                  f"rendering {part['render_seconds']:.0f} s, recovery "
                  f"{part['recovery_seconds']:.0f} s.", '',
                  '| | roughness MAE | base colour RMSE |', '|---|---|---|',
                  f"| recovered | {part['roughness_mae']:.3f} | "
                  f"{part['base_color_rmse']:.3f} |",
                  f"| constant 0.5 | {part['constant_0.5_roughness_mae']:.3f}"
                  f" | {part['constant_0.5_base_color_rmse']:.3f} |", '',
                  f"Entropy against per-point roughness error: Spearman "
                  f"{part['spearman_entropy_vs_roughness_error']:+.2f} "
                  f"(mean entropy {part['mean_entropy']:.2f}).", '']
        lines += [f'![{f}]({f})' for f in part['figures']] + ['']
    return '\n'.join(lines)


def run(args):
    from tg_intrinsic.io.results import result_folder
    parts = args.only or list(PARTS)
    with result_folder(args.out, 'demo', args.overwrite,
                       inputs=[args.root]) as staging:
        summary = _run_parts(args, parts, staging)
    print('\n'.join(line for line in markdown(summary).split('\n')[2:]
                    if not line.startswith('![')))
    print(f"Wrote {os.path.join(args.out, 'summary.md')}, summary.json and "
          f"{sum(len(summary[p]['figures']) for p in parts)} figures to "
          f"{os.path.abspath(args.out)} in {summary['seconds']:.0f} s")
    return 0


def _run_parts(args, parts, out: str) -> dict:
    """Runs the demo's ``parts`` writing into ``out``; the summary."""
    import torch
    from tg_intrinsic.utils import atomic_write, atomic_write_json, \
        machine_info
    torch.manual_seed(0)
    summary = {'quick': args.quick, 'parts': parts,
               'machine': machine_info()}
    started = time.perf_counter()

    def say(text):
        if not args.quiet:
            print(f'  {text}', flush=True)

    titles = {'deltanet': 'DeltaConv: training DeltaNet',
              'hsn': 'Harmonic Surface Networks: training HSN',
              'gravo': 'Gravo MG: multigrid on a large surface',
              'svbrdf': 'Frequency-domain SVBRDF recovery'}
    for index, part in enumerate(parts, 1):
        print(f"[{index}/{len(parts)}] {titles[part]}", flush=True)
        begin = time.perf_counter()
        if part in ('deltanet', 'hsn'):
            summary[part] = learning_part(part, args, out)
        elif part == 'gravo':
            summary[part] = gravo_part(args, out, say)
        else:
            summary[part] = svbrdf_part(args, out, say)
        summary[part]['part_seconds'] = round(time.perf_counter() - begin, 1)
    summary['seconds'] = round(time.perf_counter() - started, 1)
    atomic_write_json(os.path.join(out, 'summary.json'), summary)
    atomic_write(os.path.join(out, 'summary.md'),
                 lambda f: f.write(markdown(summary)), 'w')
    return summary
