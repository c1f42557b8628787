"""Rows of Harmonic Surface Networks: log-map precomputation, the
harmonic convolution's speed, HSN's accuracy, correspondence, sphere
digits and the complex normalisations."""

from .common import (f1, pair, pct, rows_for, sci, seconds, span,
                     span_pct, strip_ext, thousands, times)


@rows_for('logmap_precompute')
def logmap_precompute(d, _):
    rows = d['rows']
    eps = {r['eps'] for r in rows}
    meshes = {r['mesh'].split('@')[0] for r in rows}

    def each(key, fmt):
        return ' / '.join(fmt(r[key]) for r in rows)

    def times1(x):
        return times(x, 1)

    def agreement(r):
        a = r['accuracy_vs_original']['vector_heat']
        return max(a['radius_err_over_eps_p95'], a['theta_err_rad_p95'],
                   a['turn_err_rad_p95'])

    fast = [r['accuracy_vs_original']['fast'] for r in rows]
    extrapolated = [r for r in rows if r['original_extrapolated']]
    note = ''
    if extrapolated:
        note = '; ' + ', '.join(
            f"{thousands(r['vertices'])} timings extrapolated from "
            f"{r['centres_timed']} centres (and "
            f"{r['original_centres_timed']} for the original)"
            for r in extrapolated)
    result = (
        f"{' / '.join(strip_ext(m) for m in sorted(meshes))} decimated to "
        f"{each('vertices', thousands)} vertices "
        f"({each('mean_neighbours', thousands)} neighbours per disc), "
        f"against the original's one global vector-heat log map + transport "
        f"solve per vertex (potpourri3d, {each('original_s', seconds)} s): "
        f"`'vector_heat'` **{each('speedup_vector_heat', times1)}** "
        f"faster (goal {times(d['goals']['vector_heat_speedup'], 0)}; "
        f"{each('speedup_vector_heat_1worker', times1)} on one "
        f"thread; **{each('speedup_vector_heat_with_graph', times1)}** "
        f"with our fast-marching disc graph counted, which the original "
        f"does not need (goal "
        f"{times(d['goals']['vector_heat_with_graph_speedup'], 0)} at 10k "
        f"and 50k)), with the same output: radii (over eps), angles and "
        f"transport equal to the original's to "
        f"{' / '.join(sci(agreement(r)) for r in rows)} (95th percentile; "
        f"angles up to the direction each vertex calls 0); `'fast'` "
        f"{each('speedup_fast', lambda x: times(x, 0))} (goal "
        f"{times(d['goals']['fast_speedup'], 0)}; "
        f"{each('speedup_fast_with_graph', times1)} with the graph), its "
        f"radii off by "
        f"{span_pct([f['radius_err_over_eps_median'] for f in fast], 1)} "
        f"of eps (median) and its angles by "
        f"{span([f['theta_err_rad_p95'] for f in fast], f1)} rad (95th "
        f"percentile){note}")
    claim = (f"HSN precomputation (discs, log map, transport, weights), eps = "
             f"{'/'.join(f'{e:g}' for e in sorted(eps))} on unit area")
    return [(claim, 'logmap_precompute.py', result)]


@rows_for('harmonic_conv_speed')
def harmonic_conv_speed(d, _):
    runs = d['runs']

    def config(r):
        return (f"{r['channels_in']} channels, orders 0-{r['max_order']}")

    vertices = span([r['vertices'] for r in runs], thousands)
    edges = span([r['edges'] for r in runs], lambda x: thousands(x, 0))
    agree = all(r['outputs_agree'] for r in runs)
    result = (
        f"a {vertices}-vertex mesh, {edges} disc edges (radius "
        f"{d['radius']}, {d['rings']} rings), forward + backward on the "
        f"{d['device'].upper()}: "
        + ', '.join(f"{times(r['speedup'], 1)} ({config(r)})" for r in runs)
        + " faster; peak memory "
        + ' / '.join(times(r['memory_ratio'], 1) for r in runs)
        + f" lower ({span([r['ours_peak_mb'] / 1024 for r in runs], f1)}"
        f" GiB vs {span([r['naive_peak_mb'] / 1024 for r in runs], f1)}"
        f" GiB)" + ('; same outputs' if agree else
                   '; **outputs differ** in '
                   + str(sum(not r['outputs_agree'] for r in runs))
                   + ' configurations'))
    return [('HarmonicConv: one sparse aggregation vs per-edge messages',
             'harmonic_conv_speed.py', result)]


@rows_for('hsn_accuracy')
def hsn_accuracy(d, _):
    parts = []
    for task in dict.fromkeys(r['task'] for r in d['runs']):
        runs = [r for r in d['runs'] if r['task'] == task]
        two = max(runs, key=lambda r: r['max_order'])
        one = min(runs, key=lambda r: r['max_order'])
        unit = ' per vertex' if task == 'segmentation' else ''
        parts.append(
            f"**{task} {pct(two['final_test_accuracy'], 1)} vs "
            f"{pct(one['final_test_accuracy'], 1)}**{unit} (" + pair(
                f"{two['parameters'] / 1e3:.0f}k",
                f"{one['parameters'] / 1e3:.0f}k", ' parameters') + ')')
    names = [r['variant'] for r in d['runs']]
    minutes = [r['seconds'] / 60 for r in d['runs']]
    result = (f"{d['protocol']}, {d['epochs']} epochs, one seed; "
              f"{names[0]} vs {names[1]}: {'; '.join(parts)}; "
              f"{span(minutes, f1)} min per run on "
              f"{d['machine']['cpu_count']} CPU cores")
    return [('HSN accuracy, two streams vs one stream (matched parameters)',
             'hsn_accuracy.py', result)]


@rows_for('normalisation')
def normalisation(d, _):
    def mean(runs, key):
        return sum(r[key] for r in runs) / len(runs)

    def of(model, norm):
        return [r for r in d['runs']
                if r['model'] == model and r['norm'] == norm]

    hsn = {norm: of('hsn', norm) for norm in ('batch', 'instance', 'none')}
    batch = hsn['batch']

    def deltanet(run):
        return (f"{run['epochs']} epochs: running statistics "
                f"{pct(run['eval'], 1)}, **recalibrated (default) "
                f"{pct(run['recalibrated'], 1)}**, batch statistics "
                f"{pct(run['batch_statistics'], 1)} (" + span_pct(
                    run['batch_statistics_shuffles'], 1) + " over "
                f"{len(run['batch_statistics_shuffles'])} cuts of the test "
                f"set into batches)")
    result = (
        f"same weights, test accuracy in eval mode vs with batch statistics "
        f"(mean of {len(batch)} seeds). HSN, hsn-shrec11 protocol (batch "
        f"1) on SyntheticSHREC: ComplexBatchNorm "
        f"{pct(mean(batch, 'eval'), 1)} vs "
        f"{pct(mean(batch, 'batch_statistics'), 1)} (recalibrated "
        f"{pct(mean(batch, 'recalibrated'), 1)}); **per-shape "
        f"ComplexInstanceNorm (default) "
        f"{pct(mean(hsn['instance'], 'eval'), 1)} in both**; no "
        f"normalisation {pct(mean(hsn['none'], 'eval'), 1)}. DeltaNet, "
        f"deltanet-modelnet40 protocol (batch 32) on SyntheticModelNet, "
        + '; '.join(deltanet(r) for r in of('deltanet', 'batch')))
    return [('Evaluation that matches training: normalisation of HSN and '
             'DeltaNet', 'normalisation.py', result)]


@rows_for('hsn_correspondence')
def hsn_correspondence(d, _):
    runs, ref = d['runs'], d['hks_nearest_neighbour']
    parts = [f"{r['model']}: **{pct(r['within_0.05'], 1)} within "
             f"0.05**, {pct(r['exact'], 1)} exact, "
             f"{pct(r['within_0.1'], 1)} within 0.1 "
             f"({thousands(r['parameters'])} parameters, backbone "
             f"{thousands(r['backbone_parameters'])}; "
             f"{seconds(r['seconds_per_epoch'])} s per epoch on one "
             f"thread)"
             for r in runs]
    result = (f"{d['num_train']} training / {d['num_test']} test poses of "
              f"one template of {d['num_vertices']} vertices, "
              f"{d['input']} as input, {d['epochs']} epochs, one seed; "
              f"fraction of test vertices whose predicted template vertex "
              f"is within a geodesic error (relative to the diameter) of "
              f"the true one: " + '; '.join(parts)
              + f"; without learning, the template vertex of nearest HKS: "
              f"{pct(ref['within_0.05'], 1)} within 0.05, "
              f"{pct(ref['exact'], 1)} exact")
    return [('HSN U-ResNet correspondence vs a non-equivariant baseline '
             '(SyntheticCorrespondence)', 'hsn_correspondence.py', result)]


@rows_for('sphere_digits')
def sphere_digits(d, _):
    parts = []
    for training in ('upright', 'turned'):
        runs = [r for r in d['runs'] if r['training'] == training]
        two = max(runs, key=lambda r: r['max_order'])
        one = min(runs, key=lambda r: r['max_order'])
        parts.append(
            f"trained {training}: **turned test {pct(two['test_turned'], 1)}"
            f" vs {pct(one['test_turned'], 1)}** (upright "
            f"{pct(two['test_upright'], 1)} vs {pct(one['test_upright'], 1)}"
            f", turned by fifths of a circle {pct(two['test_turned72'], 1)} "
            f"vs {pct(one['test_turned72'], 1)}; same class upright and "
            f"turned {pct(two['agreement_upright_turned'], 0)} vs "
            f"{pct(one['agreement_upright_turned'], 0)})")
    two = max(d['runs'], key=lambda r: r['max_order'])
    one = min(d['runs'], key=lambda r: r['max_order'])
    minutes = [r['seconds'] / 60 for r in d['runs']]
    quick = ' (quick smoke run)' if d.get('quick') else ''
    result = (f"{d['protocol']}; {d['train_size']} training / "
              f"{d['test_size']} test digits, {d['epochs']} epochs, one "
              f"seed{quick}; two streams vs one stream ("
              f"{two['parameters'] / 1e3:.0f}k vs "
              f"{one['parameters'] / 1e3:.0f}k parameters): "
              + '; '.join(parts) + f"; {span(minutes, f1)} min per run on "
              f"{d['machine']['cpu_count']} CPU cores")
    return [('HSN on digits turned on a sphere (thesis Table 2.3), two '
             'streams vs one', 'sphere_digits.py', result)]
