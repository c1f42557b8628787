"""Gravo MG at scale: tg_intrinsic's GravoMG against the original (PyPI
gravomg 0.0.4, in its own numpy < 2 environment: make gravomg-env, or
--gravomg-python) on real scans Loop-subdivided to millions of vertices,
time and peak memory, both stopped at the same residual.

Surfaces (../shared/data/meshes, Loop subdivision by trimesh, cached under
--cache): the koala after 1, 2 and 3 subdivisions (0.2M, 0.8M, 3.2M
vertices) and the falcon statue after 4 (6.6M), unit area.

Systems, y ~ N(0, 1), b = M y, S the cotan Laplacian, M the lumped mass:
  poisson:   (S + 1e-6 M) x = M y
  smoothing: (M + 1e-3 S) x = M y
Both solvers stop at the relative residual |b - A x| / |b| < 1e-4 (the
original with its stopping criterion 0), at most 100 cycles.

Every measurement runs in a fresh process that loads the system and then
builds the hierarchy and solves: the hierarchy (ours: mesh edges + the
Gravo hierarchy; the original: its MultigridSolver constructor) and one
solve with a matrix not seen before (ours: checks, Galerkin products,
coarse factorisation and cycles; the original recomputes its coarse
operators on every solve), the fastest of --repeats runs (one above 1M
vertices). Memory: the process's peak resident set (ru_maxrss) less its
resident set after loading the system, i.e. what the hierarchy and the
solve added, per million vertices. The original's cycle count comes from
solves with max_iter = 1, 2, 4, ... and bisection (after its timed solve
and its memory reading). With a CUDA GPU, ours also solves with the torch
backend on the GPU (float64 and float32); none here.

Goals (issue 19), at every size: hierarchy <= 1.0x and solve <= 0.8x the
original's time, with no more cycles.

Usage: python benchmarks/gravo_scale.py [--only NAME ...] [--repeats 2]
       [--plot-only]
Writes benchmarks/results/gravo_scale.json and gravo_scale.png.
"""
import argparse
import json
import os
import resource
import subprocess
import sys
import tempfile
import time

import matplotlib
import numpy as np
import scipy.sparse as sp
import torch
import trimesh

matplotlib.use('Agg')
import matplotlib.pyplot as plt  # noqa: E402

from tg_intrinsic.geometry import (cotan_laplacian, lumped_mass,  # noqa
                                   normalize_area, to_scipy)
from tg_intrinsic.solvers import GravoMG  # noqa: E402
from tg_intrinsic.utils import atomic_write_json, machine_info  # noqa: E402

# the systems, tolerance and oracle of the side-by-side benchmark
from gravo_mg import (HERE, MAX_ITER, PROBLEMS, ROOT, TOL,  # noqa: E402
                      add_original_option, original, original_python,
                      relative)

SURFACES = {'koala-loop1': ('koala', 1), 'koala-loop2': ('koala', 2),
            'koala-loop3': ('koala', 3), 'falconstatue-loop4':
            ('falconstatue_boundary', 4)}


def resident_mb() -> float:
    """The resident set of this process now, MB."""
    with open('/proc/self/statm') as f:
        pages = int(f.read().split()[1])
    return pages * os.sysconf('SC_PAGE_SIZE') / 2 ** 20


def peak_mb() -> float:
    """The peak resident set of this process so far, MB (Linux: KB)."""
    return resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024


def build_system(name, meshes, cache) -> str:
    """The npz of a surface's unit-area mesh, S and the lumped masses,
    made once."""
    path = os.path.join(cache, name + '.npz')
    if os.path.exists(path):
        return path
    mesh_name, loops = SURFACES[name]
    mesh = trimesh.load(os.path.join(meshes, mesh_name + '.obj'),
                        process=True, force='mesh')
    pos, face = np.asarray(mesh.vertices), np.asarray(mesh.faces)
    for _ in range(loops):  # one at a time: trimesh's peak memory
        pos, face = trimesh.remesh.subdivide_loop(pos, face, 1)
    p = torch.from_numpy(pos)
    f = torch.from_numpy(face).t().contiguous()
    p = normalize_area(p, f)
    S = to_scipy(cotan_laplacian(p, f)).tocsr()
    m = lumped_mass(p, f).numpy()
    os.makedirs(cache, exist_ok=True)
    tmp = path + '.part.npz'
    np.savez(tmp, pos=p.numpy(), face=face, data=S.data, indices=S.indices,
             indptr=S.indptr, m=m)
    os.replace(tmp, path)
    return path


def load_problem(path, problem):
    data = np.load(path)
    pos, face, m = data['pos'], data['face'], data['m']
    n = pos.shape[0]
    S = sp.csr_matrix((data['data'], data['indices'], data['indptr']),
                      shape=(n, n))
    weight = PROBLEMS[problem][0]
    M = sp.diags(m).tocsr()
    A = (S + weight * M if problem == 'poisson' else M + weight * S).tocsr()
    b = m * np.random.default_rng(0).normal(size=n)
    return pos, face, m, A, b


def warm_up():
    """Compiles (or loads) the numba kernels outside the timings."""
    mesh = trimesh.creation.icosphere(5)
    pos = torch.from_numpy(np.asarray(mesh.vertices))
    face = torch.from_numpy(np.asarray(mesh.faces)).t().contiguous()
    A = to_scipy(cotan_laplacian(pos, face)).tocsr() + sp.identity(len(pos))
    solver = GravoMG.from_mesh(pos, face, lower_bound=100)
    solver.solve(A.tocsr(), np.ones(len(pos)))


def ours_worker(system, problem, repeats, out):
    """One measurement of ours in this (fresh) process."""
    warm_up()
    pos, face, m, A, b = load_problem(system, problem)
    n = pos.shape[0]
    base = resident_mb()
    edges = np.concatenate([face[:, [0, 1]], face[:, [1, 2]],
                            face[:, [2, 0]]]).T
    hierarchy, solve = np.inf, np.inf
    for _ in range(repeats):
        start = time.perf_counter()
        solver = GravoMG.from_points(pos, edges)
        hierarchy = min(hierarchy, time.perf_counter() - start)
        solver._cache.clear()
        start = time.perf_counter()
        x = solver.solve(A, b, tol=TOL, max_iter=MAX_ITER)
        solve = min(solve, time.perf_counter() - start)
        info = solver.info
    result = {'hierarchy_s': hierarchy, 'seconds': solve,
              'setup_s': info.setup_time, 'iterations': info.iterations,
              'residual': relative(A, b, x), 'base_mb': base,
              'peak_mb': peak_mb(),
              'levels': [n] + [P.shape[1] for P in solver.prolongations]}
    if torch.cuda.is_available():
        for dtype in (torch.float64, torch.float32):
            solver._cache.clear()
            B = torch.from_numpy(b).to('cuda', dtype)
            torch.cuda.synchronize()
            start = time.perf_counter()
            X = solver.solve(A, B, tol=TOL, max_iter=MAX_ITER)
            torch.cuda.synchronize()
            result[f'cuda_{str(dtype)[6:]}'] = {
                'seconds': time.perf_counter() - start,
                'iterations': solver.info.iterations,
                'residual': relative(A, b, X.double().cpu().numpy())}
    atomic_write_json(out, result)


def run_ours(system, problem, repeats):
    with tempfile.TemporaryDirectory() as tmp:
        out = os.path.join(tmp, 'ours.json')
        subprocess.run([sys.executable, __file__, '--worker', system,
                        problem, str(repeats), out], check=True)
        with open(out) as f:
            return json.load(f)


def run_original(python, system, problem, repeats):
    pos, face, m, A, b = load_problem(system, problem)
    return original(python, pos, face, None, A, m, b, repeats)


def summarise(row, problem):
    r = row[problem]
    ours, original = r['ours'], r.get('original')
    n = row['vertices'] / 1e6
    ours['added_mb_per_million'] = (ours['peak_mb'] - ours['base_mb']) / n
    line = (f"{row['surface']:20s} {row['vertices']:8d} {problem:9s} | ours "
            f"hier {ours['hierarchy_s']:6.2f}s solve {ours['seconds']:6.2f}s "
            f"({ours['iterations']} cycles) "
            f"{ours['added_mb_per_million']:5.0f} MB/M")
    if original:
        original['added_mb_per_million'] = (original['peak_mb']
                                            - original['base_mb']) / n
        r['hierarchy_ratio'] = ours['hierarchy_s'] / original['hierarchy_s']
        r['solve_ratio'] = ours['seconds'] / original['seconds']
        r['met_hierarchy'] = r['hierarchy_ratio'] <= 1.0
        r['met_iterations'] = ours['iterations'] <= original['iterations']
        if np.isfinite(original['residual']):
            r['met_solve'] = r['solve_ratio'] <= 0.8
        else:  # a time to a NaN answer is no time to compare with
            r['original_failed'] = 'its solution is NaN'
            r['met_solve'] = bool(ours['residual'] < TOL)
        line += (f" | original hier {original['hierarchy_s']:6.2f}s solve "
                 f"{original['seconds']:6.2f}s ({original['iterations']} "
                 f"cycles) {original['added_mb_per_million']:5.0f} MB/M | "
                 f"ratios {r['hierarchy_ratio']:.2f} {r['solve_ratio']:.2f}")
    print(line, flush=True)


def plot(rows, path):
    fig, axes = plt.subplots(1, 3, figsize=(15, 4))
    n = [r['vertices'] for r in rows]
    for problem, line in (('poisson', '-'), ('smoothing', '--')):
        for key, colour, label in (('ours', 'C0', 'tg_intrinsic'),
                                   ('original', 'C3', 'gravomg 0.0.4')):
            if not all(key in r[problem] for r in rows):
                continue
            values = [r[problem][key] for r in rows]
            axes[0].loglog(n, [v['hierarchy_s'] for v in values], line,
                           color=colour, marker='o',
                           label=f'{label}, {problem}')
            # a solve that returned NaN has no time to show
            solved = [(k, v['seconds']) for k, v in zip(n, values)
                      if np.isfinite(v['residual'])]
            axes[1].loglog(*zip(*solved), line, color=colour, marker='o',
                           label=f'{label}, {problem}')
            axes[2].semilogx(n, [v['added_mb_per_million'] for v in values],
                             line, color=colour, marker='o',
                             label=f'{label}, {problem}')
    titles = ('hierarchy (s)', 'solve, new matrix (s)',
              'peak memory added (MB per million vertices)')
    failed = [r['vertices'] for r in rows
              if 'original_failed' in r['poisson']]
    if failed:
        axes[1].text(0.98, 0.04, 'gravomg 0.0.4 returns NaN at ' + ', '.join(
            f'{k / 1e6:.1f}M' for k in failed), transform=axes[1].transAxes,
            color='C3', ha='right', fontsize=8)
    for ax, title in zip(axes, titles):
        ax.set_xscale('log')
        ax.xaxis.set_minor_formatter(matplotlib.ticker.NullFormatter())
        ax.set_xlabel('vertices')
        ax.set_title(title)
        ax.grid(alpha=0.3, which='both')
    axes[2].set_ylim(bottom=0)
    axes[0].legend(fontsize=7)
    fig.suptitle(f'Gravo MG on Loop-subdivided scans, relative residual '
                 f'{TOL:g}')
    fig.tight_layout()
    fig.savefig(path, dpi=110)


def main():
    if len(sys.argv) > 1 and sys.argv[1] == '--worker':
        system, problem, repeats, out = sys.argv[2:6]
        return ours_worker(system, problem, int(repeats), out)
    parser = argparse.ArgumentParser()
    parser.add_argument('--meshes', default=os.path.join(
        ROOT, '..', 'shared', 'data', 'meshes'))
    parser.add_argument('--cache', default=os.path.join(ROOT, 'data',
                                                        'gravo_scale'))
    add_original_option(parser)
    parser.add_argument('--only', nargs='+', choices=list(SURFACES))
    parser.add_argument('--repeats', type=int, default=2)
    parser.add_argument('--out', default=os.path.join(HERE, 'results'))
    parser.add_argument('--plot-only', action='store_true')
    args = parser.parse_args()
    path = os.path.join(args.out, 'gravo_scale.json')
    if args.plot_only:
        with open(path) as f:
            return plot(json.load(f)['rows'], path[:-5] + '.png')
    args.gravomg_python = original_python(args)
    rows = []
    for name in args.only or SURFACES:
        system = build_system(name, args.meshes, args.cache)
        vertices = int(np.load(system)['m'].shape[0])
        repeats = args.repeats if vertices <= 1_000_000 else 1
        row = {'surface': name, 'vertices': vertices}
        for problem, (_, formula) in PROBLEMS.items():
            row[problem] = {'matrix': formula,
                            'ours': run_ours(system, problem, repeats)}
            if args.gravomg_python:
                row[problem]['original'] = run_original(
                    args.gravomg_python, system, problem, repeats)
            summarise(row, problem)
        rows.append(row)
        atomic_write_json(path, {'machine': machine_info(),
                                 'protocol': __doc__, 'gpu':
                                 torch.cuda.get_device_name()
                                 if torch.cuda.is_available() else None,
                                 'rows': rows})
    plot(rows, path[:-5] + '.png')


if __name__ == '__main__':
    main()
