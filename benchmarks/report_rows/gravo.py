"""Rows of Gravo MG: mesh operators, the solver, its applications, its
scaling and learned diffusion."""
import re

from .common import (f1, pct, rows_for, sci, seconds, span, span_pct,
                     span_times, strip_ext, thousands, times)


@rows_for('mesh_operators')
def mesh_operators(d, _):
    rows = d['rows']
    vertices = span([r['vertices'] for r in rows], thousands)
    laplacian = (
        f"{span_times([r['speedup'] for r in rows])} faster than "
        f"`robust_laplacian.mesh_laplacian` on {len(rows)} scanned meshes "
        f"({vertices} vertices); Dirichlet energies agree to "
        f"{sci(max(r['max_rel_dirichlet_energy_difference'] for r in rows))}"
        f" (robust_laplacian flips to an intrinsic Delaunay mesh)")
    oriented = [r['normals_fraction_oriented_like_mesh'] for r in rows]
    angles = [r['normals_median_angle_deg'] for r in rows]
    worst = min(rows, key=lambda r: r['normals_fraction_oriented_like_mesh'])
    normals = (
        f"median {span(angles, f1)} degrees from the mesh normals, "
        f"{span_pct(oriented)} consistently oriented (the "
        f"{pct(min(oriented))} is "
        f"`{strip_ext(worst['mesh'])}`)")
    return [('cotan Laplacian + lumped mass', 'mesh_operators.py', laplacian),
            ('normal estimation', 'mesh_operators.py', normals)]


def surface_name(row: dict) -> str:
    """The surface's name, with its size unless the name says it."""
    if re.search(r'\d+k$', row['surface']):
        return f"`{row['surface']}`"
    return f"`{row['surface']}` ({thousands(row['vertices'])})"


@rows_for('gravo_mg')
def gravo_mg(d, _):
    by_name = {r['surface']: r for r in d['rows']}
    goals = d['goals']
    tolerance = re.search(r'Tolerance (\S+)', d['protocol']).group(1)
    original = re.search(r'\((PyPI gravomg [^,]+),', d['protocol']).group(1)
    matrices = ' and '.join(
        f"({d['rows'][0][p]['matrix']})" for p in ('poisson', 'smoothing'))
    covered = sorted({g['surface'] for g in goals},
                     key=lambda s: by_name[s]['vertices'])
    least = min(by_name[s]['vertices'] for s in covered)
    # the threshold the goals cover, rounded down to two digits: 160k
    smallest = thousands(least - least % 10 ** (len(str(least)) - 2))

    # cycles, everywhere
    pairs = [(r, p) for r in d['rows'] for p in ('poisson', 'smoothing')
             if r[p]['original'].get('converged')]
    excess = [(r[p]['ours']['iterations'] - r[p]['original']['iterations'],
               r, p) for r, p in pairs]
    covered_excess = [e for e in excess if e[1]['surface'] in covered]
    gap = max(((r[p]['original']['iterations'] - r[p]['ours']['iterations'],
                r, p) for r, p in pairs if r['surface'] in covered),
              key=lambda e: e[0])
    cycles = ('**never more cycles** there' if max(
        e[0] for e in covered_excess) <= 0 else 'more cycles on some')
    cycles += (f" ({surface_name(gap[1])} {gap[2]}: "
               f"{gap[1][gap[2]]['ours']['iterations']} vs "
               f"{gap[1][gap[2]]['original']['iterations']})")
    worst = max(excess, key=lambda e: e[0])
    if worst[0] > 0:
        cycles += (f"; on smaller surfaces up to {worst[0]} more "
                   f"({surface_name(worst[1])} {worst[2]}: "
                   f"{worst[1][worst[2]]['ours']['iterations']} vs "
                   f"{worst[1][worst[2]]['original']['iterations']})")

    # hierarchy time per surface
    hierarchy = {g['surface']: g['hierarchy_ratio'] for g in goals}
    faster = [v for v in hierarchy.values() if v <= 1]
    slower = [s for s, v in hierarchy.items() if v > 1]
    hierarchy_text = (f"hierarchy **{span_times(faster, 2)}** of its time on "
                      f"{len(faster)} of {len(hierarchy)} surfaces")
    if slower:
        hierarchy_text += ' (' + ', '.join(
            f'{surface_name(by_name[s])}: {times(hierarchy[s], 2)}'
            for s in slower) + ')'

    # solve time per surface and problem
    comparable = [g for g in goals if 'original_failed' not in g]
    faster = [g['solve_ratio'] for g in comparable if g['solve_ratio'] <= 1]
    slower = {}
    for g in comparable:
        if g['solve_ratio'] > 1:
            slower.setdefault(g['surface'], []).append(g['solve_ratio'])
    solve_text = (f"solve **{span_times(faster, 2)}** of its time in "
                  f"{len(faster)} surface-problem pairs")
    if slower:
        solve_text += ', ' + ', '.join(
            f'{span_times(v, 2)} on {surface_name(by_name[s])}'
            for s, v in slower.items())
    met = sum(g['met_solve'] for g in comparable)
    failed = {}
    for g in goals:
        if 'original_failed' in g:
            failed.setdefault((g['surface'], g['original_failed']),
                              []).append(g['iterations'][0])
    failed_text = ''.join(
        f"; on {surface_name(by_name[s])} the original fails ({why}), ours "
        f"converges in {span(v, str)} cycles" for (s, why), v in
        failed.items())

    # PCG where the goals ask for it
    pcg_goals = [g for g in goals if 'met_pcg_beats_v' in g]
    pcg_text = ''
    if pcg_goals:
        its = [by_name[g['surface']][g['problem']]['ours_pcg']['iterations']
               for g in pcg_goals]
        v_its = [by_name[g['surface']][g['problem']]['ours']['iterations']
                 for g in pcg_goals]
        families = sorted({by_name[g['surface']]['family']
                           for g in pcg_goals})
        beats = sum(g['met_pcg_beats_v'] for g in pcg_goals)
        pcg_text = (f"; as a CG preconditioner {span(its, str)} instead of "
                    f"{span(v_its, str)} iterations on the "
                    f"{'/'.join(families)} surfaces (faster than plain "
                    f"V-cycles in {beats} of {len(pcg_goals)} cases)")
    sa = [g['ratio_vs_sa_cg'] for g in goals]
    result = (
        f"against the original ({original} in its own numpy<2 env, same "
        f"relative-residual criterion), unit-area {matrices}, on the "
        f"{len(covered)} surfaces >= {smallest} the goals cover: {cycles}; "
        f"{hierarchy_text}; {solve_text} (goal {times(0.8, 1)}: met on "
        f"{met} of the {len(comparable)} comparable surface-problem pairs)"
        f"{failed_text}{pcg_text}; {span_times(sa, 2)} the time of pyamg "
        f"SA+CG (setup + solve)")
    claim = (f"Gravo MG: hierarchy and solve, per new matrix, tolerance "
             f"{tolerance}")
    return [(claim, 'gravo_mg.py', result)]


@rows_for('gravo_applications')
def gravo_applications(d, _):
    def case(r):
        if 'step' in r:
            return 'conformal flow (per step)'
        if r['beta'] == 0:
            return f"Laplace alpha={r['alpha']:g}"
        return (f"bi-Laplace alpha={r['alpha']:g}, beta={r['beta']:g}"
                + (' (split)' if r['split'] else ' (full, PCG)'))

    def versus(r):
        out = f"**{seconds(r['ours_s'])} s** ({r['ours_best']})"
        peers = [('cholespy', 'cholespy'), ('cholespy_split', 'split'),
                 ('splu', 'splu')]
        out += ' vs ' + ', '.join(
            f"{label} {seconds(r[key + '_s'])} s "
            f"({times(r[key + '_s'] / r['ours_s'], 1)})"
            for key, label in peers if key + '_s' in r)
        return f"{case(r)}: {out}"

    rows = d['smoothing'] + [d['conformal_flow']]
    worst = max(max(r[r['ours_best']]['difference'] for r in d['smoothing']),
                d['conformal_flow'][d['conformal_flow']['ours_best']]
                ['difference'])
    flow = d['conformal_flow']
    result = (f"{d['surface']} ({thousands(d['vertices'], 0)} vertices), "
              f"assembly included, hierarchy built once "
              f"({seconds(d['hierarchy_s'])} s): "
              + '; '.join(versus(r) for r in rows)
              + f"; results equal the direct solver's to {sci(worst)} "
              f"(relative); PCG iterations per flow step "
              f"{min(flow['pcg']['iterations'])}-"
              f"{max(flow['pcg']['iterations'])}")
    if not d['cholespy']:
        result += '; cholespy was not installed'
    return [('Gravo MG applications: smoothing sweep and conformal flow '
             f"vs direct solvers, tolerance {d['tol']:g}",
             'gravo_applications.py', result)]


@rows_for('gravo_scale')
def gravo_scale(d, _):
    def size(row):
        return f"{row['vertices'] / 1e6:.1f}M"

    parts = []
    for row in d['rows']:
        cells = []
        for problem in ('poisson', 'smoothing'):
            r = row[problem]
            ours, original = r['ours'], r.get('original')
            text = (f"{problem} {seconds(ours['seconds'])} s "
                    f"({ours['iterations']} cycles)")
            if original and 'original_failed' in r:
                text += ' (original: NaN)'
            elif original:
                text += (f" vs {seconds(original['seconds'])} s "
                         f"({original['iterations']}), "
                         f"**{times(r['solve_ratio'], 2)}**")
            cells.append(text)
        r = row['poisson']
        memory = f"{r['ours']['added_mb_per_million']:.0f}"
        hierarchy = f"hierarchy {seconds(r['ours']['hierarchy_s'])} s"
        if 'original' in r:
            memory += f" vs {r['original']['added_mb_per_million']:.0f}"
            hierarchy += (f" vs {seconds(r['original']['hierarchy_s'])} s "
                          f"(**{times(r['hierarchy_ratio'], 2)}**)")
        parts.append(f"{size(row)} vertices: {hierarchy}; "
                     + '; '.join(cells)
                     + f"; peak memory {memory} MB per million vertices")
    result = ('ours vs gravomg 0.0.4, same residual 1e-4. '
              + '. '.join(parts))
    if d.get('gpu') is None:
        result += ' (no GPU was available)'
    return [('Gravo MG at scale: Loop-subdivided scans, time and peak '
             'memory', 'gravo_scale.py', result)]


@rows_for('gravo_diffusion')
def gravo_diffusion(d, _):
    runs = {r['solver']: r for r in d['runs']}
    gravo, direct = runs['gravo'], runs['direct']
    ratio = d['step_ratio']
    speed = (f"**Gravo MG {times(ratio)} faster per step**" if ratio >= 1
             else f"**Gravo MG {times(1 / ratio)} slower per step**")
    quick = ' (quick smoke run)' if d.get('quick') else ''
    apart = sci(d['learned_time_difference']) \
        if d['learned_time_difference'] else '0'
    result = (f"{d['protocol']}{quick}: {speed} "
              f"({1e3 * gravo['step_s']:.0f} vs "
              f"{1e3 * direct['step_s']:.0f} ms: forward, adjoint "
              f"backward and the update; Gravo levels "
              f"{', '.join(str(n) for n in gravo['levels'])}, built once "
              f"in {seconds(gravo['setup_s'])} s, tolerance "
              f"{d['tol']:g}); learned times within "
              f"{pct(gravo['max_time_error'], 2)} (Gravo MG) and "
              f"{pct(direct['max_time_error'], 2)} (LU) of the true "
              f"ones, final loss {sci(gravo['final_relative_loss'])} vs "
              f"{sci(direct['final_relative_loss'])} of the input's, the "
              f"arms' times apart by {apart} of the largest; "
              f"{d['machine']['cpu_count']} CPU cores")
    return [('GravoDiffusion: learning per-channel diffusion times '
             '(DiffusionNet\'s layer, implicit) by adjoint solves, Gravo '
             'MG vs the sparse LU', 'gravo_diffusion.py', result)]
