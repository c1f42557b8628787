"""Rows of the library as a whole: the demo, torch.compile and mixed
precision, the command-line sweep, out-of-core data, data-parallel
training and the GPU."""

from .common import (f3, pct, rows_for, sci, seconds, signed, thousands,
                     times)


@rows_for('demo')
def demo(d, _):
    """Registered first: the demo is the README's first command."""
    dn, hsn, gravo, sv = d['deltanet'], d['hsn'], d['gravo'], d['svbrdf']
    smoothing = gravo['problems']['smoothing']
    poisson = gravo['problems']['poisson']

    def solvers(entry):
        return (f"Gravo MG {entry['gravo']['cycles']} cycles, "
                f"{entry['gravo']['solve_seconds']:.2f} s (+ "
                f"{entry['gravo']['setup_seconds']:.2f} s setup), scipy "
                f"direct {seconds(entry['scipy_direct']['seconds'])} s, "
                f"pyamg SA + CG {entry['pyamg_sa_cg']['iterations']} "
                f"iterations, {seconds(entry['pyamg_sa_cg']['seconds'])} s")

    result = (
        f"{d['seconds'] / 60:.1f} min on {d['machine']['cpu_count']} CPU "
        f"cores (data generated in the run, numba kernels already compiled)"
        f". DeltaNet ({dn['epochs']} epochs, "
        f"{dn['train_shapes']} SyntheticModelNet clouds): "
        f"{pct(dn['test_accuracy'], 1)} test accuracy, bounding-box nearest "
        f"centroid {pct(dn['baselines']['bounding_box_nearest_centroid'], 1)}"
        f"; HSN ({hsn['epochs']} epochs, {hsn['train_shapes']} SyntheticSHREC "
        f"meshes in random poses): {pct(hsn['test_accuracy'], 1)}, Shape-DNA "
        f"nearest centroid "
        f"{pct(hsn['baselines']['shape_dna_nearest_centroid'], 1)}, bounding "
        f"box {pct(hsn['baselines']['bounding_box_nearest_centroid'], 1)}; "
        f"Gravo MG on a {thousands(gravo['vertices'], 1)}-vertex torus "
        f"(hierarchy once per surface, {gravo['hierarchy_seconds']:.1f} s), "
        f"relative residual {sci(gravo['tolerance'])}: smoothing "
        f"{solvers(smoothing)}; Poisson {solvers(poisson)}; SVBRDF from {sv['views']} rendered photographs "
        f"of {sv['points']} points: roughness MAE {f3(sv['roughness_mae'])} / "
        f"base RMSE {f3(sv['base_color_rmse'])} (constant 0.5: "
        f"{f3(sv['constant_0.5_roughness_mae'])} / "
        f"{f3(sv['constant_0.5_base_color_rmse'])}), entropy vs error "
        f"Spearman {signed(sv['spearman_entropy_vs_roughness_error'])}")
    return [('`make demo`: all four methods on generated data', 'demo.py',
             result)]


@rows_for('compile_precision')
def compile_precision(d, _):
    seeds = next(iter(d['accuracy'].values()))['seeds']
    parts = []
    for name, row in d['speed'].items():
        model, task = name.split('_', 1)
        parts.append(
            f"{model} {task}: compiled {times(row['compiled_speedup'])}, "
            f"bf16 {times(row['bf16_speedup'])}, both "
            f"{times(row['compiled_bf16_speedup'])} (logits within "
            f"{pct(row['bf16_logits_gap'], 1)})")
    accuracy = '; '.join(
        f"{name} {pct(run['32-true_mean'], 1)} (float32) vs "
        f"{pct(run['bf16-mixed_mean'], 1)} (bf16-mixed), "
        f"**{run['points_apart']:.1f} points apart** (paired spread "
        f"{run['paired_stdev_points']:.1f} points)"
        for name, run in d['accuracy'].items())
    quick = ' (quick smoke run)' if d.get('quick') else ''
    result = (f"training step over eager float32{quick}, "
              f"{d['threads']} threads, {d['conditions']}: "
              + '; '.join(parts) + f". Final test accuracy, mean of "
              f"{len(seeds)} seeds: {accuracy} (goal: within 1 point)")
    return [('torch.compile and bfloat16 autocast: DeltaNet and HSN training '
             'steps against eager float32, the accuracy of bf16-mixed '
             'training', 'compile_precision.py', result)]


@rows_for('cli_sweep')
def cli_sweep(d, _):
    c = d['counts']
    together = [r for r in d['cases'] if r.get('concurrent')]
    result = (f"{c['cases']} command lines over every sub-command (files "
              f"other tools write, every numeric option, earlier results, "
              f"resumes, Ctrl-C while writing, linked output folders, "
              f"byte-order marks, names too long for the file system, "
              f"{len(together)} runs started 2-4 at a time into one "
              f"folder): exit 0 {c['exit_0']}, exit 2 "
              f"{c['exit_2']}, exit 130 {c.get('exit_130', 0)}, "
              f"**other exit codes {c['other_exit_codes']}, lost or changed "
              f"files {c['data_loss']}, stray files {c['stray_files']}, "
              f"wrong results {c['wrong_results']}, messages that name "
              f"none of the user's options or files "
              f"{c['messages_not_naming_the_input']}**")
    return [("The command line on a careful user's inputs", 'cli_sweep.py',
             result)]


@rows_for('out_of_core')
def out_of_core(d, _):
    rows = d['rows']
    slopes, prep = d['mb_per_1000_shapes'], d['preparation']

    def peaks(arm):
        mine = sorted((r for r in rows if r['arm'] == arm),
                      key=lambda r: r['size'])
        return ', '.join(f"{r['peak_mb']:.0f}" for r in mine)

    sizes = sorted({r['size'] for r in rows})
    quick = ' (quick smoke run)' if d.get('quick') else ''
    result = (f"peak resident memory of one DeltaNet training epoch (a "
              f"fresh process each) on N = "
              f"{', '.join(str(n) for n in sizes)} shapes of "
              f"{d['num_points']} points with MLS operators (k = {d['k']}, "
              f"{d['example_megabytes']:.2f} MB each){quick}: **on disk "
              f"{peaks('on_disk')} MB ({slopes['on_disk']:.0f} MB per 1000 "
              f"shapes)** vs in memory {peaks('in_memory')} MB "
              f"({slopes['in_memory']:.0f} MB per 1000 shapes); same "
              f"training loss: {'yes' if d['same_loss'] else 'NO'}; "
              f"preparing {prep['shapes']} shapes: 1 worker "
              f"{seconds(prep['seconds']['1'])} s, 2 workers "
              f"{seconds(prep['seconds']['2'])} s "
              f"({times(prep['speedup'], 2)}), identical databases: "
              f"{'yes' if prep['identical'] else 'NO'}; "
              f"{d['machine']['cpu_count']} CPU cores")
    return [('out-of-core training data (PrecomputedOnDisk, train '
             '--on-disk): memory stays flat as the data set grows; '
             'parallel precomputation (--workers)', 'out_of_core.py',
             result)]


@rows_for('ddp_training')
def ddp_training(d, _):
    rows = []
    for model, data in d['models'].items():
        by = {c['label']: c for c in data['configurations']}
        one_2 = by['1 process x 2 threads']['epoch_seconds']
        one_1 = by['1 process x 1 thread']['epoch_seconds']
        two = by['2 processes x 1 thread']['epoch_seconds']
        sync = by['2 processes x 1 thread, sync BN']['epoch_seconds']
        gpu = d['gpu'] if isinstance(d['gpu'], str) else \
            f"{d['gpu']['devices']} x {d['gpu']['name']}"
        rows.append((
            f"Data-parallel training (torchrun, gloo), {model}",
            'ddp_training.py',
            f"{data['train_shapes']} shapes, same global batch, "
            f"{d['machine']['cpu_count']} CPU cores: seconds per epoch 1 "
            f"process x 2 threads {seconds(one_2)}, x 1 thread "
            f"{seconds(one_1)}, 2 processes x 1 thread {seconds(two)} "
            f"(speed-up {times(one_2 / two, 2)} over 1 process x 2 "
            f"threads, {times(one_1 / two, 2)} over 1 thread), with sync "
            f"BN {seconds(sync)}; GPUs: {gpu}"))
    return rows


GPU_CLAIM = 'CUDA: the test suite on the GPU, and the GPU speed goals'


def two_digits(x: float) -> str:
    """150, 12, 0.8: two significant digits, no trailing zeros."""
    return f'{float(f"{x:.2g}"):g}'


def milliseconds(x: float) -> str:
    return f'{two_digits(1e3 * x)} ms'


def in_seconds(x: float) -> str:
    return f'{two_digits(x)} s' if x < 10 else f'{seconds(x)} s'


@rows_for('gpu', unverified=(
    GPU_CLAIM, 'gpu.py', 'not verified: no GPU run has written '
    'benchmarks/results/gpu.json yet'))
def gpu(d, _):
    """Written only by a run on a CUDA device (``benchmarks/gpu.py``)."""
    if d['quick'] or d['device'] == 'cpu':
        raise ValueError('gpu.json is a --quick or CPU check, not the '
                         'results: run benchmarks/gpu.py on a GPU')
    parts = []
    failed = [f"{name} failed ({d[name]['error'][:60]})" for name in (
        'device_tests', 'neighbours', 'networks', 'uncertainty', 'svbrdf',
        'epochs') if 'error' in d[name]]
    if 'error' not in d['device_tests']:
        t = d['device_tests']
        parts.append(f"`pytest --device cuda`: {t['summary']}")
    # the stages' figures (not the goals, verdicts or machine)
    figures = {key: value for name, part in d.items()
               if name not in ('goals', 'met', 'machine')
               and isinstance(part, dict) for key, value in part.items()}

    def goal(key, fmt):
        """A figure against its goal, as gpu.py judged it."""
        sign = '>=' if key in d['at_least'] else '<='
        return (f"{fmt(figures[key])} (goal {sign} {fmt(d['goals'][key])}, "
                f"{'met' if d['met'][key] else '**not met**'})")
    if 'error' not in d['neighbours']:
        n = d['neighbours']
        parts.append(
            f"knn on 100k points {goal('knn_100k_s', milliseconds)}, on "
            f"32 x 1024 {goal('knn_32x1024_s', milliseconds)}, "
            f"{'the same' if n['knn_same_graph_as_cpu'] else '**not the same**'} "  # noqa: E501
            f"graph as the CPU; MLS operators {in_seconds(n['mls_100k_s'])} / "
            f"{milliseconds(n['mls_32x1024_s'])}")
    if 'error' not in d['networks']:
        parts.append(
            f"DeltaNet step on 32 x 1024, operators in the forward, "
            f"{goal('deltanet_step_s', milliseconds)}, EdgeConv DGCNN "
            f"{milliseconds(figures['dgcnn_step_s'])}: "
            f"{goal('deltanet_vs_dgcnn', lambda x: times(x, 2))}")
    if 'error' not in d['uncertainty']:
        parts.append(f"spectral uncertainty of 100k points "
                     f"{goal('spectral_uncertainty_100k_s', milliseconds)}")
    if 'error' not in d['svbrdf']:
        s = d['svbrdf']
        parts.append(f"`svbrdf --refine 10` on 2562 points x 25 views "
                     f"{in_seconds(s['svbrdf_device']['wall_s'])} vs "
                     f"{in_seconds(s['svbrdf_cpu']['wall_s'])} on its CPU "
                     f"({times(s['svbrdf_speedup'], 2)})")
    if 'error' not in d['epochs']:
        parts.append(
            f"SHREC'11-protocol epochs: DeltaNet "
            f"{goal('deltanet_epoch_s', in_seconds)}, HSN "
            f"{goal('hsn_epoch_s', in_seconds)}")
    text = f"{d['device']}, {in_seconds(d['seconds'])} in all: " + \
        '; '.join(parts + failed)
    return [(GPU_CLAIM, 'gpu.py', text.replace('|', '/'))]
