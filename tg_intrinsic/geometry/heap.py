"""A binary min-heap on two parallel arrays (keys, values) for the numba
shortest-path kernels (fast marching, graph Voronoi, Dijkstra)."""
from .jit import jit


@jit
def sift_up(hd, hv, k):  # pragma: no cover (numba)
    """Moves entry ``k`` of a binary min-heap (keys ``hd``, values ``hv``)
    up to its place."""
    while k > 0:
        parent = (k - 1) >> 1
        if hd[parent] <= hd[k]:
            break
        hd[parent], hd[k] = hd[k], hd[parent]
        hv[parent], hv[k] = hv[k], hv[parent]
        k = parent


@jit
def sift_down(hd, hv, k, size):  # pragma: no cover (numba)
    """Moves entry ``k`` of a binary min-heap of ``size`` entries (keys
    ``hd``, values ``hv``) down to its place."""
    while True:
        left = 2 * k + 1
        if left >= size:
            break
        small = left
        if left + 1 < size and hd[left + 1] < hd[left]:
            small = left + 1
        if hd[k] <= hd[small]:
            break
        hd[small], hd[k] = hd[k], hd[small]
        hv[small], hv[k] = hv[k], hv[small]
        k = small
