"""Gravo MG side by side: tg_intrinsic's GravoMG against the original
(PyPI gravomg 0.0.4, run in its own numpy < 2 environment: make
gravomg-env, or --gravomg-python), pyamg's Ruge-Stuben and smoothed
aggregation solvers (plain V-cycles and as conjugate-gradient
preconditioners), scipy's sparse LU and CHOLMOD (scikit-sparse, when
installed), all in one run.

Systems, on unit-area surfaces, y ~ N(0, 1), b = M y:
  poisson:   (S + 1e-6 M) x = M y
  smoothing: (M + 1e-3 S) x = M y
with S the cotan Laplacian and M the lumped mass (for the point cloud: the
robust point-cloud Laplacian and its masses, on a symmetric 8-nn graph
that both multigrid methods coarsen). Tolerance 1e-4 on the relative
residual |b - A x| / |b|, at most 100 iterations.

Surfaces: icospheres and irregular spheres (the convex hull of random
points whose density varies 55-fold from pole to pole) at ~40k, ~160k and
~650k vertices; the meshes in --meshes (../shared/data/meshes) as they
are, and the lion statue after 2 and 3 Loop subdivisions (~510k, ~2.0M);
and a point cloud (the koala after one subdivision, ~200k points).

Timed per surface (fastest of --repeats runs where marked *):
  hierarchy*   building the multigrid levels (ours: mesh edges + the
               Gravo hierarchy; original: its MultigridSolver constructor)
  new matrix*  one solve with a matrix not seen before: ours = cache
               lookup, checks, Galerkin products, coarse LU and V-cycles;
               the original recomputes its coarse operators on every solve
  cached       ours again with the same matrix (cycles only)
  pcg          ours as a conjugate-gradients preconditioner (new matrix)
  torch        ours with the torch backend on the CPU, float64 and float32
  pyamg        setup + solve, plain and CG-accelerated, per matrix
  direct       scipy splu with its defaults (COLAMD ordering: 1 s at 40k,
               8.5 s at 160k; the symmetric MMD ordering took 24 s at 40k),
               up to --direct-max vertices; CHOLMOD when installed

Goals (issue 5), on every mesh with at least 100k vertices: hierarchy
<= 1.0x and new-matrix solve <= 0.8x the original's time, no more
iterations than the original; PCG faster than plain V-cycles on the
irregular meshes; faster than pyamg SA+CG per new matrix at >= 160k.

Usage: python benchmarks/gravo_mg.py [--only NAME ...] [--quick]
Writes benchmarks/results/gravo_mg.json and gravo_mg.png.
"""
import argparse
import json
import os
import subprocess
import tempfile
import time

import matplotlib
import numpy as np
import scipy.sparse as sp
import torch
import trimesh
from scipy.sparse.linalg import cg, splu

matplotlib.use('Agg')
import matplotlib.pyplot as plt  # noqa: E402

from tg_intrinsic.geometry import (cotan_laplacian, knn, lumped_mass,  # noqa
                                   normalize_area, to_scipy)
from tg_intrinsic.solvers import GravoMG  # noqa: E402
from tg_intrinsic.utils import atomic_write_json, machine_info  # noqa: E402

HERE = os.path.dirname(os.path.abspath(__file__))
ROOT = os.path.dirname(HERE)
ORACLE = os.path.join(HERE, 'oracles', 'gravomg_oracle.py')
TOL, MAX_ITER = 1e-4, 100
PROBLEMS = {'poisson': (1e-6, 'S + 1e-6 M'), 'smoothing': (1e-3, 'M + 1e-3 S')}


# ---------------------------------------------------------------- surfaces
def unit_area(pos, face):
    p = normalize_area(torch.from_numpy(pos), torch.from_numpy(face).t())
    return p.numpy()


def icosphere(subdivisions):
    mesh = trimesh.creation.icosphere(subdivisions)
    return np.asarray(mesh.vertices), np.asarray(mesh.faces)


def irregular_sphere(n, seed=0):
    """Convex hull of n points on the sphere with density exp(2 (z - 1))
    relative to the north pole (55x sparser at the south pole)."""
    rng = np.random.default_rng(seed)
    points = []
    while sum(len(p) for p in points) < n:
        p = rng.normal(size=(2 * n, 3))
        p /= np.linalg.norm(p, axis=1, keepdims=True)
        points.append(p[rng.random(2 * n) < np.exp(2.0 * (p[:, 2] - 1))])
    hull = trimesh.convex.convex_hull(np.concatenate(points)[:n])
    return np.asarray(hull.vertices), np.asarray(hull.faces)


def load_obj(path, loops=0):
    mesh = trimesh.load(path, process=True, force='mesh')
    pos, face = np.asarray(mesh.vertices), np.asarray(mesh.faces)
    if loops:
        pos, face = trimesh.remesh.subdivide_loop(pos, face, loops)
    return pos, face


def surfaces(args):
    """(name, family, builder) in the order they run."""
    out = []
    for sub, label in ((6, '40k'), (7, '160k'), (8, '650k')):
        out.append((f'icosphere-{label}', 'icosphere',
                    lambda s=sub: icosphere(s)))
    for n, label in ((40962, '40k'), (163842, '160k'), (655362, '650k')):
        out.append((f'irregular-{label}', 'irregular',
                    lambda n=n: irregular_sphere(n)))
    folder = args.meshes
    if os.path.isdir(folder):
        for name in sorted(os.listdir(folder)):
            if name.endswith('.obj'):
                out.append((name[:-4], 'real',
                            lambda p=os.path.join(folder, name): load_obj(p)))
        lion = os.path.join(folder, 'lionstatue.obj')
        if os.path.exists(lion):
            for loops in (2, 3):
                out.append((f'lionstatue-loop{loops}', 'subdivided',
                            lambda k=loops: load_obj(lion, k)))
        koala = os.path.join(folder, 'koala.obj')
        if os.path.exists(koala):
            out.append(('koala-cloud', 'cloud',
                        lambda: load_obj(koala, 1)))
    if args.only:
        out = [s for s in out if s[0] in args.only]
    return out


def system(family, pos, face):
    """Unit-area positions, the neighbour graph (2, E) and S, M."""
    pos = unit_area(pos, face)
    if family == 'cloud':
        import robust_laplacian
        S, M = robust_laplacian.point_cloud_laplacian(pos, n_neighbors=30)
        graph = knn(torch.from_numpy(pos), 8).numpy()
        graph = np.concatenate([graph, graph[::-1]], 1)  # symmetric
        return pos, None, graph, sp.csr_matrix(S), M.diagonal()
    p, f = torch.from_numpy(pos), torch.from_numpy(face).t().contiguous()
    S = to_scipy(cotan_laplacian(p, f)).tocsr()
    m = lumped_mass(p, f).numpy()
    graph = np.concatenate([face[:, [0, 1]], face[:, [1, 2]],
                            face[:, [2, 0]]]).T.copy()
    return pos, face, graph, S, m


def padded_neighbours(graph, n):
    """The original's neighbour format: (N, K) padded with -1."""
    src, dst = graph
    key = np.unique(src * n + dst)
    src, dst = key // n, key % n
    counts = np.bincount(src, minlength=n)
    out = np.full((n, counts.max()), -1, dtype=np.int64)
    slot = np.arange(src.size) - np.repeat(np.cumsum(counts) - counts, counts)
    out[src, slot] = dst
    return out


# ---------------------------------------------------------------- runners
def best(fn, repeats):
    times, result = [], None
    for _ in range(repeats):
        start = time.perf_counter()
        result = fn()
        times.append(time.perf_counter() - start)
    return min(times), result


def relative(A, b, x):
    return float(np.linalg.norm(b - A @ x) / np.linalg.norm(b))


def ours(solver, A, b, repeats):
    def new_matrix():
        solver._cache.clear()
        return solver.solve(A, b, tol=TOL, max_iter=MAX_ITER)
    seconds, x = best(new_matrix, repeats)
    info = solver.info
    out = {'seconds': seconds, 'setup_s': info.setup_time,
           'iterations': info.iterations, 'residual': relative(A, b, x),
           'history': [[k + 1, info.setup_time + t, r] for k, (t, r) in
                       enumerate(zip(info.times, info.residuals))]}
    cached, _ = best(lambda: solver.solve(A, b, tol=TOL), repeats)
    out['cached_s'] = cached
    return out, x


def ours_pcg(solver, A, b):
    solver._cache.clear()
    stamps = []
    start = time.perf_counter()
    M = solver.as_preconditioner(A)
    x, flag = cg(A, b, rtol=TOL, maxiter=MAX_ITER, M=M, callback=lambda xk:
                 stamps.append((time.perf_counter() - start, xk.copy())))
    seconds = time.perf_counter() - start
    return {'seconds': seconds, 'iterations': len(stamps),
            'converged': flag == 0, 'residual': relative(A, b, x),
            'history': [[k + 1, t, relative(A, b, xk)]
                        for k, (t, xk) in enumerate(stamps)]}


def ours_torch(solver, A, b, dtype):
    solver._cache.clear()
    B = torch.from_numpy(b).to(dtype)
    start = time.perf_counter()
    x = solver.solve(A, B, tol=TOL, max_iter=MAX_ITER)
    seconds = time.perf_counter() - start
    return {'seconds': seconds, 'iterations': solver.info.iterations,
            'residual': relative(A, b, x.double().numpy())}


def original(python, pos, face, graph, A, m, b, repeats):
    with tempfile.TemporaryDirectory() as tmp:
        source, target = os.path.join(tmp, 'in.npz'), os.path.join(tmp,
                                                                   'out.npz')
        extra = {'face': face} if face is not None else \
            {'neigh': padded_neighbours(graph, pos.shape[0])}
        np.savez(source, pos=pos, data=A.data, indices=A.indices,
                 indptr=A.indptr, m=m, b=b, tol=TOL, max_iter=MAX_ITER,
                 repeats=repeats, **extra)
        env = {k: v for k, v in os.environ.items() if k != 'PYTHONPATH'}
        subprocess.run([python, ORACLE, source, target], check=True, env=env)
        out = np.load(target)
        return {'hierarchy_s': float(out['hierarchy_time']),
                'seconds': float(out['solve_time']),
                'iterations': int(out['iterations']),
                'converged': int(out['iterations']) <= MAX_ITER,
                'sizes': out['sizes'].tolist(),
                'residual': relative(A, b, out['x']),
                'base_mb': float(out['base_mb']),
                'peak_mb': float(out['peak_mb']),
                'history': [[int(k), float(t), float(r)] for k, t, r in
                            zip(out['cycles'], out['times'],
                                out['residuals'])]}


def add_original_option(parser):
    """--gravomg-python: the Python that has gravomg 0.0.4."""
    parser.add_argument('--gravomg-python', default=os.environ.get(
        'TG_GRAVOMG_PYTHON', os.path.join(ROOT, '.gravomg-env', 'bin',
                                          'python')))


def original_python(args):
    """args.gravomg_python, or None (with a message) when it is not
    there."""
    if os.path.exists(args.gravomg_python):
        return args.gravomg_python
    print(f'no gravomg Python at {args.gravomg_python}: the original is '
          f'left out (make gravomg-env)')
    return None


def pyamg_solvers(A, b):
    import pyamg
    out = {}
    for name, build in (('pyamg_rs', pyamg.ruge_stuben_solver),
                        ('pyamg_sa', pyamg.smoothed_aggregation_solver)):
        start = time.perf_counter()
        ml = build(A)
        setup = time.perf_counter() - start
        for accel in (None, 'cg'):
            residuals = []
            start = time.perf_counter()
            x = ml.solve(b, tol=TOL, maxiter=MAX_ITER, residuals=residuals,
                         accel=accel)
            seconds = time.perf_counter() - start
            iterations = len(residuals) - 1
            key = name + ('_cg' if accel else '')
            # pyamg reports no times per iteration: spread evenly.
            out[key] = {
                'setup_s': setup, 'solve_s': seconds,
                'seconds': setup + seconds, 'iterations': iterations,
                'residual': relative(A, b, x),
                'history': [[k + 1,
                             setup + seconds * (k + 1) / max(iterations, 1),
                             r / np.linalg.norm(b)]
                            for k, r in enumerate(residuals[1:])]}
    return out


def direct_solvers(A, b, direct_max):
    out = {}
    if A.shape[0] <= direct_max:
        start = time.perf_counter()
        lu = splu(A.tocsc())
        factor = time.perf_counter() - start
        x = lu.solve(b)
        out['splu'] = {'factor_s': factor,
                       'seconds': time.perf_counter() - start,
                       'residual': relative(A, b, x)}
    else:
        out['splu'] = {'skipped': f'more than --direct-max={direct_max} '
                                  f'vertices'}
    try:
        from sksparse.cholmod import cholesky
    except ImportError:
        out['cholmod'] = {'skipped': 'scikit-sparse is not installed'}
    else:
        start = time.perf_counter()
        x = cholesky(A.tocsc())(b)
        out['cholmod'] = {'seconds': time.perf_counter() - start,
                          'residual': relative(A, b, x)}
    return out


def run(name, family, build, args):
    pos, face = build()
    pos, face, graph, S, m = system(family, pos, face)
    n = pos.shape[0]
    repeats = args.repeats if n <= 1_000_000 else 1
    M = sp.diags(m).tocsr()
    row = {'surface': name, 'family': family, 'vertices': n}

    def hierarchy():
        if face is not None:  # mesh edges from the faces, as the transform
            edges = np.concatenate([face[:, [0, 1]], face[:, [1, 2]],
                                    face[:, [2, 0]]]).T
        else:
            edges = graph
        return GravoMG.from_points(pos, edges, voronoi=args.voronoi)
    row['hierarchy_s'], solver = best(hierarchy, repeats)
    row['levels'] = [n] + [P.shape[1] for P in solver.prolongations]
    y = np.random.default_rng(0).normal(size=n)
    b = m * y
    for problem, (weight, formula) in PROBLEMS.items():
        A = (S + weight * M if problem == 'poisson' else M + weight * S)
        A = A.tocsr()
        result = {'matrix': formula}
        result['ours'], x = ours(solver, A, b, repeats)
        result['ours_pcg'] = ours_pcg(solver, A, b)
        for dtype in (torch.float64, torch.float32):
            result[f'ours_torch_{str(dtype)[6:]}'] = ours_torch(
                solver, A, b, dtype)
        if args.gravomg_python:
            result['original'] = original(args.gravomg_python, pos, face,
                                          graph, A, m, b, repeats)
        result.update(pyamg_solvers(A, b))
        result.update(direct_solvers(A, b, args.direct_max))
        row[problem] = result
        summary(row, problem)
    if args.gravomg_python:  # the same hierarchy was built for each problem
        row['original_hierarchy_s'] = min(row[p]['original']['hierarchy_s']
                                          for p in PROBLEMS)
    return row


def summary(row, problem):
    r = row[problem]
    o = r.get('original')
    line = (f"{row['surface']:24s} {row['vertices']:8d} {problem:9s} | "
            f"hier {row['hierarchy_s']:6.2f}s ours {r['ours']['seconds']:6.2f}"
            f"s ({r['ours']['iterations']:3d} it, cached "
            f"{r['ours']['cached_s']:5.2f}s) pcg {r['ours_pcg']['seconds']:6.2f}"
            f"s ({r['ours_pcg']['iterations']} it)")
    if o:
        line += (f" | original hier {o['hierarchy_s']:6.2f}s solve "
                 f"{o['seconds']:6.2f}s ({o['iterations']} it) | ratios "
                 f"{row['hierarchy_s'] / o['hierarchy_s']:.2f} "
                 f"{r['ours']['seconds'] / o['seconds']:.2f}")
        if not np.isfinite(o['residual']):
            line += ' (original: NaN)'
    line += (f" | SA+CG {r['pyamg_sa_cg']['seconds']:6.2f}s RS "
             f"{r['pyamg_rs']['seconds']:6.2f}s")
    print(line, flush=True)


def goals(rows):
    """Each goal of the issue, per surface where it applies."""
    out = []
    for row in rows:
        if row['vertices'] < 100_000:
            continue
        for problem in PROBLEMS:
            r = row[problem]
            o = r.get('original')
            entry = {'surface': row['surface'], 'problem': problem}
            if o:
                entry['hierarchy_ratio'] = (row['hierarchy_s']
                                            / row['original_hierarchy_s'])
                entry['solve_ratio'] = r['ours']['seconds'] / o['seconds']
                entry['iterations'] = [r['ours']['iterations'],
                                       o['iterations']]
                entry['met_hierarchy'] = entry['hierarchy_ratio'] <= 1.0
                entry['met_iterations'] = \
                    r['ours']['iterations'] <= o['iterations']
                if not np.isfinite(o['residual']):
                    # A time to a NaN answer is no time to compare with.
                    entry['original_failed'] = 'its solution is NaN'
                    entry['met_solve'] = bool(r['ours']['residual'] < TOL)
                else:
                    entry['met_solve'] = entry['solve_ratio'] <= 0.8
            if row['family'] == 'irregular':
                entry['met_pcg_beats_v'] = \
                    r['ours_pcg']['seconds'] < r['ours']['seconds']
            if row['vertices'] >= 160_000:
                entry['ratio_vs_sa_cg'] = (r['ours']['seconds']
                                           / r['pyamg_sa_cg']['seconds'])
                entry['met_beats_sa_cg'] = entry['ratio_vs_sa_cg'] < 1.0
            out.append(entry)
    return out


def plot(rows, path):
    picks = [r for r in rows if r['surface'] in
             ('irregular-650k', 'lionstatue-loop3', 'koala-cloud')] or rows[-1:]
    fig, axes = plt.subplots(len(picks), 4, figsize=(18, 3.8 * len(picks)),
                             squeeze=False)
    styles = {'ours': ('tg_intrinsic V', 'C0', '-'),
              'ours_pcg': ('tg_intrinsic PCG', 'C0', '--'),
              'original': ('gravomg 0.0.4', 'C3', '-'),
              'pyamg_rs': ('pyamg RS', 'C2', '-'),
              'pyamg_rs_cg': ('pyamg RS+CG', 'C2', '--'),
              'pyamg_sa': ('pyamg SA', 'C1', '-'),
              'pyamg_sa_cg': ('pyamg SA+CG', 'C1', '--')}
    for axes_row, row in zip(axes, picks):
        for k, problem in enumerate(PROBLEMS):
            for key, (label, colour, line) in styles.items():
                h = row[problem].get(key, {}).get('history')
                if not h:
                    continue
                cycles, t, r = np.array(h).T
                # The original's points are separate solves (max_iter = 1,
                # 2, 4, ...), so its times carry their own noise.
                marker = '.' if key == 'original' else None
                axes_row[2 * k].semilogy(cycles, r, line, color=colour,
                                         label=label, marker=marker)
                axes_row[2 * k + 1].semilogy(t, r, line, color=colour,
                                             label=label, marker=marker)
            original = row[problem].get('original')
            if original and not np.isfinite(original['residual']):
                axes_row[2 * k].text(0.5, 0.9, 'gravomg 0.0.4 returns NaN',
                                     transform=axes_row[2 * k].transAxes,
                                     color='C3', ha='center', fontsize=8)
            for j, xlabel in enumerate(('iterations', 'seconds (new '
                                        'matrix, hierarchy excluded)')):
                ax = axes_row[2 * k + j]
                ax.axhline(TOL, color='k', lw=0.5)
                ax.set_xlabel(xlabel)
                ax.set_title(f"{row['surface']} ({row['vertices'] / 1e3:.0f}"
                             f"k), {row[problem]['matrix']}", fontsize=9)
        axes_row[0].set_ylabel('relative residual')
    axes[0, 0].legend(fontsize=7)
    fig.tight_layout()
    fig.savefig(path, dpi=110)


def main():
    parser = argparse.ArgumentParser()
    parser.add_argument('--meshes', default=os.path.join(
        ROOT, '..', 'shared', 'data', 'meshes'))
    add_original_option(parser)
    parser.add_argument('--only', nargs='+')
    parser.add_argument('--repeats', type=int, default=2)
    parser.add_argument('--voronoi', default='exact',
                        help="ours: 'exact' or 'sweep' cells")
    parser.add_argument('--direct-max', type=int, default=200_000)
    parser.add_argument('--out', default=os.path.join(HERE, 'results'))
    parser.add_argument('--plot-only', action='store_true')
    args = parser.parse_args()
    path = os.path.join(args.out, 'gravo_mg.json')
    if args.plot_only:
        with open(path) as f:
            return plot(json.load(f)['rows'], path[:-5] + '.png')
    args.gravomg_python = original_python(args)
    # Compile the numba kernels outside the timings.
    pos, face = icosphere(3)
    GravoMG.from_points(pos, face[:, :2].T)
    rows = []
    for name, family, build in surfaces(args):
        rows.append(run(name, family, build, args))
        atomic_write_json(path, {'machine': machine_info(),
                                 'protocol': __doc__,
                                 'voronoi': args.voronoi, 'rows': rows,
                                 'goals': goals(rows)})
    plot(rows, path[:-5] + '.png')


if __name__ == '__main__':
    main()
