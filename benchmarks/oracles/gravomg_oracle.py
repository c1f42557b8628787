"""Runs PyPI gravomg 0.0.4 (the original Gravo MG) on a system saved by
tg_intrinsic, in a separate Python that has it (it needs numpy < 2; make
gravomg-env builds one). Usage:

    python gravomg_oracle.py in.npz out.npz

in.npz: pos (N, 3), face (F, 3) or neigh (N, K) padded with -1, the matrix
A as CSR arrays (data, indices, indptr), the lumped mass m and b; optional
tol, lower_bound. out.npz: level sizes, the solution, and the relative
residual after 1, 2, ... cycles (gravomg reports no iteration count, so the
script solves again with max_iter = 1, 2, ... until the tolerance is met).
Writes the output atomically."""
import os
import sys
import time

import numpy as np
import scipy.sparse as sp


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
    if 'face' in data:
        neigh = gravomg.util.neighbors_from_faces(data['face'])
    else:
        neigh = data['neigh']
    residuals, times = [], []
    x = None
    sizes = None
    for cycles in range(1, 101):
        start = time.perf_counter()
        solver = gravomg.MultigridSolver(pos, neigh, mass, lower_bound=lower,
                                         tolerance=tol, max_iter=cycles)
        x = np.asarray(solver.solve(A, b)).reshape(-1)
        times.append(time.perf_counter() - start)
        if sizes is None:
            sizes = [n] + [P.shape[1] for P in solver.prolongation_matrices]
        residuals.append(float(np.linalg.norm(b - A @ x)
                               / np.linalg.norm(b)))
        if residuals[-1] < tol:
            break
    tmp = target + '.part.npz'
    np.savez(tmp, sizes=np.array(sizes), x=x, residuals=np.array(residuals),
             times=np.array(times))
    os.replace(tmp, target)


if __name__ == '__main__':
    main(sys.argv[1], sys.argv[2])
