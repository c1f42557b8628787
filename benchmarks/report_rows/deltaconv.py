"""Rows of DeltaConv: neighbours, normals, the generated data sets, the
operators' and the training's speed, DeltaNet's accuracy, part
segmentation and Perona-Malik diffusion."""
import math
import sys
from typing import Dict, List, Sequence

from .common import (ROOT, f1, pair, pct, rows_for, sci, seconds, sig, span,
                     span_times, thousands, times)


@rows_for('neighbors')
def neighbors(d, _):
    rows = d['results']
    single = [r for r in rows if r['batch'] == '1 cloud']
    batched = [r for r in rows if r['batch'] != '1 cloud']
    ops = []
    for op in dict.fromkeys(r['op'] for r in single):
        these = [r for r in single if r['op'] == op]
        ops.append(f"{op} {span_times([r['speedup'] for r in these])} "
                   f"({span([r['n'] for r in these], thousands)} points)")
    ops = ', '.join(ops)
    extrapolated = sorted({(r['n'], r['baseline_extrapolated_from_rows'])
                           for r in single
                           if r.get('baseline_extrapolated_from_rows')})
    note = ''.join(f' (the baseline at {thousands(n)} timed on '
                   f'{thousands(rows_)} query rows and scaled)'
                   for n, rows_ in extrapolated)
    groups = sorted({r['batch'] for r in batched})
    batch_text = '; '.join(
        f'batched {g}: ' + ', '.join(
            f"{r['op']} {times(r['speedup'])}" for r in batched
            if r['batch'] == g) for g in groups)
    agreement = min(r['edge_agreement'] for r in rows
                    if 'edge_agreement' in r)
    same = min(r['same_samples'] for r in rows if 'same_samples' in r)
    distance = max(r['max_dist_diff'] for r in rows if 'max_dist_diff' in r)

    def floor_pct(x):
        return f'{math.floor(10000 * x) / 100:.2f}%'

    result = (f'vs. plain torch (cdist + topk, a Python-loop fps), one '
              f'cloud: {ops}{note}; {batch_text}; the same '
              f'neighbours as brute force up to float32 near-ties (radius '
              f'edges >= {floor_pct(agreement)}, fps samples >= '
              f'{floor_pct(same)}, knn distances within {sci(distance)})')
    return [('knn / radius / fps without torch-cluster', 'neighbors.py',
             result)]


@rows_for('normals')
def normals(d, _):
    names = {'old': 'previous MST + flux', 'new': 'ours',
             'open3d': f"Open3D {d['versions'].get('open3d', '')}".strip()}
    sets = []
    for name, entry in d['datasets'].items():
        summary = entry['summary']['methods']
        rows = entry['rows']
        scores = ', '.join(
            f"{names[m]} {pct(summary[m]['mean_agreement'], 1)} / "
            f"{pct(summary[m]['min_agreement'], 1)}"
            for m in d['methods'])
        ours, old = summary['new'], summary['old']
        sets.append(
            f"{name} ({len(rows)} clouds of {rows[0]['points']} points): "
            f"{scores}; ours >= {pct(d['goal'])} on {ours['shapes_at_goal']}"
            f" of {ours['shapes']} (worst `{ours['worst_shape']}`), "
            f"{times(ours['median_seconds'] / old['median_seconds'])} the "
            f"time of the previous method "
            f"({1e3 * ours['median_seconds']:.0f} ms per cloud); PCA line "
            f">60 degrees off the truth on "
            f"{pct(entry['summary']['pca_over_60'], 1)} of points (oracle "
            f"one-sided PCA: {pct(entry['summary']['one_sided_over_60'], 1)}"
            f"), ours {pct(ours['mean_agreement_resolved'], 1)} on the "
            f"rest")
    modelnet = d['datasets'].get('SyntheticModelNet')
    note = ''
    contact = (sum(r['contact_fraction'] for r in modelnet['rows'])
               / len(modelnet['rows'])) if modelnet else 0.0
    if contact > 0.005:  # older data sets kept faces where parts touch
        visible = modelnet['summary']['methods']['new']
        note = (f". SyntheticModelNet keeps hidden contact faces between "
                f"touching parts (coincident points with opposite true "
                f"normals); without them ours scores "
                f"{pct(visible['mean_agreement_visible'], 1)} / "
                f"{pct(visible['min_agreement_visible'], 1)}")
    result = (f"share of points whose normal points to the side of the true "
              f"outward normal, mean / min over shapes, k = {d['k']}, "
              f"{d['threads']} thread(s): " + '; '.join(sets) + note)
    return [('oriented normals (visibility + signed-graph relaxation)',
             'normals.py', result)]


FEATURES = {'bbox_sorted': 'bounding box', 'area': 'area',
            'volume': 'volume', 'num_vertices': 'vertex count',
            'covariance_eigenvalues': 'covariance eigenvalues',
            'radial_stats': 'radial statistics',
            'bbox_aligned(upright)': 'upright bounding box'}


def feature_names(key: str) -> str:
    names = [FEATURES.get(k, k) for k in key.strip('+').split('+')]
    return ', '.join(names)


def nearest_centroid(stats: dict) -> str:
    accuracy = {k: v for k, v in stats.items() if k != 'random_chance'}
    keys = list(accuracy)
    text = f'{pct(accuracy[keys[0]])} ({feature_names(keys[0])}'
    for key in keys[1:]:
        verb = 'adding' if key.startswith('+') else 'with'
        text += f'; {pct(accuracy[key])} {verb} {feature_names(key)}'
    return text + ')'


@rows_for('datasets')
def datasets(d, _):
    shrec, modelnet = d['shrec'], d['modelnet']
    n_shrec = shrec['num_train'] + shrec['num_test']
    valid, total = (int(v) for v in
                    shrec['valid_closed_genus0_manifolds'].split('/'))
    kind = ('closed genus-0 manifold meshes' if valid == total else
            f'meshes, {valid} closed genus-0 manifolds')
    per_class = n_shrec // len(shrec['classes'])
    chance = {shrec['nearest_centroid_accuracy']['random_chance'],
              modelnet['nearest_centroid_accuracy']['random_chance']}
    centroid = {name: nearest_centroid(data['nearest_centroid_accuracy'])
                for name, data in (('SHREC', shrec), ('ModelNet', modelnet))}
    result = (
        f"SyntheticSHREC ({len(shrec['classes'])} classes x {per_class} "
        f"{kind}, {span(shrec['vertex_count_range'], str)} vertices) in "
        f"{shrec['generation_s']:.0f} s, SyntheticModelNet "
        f"({len(modelnet['classes'])} classes, "
        f"{modelnet['num_train'] + modelnet['num_test']} clouds of "
        f"{modelnet['num_points']} points) in "
        f"{modelnet['generation_s']:.0f} s; nearest centroid on global "
        f"features: SHREC {centroid['SHREC']}, ModelNet "
        f"{centroid['ModelNet']} (chance "
        f"{'/'.join(pct(c) for c in sorted(chance))})")
    return [('synthetic data sets are quick and not trivial', 'datasets.py',
             result)]


@rows_for('deltaconv_speed')
def deltaconv_speed(d, _):
    c, n, comp = d['construction'], d['networks'], d['compile']
    construction = (
        f"{d['batch']}, k = {d['k']}: {c['ours_with_normals_s']:.2f} s per "
        f"batch with normals ({c['ours_estimated_normals_s']:.2f} s "
        f"estimating normals), {times(c['speedup_with_normals'])} "
        f"({times(c['speedup_estimated_normals'])}) faster than the original "
        f"authors' `pcdiff`; gradient of x, y, z on a sphere: max error "
        f"{sig(c['sphere_gradient_max_error_ours'], 1)} against "
        f"{sig(c['sphere_gradient_max_error_original'], 2)} for the original "
        f"with the same regulariser weight (its regulariser is not "
        f"scale-invariant)")
    networks = (
        f"forward {times(n['speedup_forward'], 2)}, backward "
        f"{times(n['speedup_backward'], 2)}, whole training step (build + "
        f"forward + backward) {times(n['speedup_training_step'], 2)} faster "
        f"({n['deltanet_parameters'] / 1e6:.2f}M vs "
        f"{n['dgcnn_parameters'] / 1e6:.2f}M parameters); operator build "
        f"{n['deltanet_build_s']:.2f} s vs {n['dgcnn_build_s']:.2f} s for "
        f"DGCNN's k-nn graph; `torch.compile` gives another "
        f"{times(comp['compile_speedup'], 2)} per step (after "
        f"{comp['compile_s']:.0f} s of compilation)")
    return [('DeltaConv operator construction', 'deltaconv_speed.py',
             construction),
            ('DeltaNet vs DGCNN (EdgeConv), same batch and k',
             'deltaconv_speed.py', networks)]


def accuracies(run: dict) -> List[float]:
    values = [run['final_test_accuracy'], run['best_test_accuracy']]
    values += [h['test_accuracy'] for h in run.get('history', [])
               if h.get('test_accuracy') is not None]
    return values


def test_set_size(values: Sequence[float], largest: int = 5000):
    """The smallest number of test examples that makes every accuracy a
    whole count (None if there is none up to ``largest``)."""
    for n in range(1, largest + 1):
        if all(abs(v * n - round(v * n)) < 1e-6 for v in values):
            return n
    return None


def widths(channels: Sequence[int]) -> str:
    if len(set(channels)) == 1:
        return f'{channels[0]}x{len(channels)}'
    return '-'.join(str(c) for c in channels)


@rows_for('training_speed')
def training_speed(d, _):
    dn, hsn = d['deltanet'], d['hsn']
    goal = d['goal_seconds_per_epoch']
    deltanet = (
        f"{d['shapes']} shapes x {dn['points']} points, batch "
        f"{dn['batch_size']}, {d['threads']} thread(s), "
        f"{d['conditions']}: "
        f"{seconds(dn['epoch_cached_operators'])} s per epoch (goal "
        f"< {goal} s; {parts(dn['epoch_parts'])}); operators rebuilt every batch "
        f"{seconds(dn['epoch_operators_per_batch'])} s, PyG's embedding and "
        f"pooling layers in place of the fused one "
        f"{seconds(dn['epoch_pyg_embedding_pool'])} s; preparing a shape "
        f"once (sampling + operators) {dn['prepare_seconds_per_shape']:.2f}"
        f" s")
    harmonic = (
        f"{d['shapes']} meshes of ~{hsn['mean_vertices']:.0f} vertices, "
        f"{d['threads']} thread(s): {seconds(hsn['epoch_batch_1'])} s per "
        f"epoch at the paper's batch 1 ({parts(hsn['epoch_parts'])}), "
        f"{seconds(hsn['epoch_batch_8'])} s "
        f"at batch 8 (goal < {goal} s); preparing a mesh once (discs, log "
        f"maps, transport) {hsn['prepare_seconds_per_shape']:.2f} s")
    return [(f"DeltaNet training epoch, `{dn['protocol']}`",
             'training_speed.py', deltanet),
            (f"HSN training epoch, `{hsn['protocol']}`",
             'training_speed.py', harmonic)]


def parts(spent: dict) -> str:
    return (f"loading {seconds(spent['loading'])} s, forward "
            f"{seconds(spent['forward'])} s, backward + step "
            f"{seconds(spent['backward_and_step'])} s")


def stale_versions(recorded: Dict[str, int], names: Dict[str, str]) -> str:
    """The generated data sets whose recorded version is older than the
    generator's current one, e.g. 'SyntheticModelNet v1, now v2'."""
    if ROOT not in sys.path:
        sys.path.insert(0, ROOT)
    from tg_intrinsic import datasets
    stale = []
    for key, version in recorded.items():
        current = getattr(datasets, names[key]).version
        if version != current:
            stale.append(f'{names[key]} v{version}, now v{current}')
    return ', '.join(stale)


@rows_for('deltanet_accuracy')
def deltanet_accuracy(d, _):
    names = {'synthetic_shrec': 'SyntheticSHREC',
             'synthetic_modelnet': 'SyntheticModelNet'}
    parts, helps, margins = [], [], []
    for dataset in dict.fromkeys(r['dataset'] for r in d['runs']):
        on = next(r for r in d['runs'] if r['dataset'] == dataset
                  and r['vector_stream'])
        off = next(r for r in d['runs'] if r['dataset'] == dataset
                   and not r['vector_stream'])
        text = (f"**{names.get(dataset, dataset)} "
                f"{pct(on['final_test_accuracy'], 1)} vs "
                f"{pct(off['final_test_accuracy'], 1)}** ({on['epochs']} "
                f"epochs")
        if (on['best_test_accuracy'], off['best_test_accuracy']) != \
                (on['final_test_accuracy'], off['final_test_accuracy']):
            text += (f", best {pct(on['best_test_accuracy'], 1)} vs "
                     f"{pct(off['best_test_accuracy'], 1)}")
        text += (f"; widths {widths(on['conv_channels'])} vs "
                 f"{widths(off['conv_channels'])}, " + pair(
                     f"{on['parameters'] / 1e6:.2f}M",
                     f"{off['parameters'] / 1e6:.2f}M", ' parameters') + ')')
        parts.append(text)
        gain = on['final_test_accuracy'] - off['final_test_accuracy']
        helps.append(gain > 0)
        size = test_set_size(accuracies(on) + accuracies(off))
        margins.append((round(gain * size), size) if size else
                       (f'{100 * gain:.1f} points', None))
    if all(helps):
        verdict = 'The vector stream helps on both'
    elif any(helps):
        verdict = 'The vector stream helps on one of the two'
    else:
        verdict = 'The vector stream does not help here'
    sizes = {size for _, size in margins}
    if len(sizes) == 1 and None not in sizes:
        margin_text = (' and '.join(str(m) for m, _ in margins)
                       + f' test shapes of {sizes.pop()}')
    else:
        margin_text = ' and '.join(
            f'{m} of {n} test shapes' if n else m for m, n in margins)
    result = (f"{d['protocol']}, {d['num_points']} points, one seed (CPU "
              f"budget): {'; '.join(parts)}. {verdict}; the margins ("
              f"{margin_text}) come from a single seed")
    stale = stale_versions(d.get('dataset_versions', {}), names)
    if stale:
        result += (f". Measured on earlier versions of the generated data "
                   f"({stale}); not rerun since")
    return [('DeltaNet accuracy, vector stream on vs off (matched '
             'parameters)', 'deltanet_accuracy.py', result)]


@rows_for('part_segmentation')
def part_segmentation(d, _):
    p = d['protocol']

    def median(values):
        values = sorted(values)
        half = len(values) // 2
        return values[half] if len(values) % 2 else \
            (values[half - 1] + values[half]) / 2

    def batch_statistics(r):
        value = r.get('final_instance_miou_batch_statistics')
        return '' if value is None else \
            f", batch statistics {pct(value, 1)}"

    runs = ', '.join(
        f"{r['label']} **{pct(r['final_instance_miou'], 1)}** / "
        f"{pct(r['final_class_miou'], 1)} ({r['parameters'] / 1e6:.2f}M "
        f"parameters, median "
        f"{seconds(median([h['seconds'] for h in r['history']]))} s per "
        f"epoch{batch_statistics(r)})" for r in d['runs'])
    result = (f"instance / class mIoU (eval mode, recalibrated batch "
              f"norms) after {p['epochs']} epochs on "
              f"{5 * p['train_per_category']} training shapes of "
              f"{p['num_points']} points, {5 * p['test_per_category']} "
              f"test shapes (10 per category, so the two agree), one "
              f"seed: {runs}")
    gravo = d['level_sizes'].get('gravo')
    if gravo:
        result += ("; Gravo levels keep " + ' / '.join(
            f"{n:.0f}" for n in gravo) + " points (FPS " + ' / '.join(
            f"{n:.0f}" for n in d['level_sizes']['fps']) + ")")
    return [('Delta-U-ResNet vs DeltaNet, part segmentation '
             '(SyntheticShapeParts)', 'part_segmentation.py', result)]


@rows_for('perona_malik')
def perona_malik(d, _):
    runs = d['runs']
    delta = runs[0]
    others = ', '.join(f"{r['model'].split(' (')[0]} {r['test_rel_l2']:.2f}"
                       for r in runs[1:])
    sizes = [r['parameters'] / 1e3 for r in runs]
    quick = ' (quick smoke run)' if d.get('quick') else ''
    result = (f"{d['protocol']}; {d['train_surfaces']} training / "
              f"{d['test_surfaces']} test surfaces, {d['epochs']} epochs, "
              f"one seed{quick}; test error relative to the input's "
              f"(1 = identity): **DeltaConv {delta['test_rel_l2']:.2f}** vs "
              f"{others} ({span(sizes, f1)}k parameters each); "
              f"{span([r['seconds'] / 60 for r in runs], f1)} min per run "
              f"on {d['machine']['cpu_count']} CPU cores")
    return [('learning Perona-Malik diffusion (DeltaConv thesis Fig. 3.2): '
             'anisotropic vs isotropic convolutions', 'perona_malik.py',
             result)]
