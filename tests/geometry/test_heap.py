"""The numba min-heap against Python's heapq: pushes and pops in random
order, with ties, give the same sequence of keys and keep keys and values
together."""
import heapq

import numpy as np
from numba import njit

from tg_intrinsic.geometry.heap import sift_down, sift_up


@njit(cache=True)
def pop(hd, hv, size):
    """Removes the smallest entry; returns it and the new size."""
    key, value = hd[0], hv[0]
    size -= 1
    hd[0] = hd[size]
    hv[0] = hv[size]
    sift_down(hd, hv, 0, size)
    return key, value, size


@njit(cache=True)
def run_operations(keys, pops):
    """Pushes keys[k] with value k; after push k pops pops[k] entries, then
    pops the rest."""
    n = keys.size
    hd = np.empty(n)
    hv = np.empty(n, dtype=np.int64)
    out_keys = np.empty(n)
    out_values = np.empty(n, dtype=np.int64)
    size = count = 0
    for k in range(n + 1):
        if k < n:
            hd[size] = keys[k]
            hv[size] = k
            size += 1
            sift_up(hd, hv, size - 1)
        wanted = pops[k] if k < n else n
        while wanted > 0 and size > 0:
            out_keys[count], out_values[count], size = pop(hd, hv, size)
            count += 1
            wanted -= 1
    return out_keys, out_values


def reference(keys, pops):
    heap, out = [], []
    for k, key in enumerate(keys):
        heapq.heappush(heap, key)
        for _ in range(pops[k]):
            if heap:
                out.append(heapq.heappop(heap))
    while heap:
        out.append(heapq.heappop(heap))
    return np.array(out)


def test_matches_heapq_with_interleaved_pops_and_ties():
    rng = np.random.default_rng(0)
    for trial in range(20):
        n = int(rng.integers(1, 200))
        # few distinct keys: many ties
        keys = rng.integers(0, 1 + trial, n).astype(np.float64)
        pops = rng.integers(0, 3, n)
        out_keys, out_values = run_operations(keys, pops)
        np.testing.assert_array_equal(out_keys, reference(keys, pops))
        # every value popped once, still paired with its own key
        assert sorted(out_values) == list(range(n))
        np.testing.assert_array_equal(keys[out_values], out_keys)


def test_pops_everything_in_sorted_order():
    keys = np.random.default_rng(1).standard_normal(1000)
    assert np.unique(keys).size == keys.size
    out_keys, out_values = run_operations(keys, np.zeros(1000, np.int64))
    np.testing.assert_array_equal(out_keys, np.sort(keys))
    np.testing.assert_array_equal(out_values, np.argsort(keys))
