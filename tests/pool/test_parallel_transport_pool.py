"""ParallelTransportPool: the transported mean (or sum) of every cluster
against a loop over the points, empty clusters, gauge equivariance, bad
input."""
import cmath

import pytest
import torch

from tg_intrinsic.pool import ParallelTransportPool
from tests.conftest import rel
from tests.pool.conftest import clusters
from tests.symmetry import rotate_streams


def test_pool_is_gauge_equivariant(gauge_setup):
    n_coarse, cluster, phi, x, fine_angle, coarse_angle, phi2 = gauge_setup
    pool = ParallelTransportPool()
    y = pool(x, cluster, phi, n_coarse)
    y2 = pool(rotate_streams(x, fine_angle), cluster, phi2, n_coarse)
    assert rel(y2, rotate_streams(y, coarse_angle)) < 1e-12


def test_pool_rejects_bad_input():
    gen = torch.Generator().manual_seed(3)
    n, n_coarse = 20, 5
    x = torch.randn(n, 2, 3, dtype=torch.complex128, generator=gen)
    cluster = torch.arange(n) % n_coarse
    phi = torch.rand(n, dtype=torch.float64, generator=gen)
    pool = ParallelTransportPool()
    nan = phi.clone()
    nan[2] = float('nan')
    cases = [
        # features, cluster index, angles, cluster count
        (lambda: pool(x[:, 0], cluster, phi), 'complex stream features'),
        (lambda: pool(x.real, cluster, phi), 'complex stream features'),
        (lambda: pool(x, cluster - 1, phi, None), 'negative indices'),
        (lambda: pool(x, cluster + 1, phi, n_coarse),
         r"'cluster' holds indices in \[1, 5\], outside \[0, 5\)"),
        (lambda: pool(x, cluster.double(), phi), 'torch.long'),
        (lambda: pool(x, cluster[:-1], phi), r'shape \[20\]'),
        (lambda: pool(x, cluster, nan), "'transport' contains NaN"),
        (lambda: pool(x, cluster, phi[:-1]), r"'transport' must have "
                                             r"shape \[20\]"),
        (lambda: pool(x, cluster, phi, -1), "'num_clusters' must be at"),
    ]
    for call, match in cases:
        with pytest.raises(ValueError, match=match):
            call()


def brute_force_pool(x, cluster, phi, num_clusters, mean):
    """Every cluster's sum (or mean) of e^{i M phi_j} x_j^M, point by point
    with Python complex numbers."""
    n, streams, channels = x.shape
    out = torch.zeros(num_clusters, streams, channels, dtype=x.dtype)
    count = [0] * num_clusters
    for j in range(n):
        c = int(cluster[j])
        count[c] += 1
        for m in range(streams):
            out[c, m] += x[j, m] * cmath.exp(1j * m * float(phi[j]))
    if mean:
        for c in range(num_clusters):
            out[c] /= max(count[c], 1)
    return out


@pytest.mark.parametrize('reduce', ['mean', 'sum'])
def test_pool_matches_a_loop_over_the_points(reduce):
    gen = torch.Generator().manual_seed(4)
    x = torch.randn(15, 3, 2, dtype=torch.complex128, generator=gen)
    cluster, phi = clusters(15, 4, gen)
    out = ParallelTransportPool(reduce)(x, cluster, phi, 4)
    assert out.shape == (4, 3, 2)
    torch.testing.assert_close(
        out, brute_force_pool(x, cluster, phi, 4, reduce == 'mean'))
    # without a cluster count the largest index decides
    torch.testing.assert_close(ParallelTransportPool(reduce)(x, cluster, phi),
                               out)


def test_empty_clusters_are_zero():
    gen = torch.Generator().manual_seed(5)
    x = torch.randn(6, 2, 3, dtype=torch.complex128, generator=gen)
    cluster, phi = clusters(6, 2, gen)
    out = ParallelTransportPool()(x, cluster, phi, 4)
    assert out.shape == (4, 2, 3)
    assert (out[2:] == 0).all() and (out[:2] != 0).all()


def test_reduce_is_checked_and_shown():
    assert repr(ParallelTransportPool()) == \
        "ParallelTransportPool(reduce='mean')"
    assert repr(ParallelTransportPool('sum')) == \
        "ParallelTransportPool(reduce='sum')"
    with pytest.raises(ValueError, match="reduce must be 'mean' or 'sum', "
                                         "got 'max'"):
        ParallelTransportPool('max')
