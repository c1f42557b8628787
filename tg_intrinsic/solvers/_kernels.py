"""Compiled kernels for GravoMG on the CPU: a bit-exact fingerprint of a
sparse matrix for the per-matrix cache, the input checks (symmetry by
random probes), a parallel sparse matrix-vector product (scipy's runs on one core) and the
Galerkin product on row blocks in threads."""
import os
from concurrent.futures import ThreadPoolExecutor

import numpy as np
import scipy.sparse as sp
from numba import get_num_threads, njit, prange


@njit(cache=True)
def _mix(h, word):  # pragma: no cover (numba)
    # splitmix64 finaliser over the running state
    h = (h ^ word) * np.uint64(0x9E3779B97F4A7C15)
    h ^= h >> np.uint64(31)
    h *= np.uint64(0xBF58476D1CE4E5B9)
    return h ^ (h >> np.uint64(27))


@njit(cache=True, parallel=True)
def _hash_blocks(words, seed, blocks):  # pragma: no cover (numba)
    """One hash per block of words (in parallel), then the hash of those."""
    out = np.empty(blocks, dtype=np.uint64)
    n = words.shape[0]
    for k in prange(blocks):
        h = _mix(seed, np.uint64(k))
        for i in range(k * n // blocks, (k + 1) * n // blocks):
            h = _mix(h, words[i])
        out[k] = h
    h = _mix(seed, np.uint64(n))
    for k in range(blocks):
        h = _mix(h, out[k])
    return h


def _words(index: np.ndarray) -> np.ndarray:
    """An index array as 64-bit words without widening int32 (padded with
    one zero to an even length, its length hashed separately)."""
    index = np.ascontiguousarray(index)
    if index.dtype.itemsize == 4:
        if index.size % 2:
            index = np.concatenate([index, np.zeros(1, index.dtype)])
        return index.view(np.int64)
    return index.astype(np.int64)


def fingerprint(A: sp.csr_matrix) -> str:
    """A 128-bit hash of the exact bits of A (shape, pattern and values):
    two independently seeded 64-bit lanes."""
    parts = [np.asarray(A.shape, dtype=np.int64), _words(A.indptr),
             _words(A.indices), np.ascontiguousarray(A.data)]
    blocks = 4 * get_num_threads()
    lanes = []
    for seed in (0x243F6A8885A308D3, 0x13198A2E03707344):
        h = np.uint64(seed)
        for part in parts:
            h = np.uint64(_hash_blocks(part.view(np.uint64), h, blocks))
        lanes.append(f'{int(h):016x}')
    return ''.join(lanes)


def check_matrix(A: sp.csr_matrix):
    """(all finite, max |a_ij|, symmetry defect) of a CSR matrix. The
    defect is |u.(A v) - v.(A u)| / (|u| |A v| + |v| |A u|) for Gaussian
    probes u, v: rounding keeps it near 1e-16 for a symmetric A; an
    asymmetry in every entry of relative size d gives about d / sqrt(N),
    one entry d / N. Two parallel products instead of a transpose (which
    cost 60 ms at 160k vertices in random order)."""
    finite = bool(np.isfinite(A.data).all())
    if not finite or A.nnz == 0:
        return finite, 0.0, 0.0
    scale = float(np.abs(A.data).max())
    rng = np.random.default_rng(0x5EED)
    u, v = rng.normal(size=(2, A.shape[0]))
    Av, Au = matvec(A, v), matvec(A, u)
    size = np.linalg.norm(u) * np.linalg.norm(Av) \
        + np.linalg.norm(v) * np.linalg.norm(Au)
    defect = abs(u @ Av - v @ Au) / size if size > 0 else 0.0
    return finite, scale, float(defect)


@njit(cache=True, parallel=True)
def _spmv(indptr, indices, data, x, out):  # pragma: no cover (numba)
    for i in prange(indptr.shape[0] - 1):
        total = 0.0
        for p in range(indptr[i], indptr[i + 1]):
            total += data[p] * x[indices[p]]
        out[i] = total
    return out


def matvec(A: sp.csr_matrix, x: np.ndarray) -> np.ndarray:
    """A @ x for a CSR matrix and a vector, rows in parallel."""
    return _spmv(A.indptr, A.indices, A.data, x, np.empty(A.shape[0]))


def _row_blocks_product(X: sp.csr_matrix, Y: sp.csr_matrix, pool,
                        parts: int) -> sp.csr_matrix:
    cuts = [X.shape[0] * k // parts for k in range(parts + 1)]
    blocks = pool.map(lambda k: X[cuts[k]:cuts[k + 1]] @ Y, range(parts))
    return sp.vstack(list(blocks), format='csr')


def galerkin(R: sp.csr_matrix, A: sp.csr_matrix,
             P: sp.csr_matrix) -> sp.csr_matrix:
    """R (A P), each product on row blocks in threads: scipy releases the
    GIL for part of it (measured 0.34 s -> 0.26 s at 655k on 2 cores)."""
    parts = min(os.cpu_count() or 1, 8)
    if parts == 1 or A.shape[0] < 50_000:
        return (R @ (A @ P)).tocsr()
    with ThreadPoolExecutor(parts) as pool:
        return _row_blocks_product(R, _row_blocks_product(A, P, pool, parts),
                                   pool, parts)
