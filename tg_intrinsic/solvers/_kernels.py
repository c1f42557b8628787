"""Compiled kernels for GravoMG on the CPU: a bit-exact fingerprint of a
sparse matrix for the per-matrix cache, the input checks (symmetry by
random probes), the matrix-vector product and the Galerkin product R A P
in one parallel pass."""
import numpy as np
import scipy.sparse as sp
from numba import get_num_threads, prange

from tg_intrinsic.geometry.jit import jit


@jit
def _mix(h, word):  # pragma: no cover (numba)
    # splitmix64 finaliser over the running state
    h = (h ^ word) * np.uint64(0x9E3779B97F4A7C15)
    h ^= h >> np.uint64(31)
    h *= np.uint64(0xBF58476D1CE4E5B9)
    return h ^ (h >> np.uint64(27))


@jit(parallel=True)
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


def matvec(A: sp.csr_matrix, x: np.ndarray) -> np.ndarray:
    """A @ x for a CSR matrix and a vector: scipy's serial product, which
    beat a parallel numba one on this project's 2-core machine (1.9 vs
    2.7 ms at 1.4M entries, 11 vs 18 ms at 5.6M)."""
    return A @ x


@jit(parallel=True)
def _triple_rows(r_ptr, r_idx, r_val, a_ptr, a_idx, a_val, p_ptr, p_idx,
                 p_val, n_cols, rows, width, counts, cols, vals,
                 blocks):  # pragma: no cover (numba)
    """Rows ``rows[t]`` of R A P, sorted, into ``width`` slots each
    (``cols``, ``vals`` from ``t * width``), blocks of rows in parallel;
    ``counts[t]`` is the row's true length, its entries written only when
    it fits."""
    m = rows.shape[0]
    for k in prange(blocks):
        owner = np.full(n_cols, -1, dtype=np.int64)
        where = np.empty(n_cols, dtype=np.int64)
        for t in range(k * m // blocks, (k + 1) * m // blocks):
            row, base, found = rows[t], t * width, 0
            for q in range(r_ptr[row], r_ptr[row + 1]):
                i = r_idx[q]
                for s in range(a_ptr[i], a_ptr[i + 1]):
                    j = a_idx[s]
                    weight = r_val[q] * a_val[s]
                    for u in range(p_ptr[j], p_ptr[j + 1]):
                        col = p_idx[u]
                        if owner[col] != t:
                            owner[col] = t
                            where[col] = base + found if found < width \
                                else -1
                            if found < width:
                                cols[base + found] = col
                                vals[base + found] = weight * p_val[u]
                            found += 1
                        elif where[col] >= 0:
                            vals[where[col]] += weight * p_val[u]
            counts[t] = found
            if found <= width:  # insertion sort: rows are short
                for a in range(base + 1, base + found):
                    col, value = cols[a], vals[a]
                    b = a - 1
                    while b >= base and cols[b] > col:
                        cols[b + 1], vals[b + 1] = cols[b], vals[b]
                        b -= 1
                    cols[b + 1], vals[b + 1] = col, value


@jit(parallel=True)
def _pack_rows(indptr, width, cols, vals, spill, spill_width, spill_cols,
               spill_vals):  # pragma: no cover (numba)
    """CSR indices and data from rows in slots (a row ``r`` with
    ``spill[r] >= 0`` from the wider spill slots)."""
    n = indptr.shape[0] - 1
    indices = np.empty(indptr[n], dtype=np.int32)
    data = np.empty(indptr[n], dtype=np.float64)
    for r in prange(n):
        length = indptr[r + 1] - indptr[r]
        if spill[r] < 0:
            source = r * width
            indices[indptr[r]:indptr[r + 1]] = cols[source:source + length]
            data[indptr[r]:indptr[r + 1]] = vals[source:source + length]
        else:
            source = spill[r] * spill_width
            indices[indptr[r]:indptr[r + 1]] = \
                spill_cols[source:source + length]
            data[indptr[r]:indptr[r + 1]] = spill_vals[source:source + length]
    return indices, data


def _rows_of_product(R, A, P, rows, width):
    counts = np.empty(rows.size, dtype=np.int64)
    cols = np.empty(rows.size * width, dtype=np.int32)
    vals = np.empty(rows.size * width, dtype=np.float64)
    _triple_rows(R.indptr, R.indices, R.data, A.indptr, A.indices, A.data,
                 P.indptr, P.indices, P.data, P.shape[1], rows, width,
                 counts, cols, vals, max(1, min(rows.size,
                                                8 * get_num_threads())))
    return counts, cols, vals


def galerkin(R: sp.csr_matrix, A: sp.csr_matrix,
             P: sp.csr_matrix, width: int = 48) -> sp.csr_matrix:
    """R A P in one compiled pass over the coarse rows, in parallel, each
    row gathered with a dense accumulator into :obj:`width` slots (rows
    that do not fit are redone with wider ones). scipy's two products run
    on one core, with A P built in between."""
    n_out = R.shape[0]
    counts, cols, vals = _rows_of_product(R, A, P, np.arange(n_out), width)
    spill = np.full(n_out, -1, dtype=np.int64)
    wide = np.flatnonzero(counts > width)
    spill_width = int(counts[wide].max()) if wide.size else 0
    spill[wide] = np.arange(wide.size)
    _, spill_cols, spill_vals = _rows_of_product(R, A, P, wide, spill_width)
    indptr = np.zeros(n_out + 1, dtype=np.int64)
    np.cumsum(counts, out=indptr[1:])
    indices, data = _pack_rows(indptr, width, cols, vals, spill, spill_width,
                               spill_cols, spill_vals)
    if indptr[-1] < 2 ** 31:
        indptr = indptr.astype(np.int32)
    return sp.csr_matrix((data, indices, indptr), shape=(n_out, P.shape[1]))
