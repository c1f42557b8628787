"""Gravo MG applications (thesis 4.5.5) against sparse direct solvers, per
solve, on a real scan of at least 200k vertices: the koala (--meshes,
../shared/data/meshes) after one Loop subdivision (~200k vertices),
scaled to unit area; without the data, an icosphere of 655k vertices
(--quick: a bumpy 10k icosphere).

Data smoothing (eq. 4.4): (M + alpha S + beta S M^-1 S) x = M y for a
noisy signal y = f + noise (f = sin 12x + cos 9y + 2z, noise N(0, 0.5^2)),
S the cotan Laplacian and M the lumped masses, a sweep over the weights in
which every solve has a new matrix:
  laplace   beta = 0, alpha in ALPHAS
  bilaplace (alpha, beta) in BILAPLACE: alpha^2 >= 4 beta factors exactly
            into two Laplace-type solves (smooth's default split); alpha = 0
            does not, and runs conjugate gradients on the full matrix
            preconditioned by one V-cycle per iteration (method='pcg')
Conformal flow: conformalized mean curvature flow, (M_t + h S_0) p = M_t p_t
with the area and centroid kept, STEPS implicit steps of h = STEP; the
masses change every step, so every step is a new matrix.

Timed end to end per solve, relative residual 1e-8 (TOL) for ours:
  ours      tg_intrinsic.solvers.smooth / conformal_flow (Laplacian and
            system assembly included) with the Gravo hierarchy built once
            beforehand (its time is reported on its own, hierarchy_s);
            'cycles' (V-cycles) and 'pcg' where both converge
  splu      scipy's sparse LU (SuperLU, COLAMD ordering) of the same
            system, assembly + factorisation + solve
  cholespy  CHOLMOD's supernodal Cholesky through cholespy (when
            installed: pip install -e .[benchmarks]), the same steps; for the
            split systems also on the two factors (cholespy_split), which
            is the direct solver's best use of the same algebra
Each solve's result is compared with cholespy's (or splu's): the largest
difference relative to the largest value, and the full system's relative
residual.

Usage: python benchmarks/gravo_applications.py [--meshes DIR] [--quick]
Writes benchmarks/results/gravo_applications.json and .png.
"""
import argparse
import importlib.util
import math
import os
import time

import matplotlib
import numpy as np
import scipy.sparse as sp
import torch
import trimesh
from scipy.sparse.linalg import splu

matplotlib.use('Agg')
import matplotlib.pyplot as plt  # noqa: E402
from torch_geometric.data import Data  # noqa: E402

from tg_intrinsic.geometry import lumped_mass, normalize_area  # noqa: E402
from tg_intrinsic.io.figures import render_surface  # noqa: E402
from tg_intrinsic.solvers import (GravoMG, conformal_flow,  # noqa: E402
                                  smooth, stiffness_and_mass)
from tg_intrinsic.utils import atomic_write_json, machine_info  # noqa: E402

HERE = os.path.dirname(os.path.abspath(__file__))
ROOT = os.path.dirname(HERE)
TOL, MAX_ITER = 1e-8, 200
ALPHAS = (1e-5, 1e-4, 1e-3)
BILAPLACE = ((2e-4, 1e-8), (2e-3, 1e-7), (0.0, 1e-8))
STEP, STEPS = 1e-2, 5


def surface(args):
    """(name, unit-area Data) of the benchmark surface."""
    path = os.path.join(args.meshes, 'koala.obj')
    if args.quick:
        mesh = trimesh.creation.icosphere(5)
        pos = mesh.vertices * (1 + 0.1 * np.sin(5 * mesh.vertices[:, :1]))
        name, face = 'bumpy-icosphere-10k', mesh.faces
    elif os.path.exists(path):
        mesh = trimesh.load(path, process=True, force='mesh')
        pos, face = trimesh.remesh.subdivide_loop(
            np.asarray(mesh.vertices), np.asarray(mesh.faces), 1)
        name = 'koala-loop1'
    else:
        mesh = trimesh.creation.icosphere(8)
        name, pos, face = 'icosphere-655k', mesh.vertices, mesh.faces
    face = torch.from_numpy(np.asarray(face, dtype=np.int64)).t()
    pos = normalize_area(torch.from_numpy(np.asarray(pos, dtype=np.float64)),
                         face)
    return name, Data(pos=pos, face=face.contiguous())


def noisy_signal(pos, seed=0):
    x, y, z = pos.numpy().T
    clean = np.sin(12 * x) + np.cos(9 * y) + 2 * z
    noise = np.random.default_rng(seed).normal(0, 0.5, size=clean.shape)
    return clean, clean + noise


def timed(fn):
    start = time.perf_counter()
    out = fn()
    return time.perf_counter() - start, out


def system(data, alpha, beta):
    S, m = stiffness_and_mass(data)
    A = sp.diags(m) + alpha * S
    if beta > 0:
        A = A + beta * (S @ sp.diags(1.0 / m) @ S)
    return (0.5 * (A + A.T)).tocsr(), S, m


def cholespy_solve(A, b):
    from cholespy import CholeskySolverD, MatrixType
    C = A.tocsc()
    solver = CholeskySolverD(A.shape[0], torch.from_numpy(C.indptr),
                             torch.from_numpy(C.indices),
                             torch.from_numpy(C.data), MatrixType.CSC)
    x = torch.zeros(b.shape, dtype=torch.float64)
    solver.solve(torch.from_numpy(np.ascontiguousarray(b)), x)
    return x.numpy()


def splu_solve(A, b):
    return splu(A.tocsc()).solve(b)


def have_cholespy():
    return importlib.util.find_spec('cholespy') is not None


def compare(x, reference, A, b):
    return {'difference': float(np.abs(x - reference).max()
                                / np.abs(reference).max()),
            'residual': float(np.linalg.norm(b - A @ x)
                              / np.linalg.norm(b))}


def smoothing_case(data, solver, y, clean, alpha, beta):
    """One sweep entry: ours (both methods where they converge) and the
    direct solvers, end to end."""
    row = {'alpha': alpha, 'beta': beta,
           'split': beta > 0 and alpha * alpha >= 4 * beta}
    signal = torch.from_numpy(y)

    def direct(solve):
        A, S, m = system(data, alpha, beta)
        return solve(A, m * y)

    if have_cholespy():
        row['cholespy_s'], reference = timed(lambda: direct(cholespy_solve))
        if row['split']:
            def factored():
                S, m = stiffness_and_mass(data)
                root = math.sqrt(alpha * alpha - 4 * beta)
                z = y
                for w in ((alpha + root) / 2, (alpha - root) / 2):
                    z = cholespy_solve((sp.diags(m) + w * S).tocsc(), m * z)
                return z
            row['cholespy_split_s'], x = timed(factored)
            row['cholespy_split_difference'] = float(
                np.abs(x - reference).max() / np.abs(reference).max())
    row['splu_s'], x = timed(lambda: direct(splu_solve))
    if not have_cholespy():
        reference = x
    A, _, m = system(data, alpha, beta)
    b = m * y
    row['splu'] = compare(x, reference, A, b)
    methods = ('cycles', 'pcg') if beta == 0 or row['split'] else ('pcg', )
    for method in methods:
        solver._cache.clear()
        seconds, out = timed(lambda: smooth(
            data, alpha, beta=beta, y=signal, solver=solver, tol=TOL,
            max_iter=MAX_ITER, method=method).numpy())
        info = solver.info
        row[method] = dict(seconds=seconds, iterations=info.iterations,
                           converged=info.converged,
                           setup_s=info.setup_time,
                           **compare(out, reference, A, b))
    best = min(methods, key=lambda k: row[k]['seconds'])
    row['ours_best'] = best
    row['ours_s'] = row[best]['seconds']
    row['rmse_to_clean'] = float(np.sqrt(np.mean((reference - clean) ** 2)))
    for peer in ('splu', 'cholespy', 'cholespy_split'):
        if peer + '_s' in row:
            row[f'speedup_vs_{peer}'] = row[peer + '_s'] / row['ours_s']
    print(f"alpha={alpha:g} beta={beta:g}: ours {row['ours_s']:.2f} s "
          f"({best}, {row[best]['iterations']} it), splu "
          f"{row['splu_s']:.2f} s, cholespy {row.get('cholespy_s', 0):.2f}"
          f" s, rmse {row['rmse_to_clean']:.3f}", flush=True)
    return row, reference


def direct_flow(data, solve):
    """The conformal flow's recurrence with a direct solver per step."""
    S, m = stiffness_and_mass(data)
    p = data.pos.numpy()
    area = m.sum()
    centroid = m @ p / area
    for _ in range(STEPS):
        p = solve((sp.diags(m) + STEP * S).tocsr(), m[:, None] * p)
        m = lumped_mass(torch.from_numpy(p), data.face).numpy()
        scale = math.sqrt(area / m.sum())
        p = (p - m @ p / m.sum()) * scale + centroid
        m = m * scale ** 2
    return p


def flow_case(data, solver):
    row = {'step': STEP, 'steps': STEPS}
    peers = (['cholespy'] if have_cholespy() else []) + ['splu']
    solves = {'cholespy': cholespy_solve, 'splu': splu_solve}
    reference = None
    for peer in peers:
        seconds, p = timed(lambda: direct_flow(data, solves[peer]))
        row[peer + '_s'] = seconds / STEPS
        if reference is None:
            reference = p
        row[peer + '_difference'] = float(np.abs(p - reference).max())
    size = float(np.ptp(reference, 0).max())
    for method in ('cycles', 'pcg'):
        iterations = []
        seconds, flow = timed(lambda: conformal_flow(
            data, STEP, STEPS, solver=solver, tol=TOL, max_iter=MAX_ITER,
            method=method, callback=lambda t, info: iterations.append(
                info.iterations)))
        row[method] = {'seconds_per_step': seconds / STEPS,
                       'iterations': iterations,
                       'difference': float(np.abs(flow[-1].numpy()
                                                  - reference).max() / size)}
    best = min(('cycles', 'pcg'), key=lambda k: row[k]['seconds_per_step'])
    row['ours_best'], row['ours_s'] = best, row[best]['seconds_per_step']
    for peer in peers:
        row[f'speedup_vs_{peer}'] = row[peer + '_s'] / row['ours_s']
    print(f"conformal flow: ours {row['ours_s']:.2f} s/step ({best}), "
          + ', '.join(f"{p} {row[p + '_s']:.2f} s/step" for p in peers),
          flush=True)
    return row, reference


def plot(result, pictures, path):
    fig = plt.figure(figsize=(16, 7.5))
    grid = fig.add_gridspec(2, 4)
    ax = fig.add_subplot(grid[:, :2])
    cases = [(f"alpha={r['alpha']:g}" + (f"\nbeta={r['beta']:g}"
                                         if r['beta'] else ''), r)
             for r in result['smoothing']]
    cases.append(("conformal flow\n(per step)", result['conformal_flow']))
    peers = [('ours_s', 'tg_intrinsic Gravo MG', 'C0'),
             ('splu_s', 'scipy splu', 'C3'),
             ('cholespy_s', 'cholespy (CHOLMOD)', 'C2'),
             ('cholespy_split_s', 'cholespy, split factors', 'C8')]
    width = 0.2
    for k, (key, label, colour) in enumerate(peers):
        xs = [i for i, (_, r) in enumerate(cases) if key in r]
        ax.bar(np.array(xs) + (k - 1.5) * width,
               [cases[i][1][key] for i in xs], width, label=label,
               color=colour)
    ax.set_xticks(range(len(cases)))
    ax.set_xticklabels([c for c, _ in cases], fontsize=7)
    ax.set_yscale('log')
    ax.set_ylabel('seconds per solve (assembly included)')
    ax.set_title(f"{result['surface']} ({result['vertices'] / 1e3:.0f}k "
                 f"vertices), relative residual {TOL:g}")
    ax.legend(fontsize=8)
    for k, (title, image) in enumerate(pictures):
        a = fig.add_subplot(grid[k // 2, 2 + k % 2])
        a.imshow(image)
        a.set_title(title, fontsize=9)
        a.set_axis_off()
    fig.tight_layout()
    fig.savefig(path, dpi=100)


def main():
    parser = argparse.ArgumentParser()
    parser.add_argument('--meshes', default=os.path.join(
        ROOT, '..', 'shared', 'data', 'meshes'))
    parser.add_argument('--quick', action='store_true')
    parser.add_argument('--out', default=os.path.join(HERE, 'results'))
    args = parser.parse_args()
    name, data = surface(args)
    path = os.path.join(args.out, 'gravo_applications.json')
    # numba kernels compiled outside the timings
    warm = trimesh.creation.icosphere(3)
    GravoMG.from_points(warm.vertices, warm.faces[:, :2].T)
    hierarchy_s, solver = timed(lambda: GravoMG.from_points(
        data.pos, torch.cat([data.face[[0, 1]], data.face[[1, 2]],
                             data.face[[2, 0]]], 1)))
    result = {'surface': name, 'vertices': int(data.pos.size(0)),
              'hierarchy_s': hierarchy_s,
              'levels': [solver.num_points] + [P.shape[1] for P in
                                               solver.prolongations],
              'tol': TOL, 'cholespy': have_cholespy(),
              'load_average_1min_before': os.getloadavg()[0]}
    clean, y = noisy_signal(data.pos)
    smoothed = {}
    result['smoothing'] = []
    for alpha, beta in [(a, 0.0) for a in ALPHAS] + list(BILAPLACE):
        if args.quick and (alpha, beta) not in ((1e-4, 0.0), BILAPLACE[0],
                                                BILAPLACE[-1]):
            continue
        row, x = smoothing_case(data, solver, y, clean, alpha, beta)
        result['smoothing'].append(row)
        smoothed[(alpha, beta)] = x
        atomic_write_json(path, {'machine': machine_info(),
                                 'protocol': __doc__, **result})
    result['conformal_flow'], flowed = flow_case(data, solver)
    result['load_average_1min_after'] = os.getloadavg()[0]
    atomic_write_json(path, {'machine': machine_info(), 'protocol': __doc__,
                             **result})
    best = {kind: min((r for r in result['smoothing'] if (r['beta'] > 0)
                       == kind), key=lambda r: r['rmse_to_clean'])
            for kind in (False, True)}
    lo, hi = np.percentile(clean, [1, 99])
    pictures = [('noisy signal', y)] + [
        (f"{'bi-Laplace' if k else 'Laplace'} (alpha={r['alpha']:g}, "
         f"beta={r['beta']:g}), RMSE {r['rmse_to_clean']:.3f}",
         smoothed[(r['alpha'], r['beta'])]) for k, r in best.items()]
    images = [(t, render_surface(data.pos, data.face, values=v, vmin=lo,
                                 vmax=hi, views=('front-left', ),
                                 size=300)[0]) for t, v in pictures]
    images.append((f'conformal flow, {STEPS} steps of h={STEP:g}',
                   render_surface(flowed, data.face, views=('front-left', ),
                                  size=300)[0]))
    plot(result, images, path[:-5] + '.png')


if __name__ == '__main__':
    main()
