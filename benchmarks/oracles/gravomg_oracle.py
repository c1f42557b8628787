"""Runs PyPI gravomg 0.0.4 (the original Gravo MG) on a system saved by
tg_intrinsic, in a separate Python that has it (it needs numpy < 2; make
gravomg-env builds one). Usage:

    python gravomg_oracle.py in.npz out.npz

in.npz: pos (N, 3), face (F, 3) or neigh (N, K) padded with -1, the matrix
A as CSR arrays (data, indices, indptr), the lumped mass m and b; optional
tol, lower_bound, max_iter (100) and repeats (timed runs, the fastest
counts; 1). The original stops on its stopping criterion 0, the relative
residual |b - A x| / |b| as ours (its default, 2, is the M-norm relative
residual, looser for b = M y: it stopped at |r| / |b| = 4e-4 for a
tolerance of 1e-4 on an irregular sphere). With save_prolongations the
output also holds the original's prolongation matrices P0_data, ...

out.npz: level sizes, the solution x of the full solve, hierarchy_time
(building the solver: its hierarchy), solve_time (one solve(A, b), which
includes the original's Galerkin products and coarse factorisation),
iterations (cycles to the tolerance; max_iter + 1 if never), and for the
cycle counts in `cycles` the relative residual and the time of a solve
with that max_iter, base_mb and peak_mb (the resident set after loading
the system and the peak after the timed solves, MB) (gravomg reports no iteration count: the script solves
on the same prolongations with max_iter = 1, 2, 4, ... until the
tolerance is met, then bisects). Writes the output atomically."""
import os
import sys
import time

import numpy as np
import scipy.sparse as sp


def resident_mb():
    with open('/proc/self/statm') as f:
        pages = int(f.read().split()[1])
    return pages * os.sysconf('SC_PAGE_SIZE') / 2 ** 20


def peak_mb():
    import resource
    return resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024


def main(source, target):
    import gravomg
    data = np.load(source)
    pos = data['pos']
    n = pos.shape[0]
    A = sp.csr_matrix((data['data'], data['indices'], data['indptr']),
                      shape=(n, n))
    mass = sp.diags(data['m']).tocsr()
    b = data['b']
    tol = float(data['tol']) if 'tol' in data else 1e-4
    lower = int(data['lower_bound']) if 'lower_bound' in data else 1000
    max_iter = int(data['max_iter']) if 'max_iter' in data else 100
    repeats = int(data['repeats']) if 'repeats' in data else 1
    options = dict(lower_bound=lower, tolerance=tol, stopping_criteria=0)
    base_mb = resident_mb()
    if 'face' in data:
        neigh = gravomg.util.neighbors_from_faces(data['face'])
    else:
        neigh = data['neigh']
    hierarchy_time, solve_time = np.inf, np.inf
    for _ in range(repeats):
        start = time.perf_counter()
        solver = gravomg.MultigridSolver(pos, neigh, mass, max_iter=max_iter,
                                         **options)
        hierarchy_time = min(hierarchy_time, time.perf_counter() - start)
        start = time.perf_counter()
        x = np.asarray(solver.solve(A, b)).reshape(-1)
        solve_time = min(solve_time, time.perf_counter() - start)
    peak = peak_mb()  # before the cycle counting below
    prolongations = solver.prolongation_matrices
    sizes = [n] + [P.shape[1] for P in prolongations]

    def run(cycles):
        # No levels of its own (lower bound above N): it takes the full
        # solver's prolongations.
        partial = gravomg.MultigridSolver(pos, neigh, mass, max_iter=cycles,
                                          **dict(options, lower_bound=n + 1))
        partial.set_prolongation_matrices(prolongations)
        start = time.perf_counter()
        xk = np.asarray(partial.solve(A, b)).reshape(-1)
        seconds = time.perf_counter() - start
        return seconds, float(np.linalg.norm(b - A @ xk) / np.linalg.norm(b))

    # Cycles to the tolerance by doubling, then bisection: a few solves
    # instead of one per cycle count.
    history = {}
    cycles = 1
    while cycles < max_iter:
        history[cycles] = run(cycles)
        if history[cycles][1] < tol:
            break
        cycles = min(2 * cycles, max_iter)
    else:
        history[cycles] = run(cycles)
    done = [k for k, (_, r) in history.items() if r < tol]
    if done:
        low = max(k for k, (_, r) in history.items() if r >= tol) \
            if any(r >= tol for _, r in history.values()) else 0
        high = min(done)
        while high - low > 1:
            mid = (low + high) // 2
            history[mid] = run(mid)
            if history[mid][1] < tol:
                high = mid
            else:
                low = mid
        iterations = high
    else:
        iterations = max_iter + 1  # did not converge
    ks = np.array(sorted(history))
    extra = {}
    if 'save_prolongations' in data:
        for k, P in enumerate(prolongations):
            P = sp.csr_matrix(P)
            extra.update({f'P{k}_data': P.data, f'P{k}_indices': P.indices,
                          f'P{k}_indptr': P.indptr,
                          f'P{k}_shape': np.array(P.shape)})
    tmp = target + '.part.npz'
    np.savez(tmp, sizes=np.array(sizes), x=x, cycles=ks,
             residuals=np.array([history[k][1] for k in ks]),
             times=np.array([history[k][0] for k in ks]),
             iterations=iterations, hierarchy_time=hierarchy_time,
             solve_time=solve_time, base_mb=base_mb, peak_mb=peak, **extra)
    os.replace(tmp, target)


if __name__ == '__main__':
    main(sys.argv[1], sys.argv[2])
