"""ParallelTransportUnpool: the copy transported back into every fine
point's frame against a loop, gauge equivariance, pooling it back gives the
coarse features, bad input."""
import cmath

import pytest
import torch

from tg_intrinsic.pool import ParallelTransportPool, ParallelTransportUnpool
from tests.conftest import rel
from tests.pool.conftest import clusters
from tests.symmetry import rotate_streams


def test_unpool_is_gauge_equivariant(gauge_setup):
    n_coarse, cluster, phi, x, fine_angle, coarse_angle, phi2 = gauge_setup
    unpool = ParallelTransportUnpool()
    # coarse features, and the same seen in the turned coarse frames
    y = ParallelTransportPool()(x, cluster, phi, n_coarse)
    y2 = rotate_streams(y, coarse_angle)
    z, z2 = unpool(y, cluster, phi), unpool(y2, cluster, phi2)
    assert rel(z2, rotate_streams(z, fine_angle)) < 1e-12


def test_pooling_what_was_unpooled_gives_it_back(gauge_setup):
    n_coarse, cluster, phi, x, *_ = gauge_setup
    pool, unpool = ParallelTransportPool(), ParallelTransportUnpool()
    y = pool(x, cluster, phi, n_coarse)
    # unpooling a pooled constant-per-cluster field is the identity
    const = unpool(y, cluster, phi)
    assert rel(pool(const, cluster, phi, n_coarse), y) < 1e-12


def test_unpool_rejects_bad_input():
    gen = torch.Generator().manual_seed(3)
    n, n_coarse = 20, 5
    y = torch.randn(n_coarse, 2, 3, dtype=torch.complex128, generator=gen)
    cluster = torch.arange(n) % n_coarse
    phi = torch.rand(n, dtype=torch.float64, generator=gen)
    unpool = ParallelTransportUnpool()
    nan = phi.clone()
    nan[2] = float('nan')
    cases = [
        (lambda: unpool(y[:, 0], cluster, phi), 'complex stream features'),
        (lambda: unpool(y[:3], cluster, phi),
         r"outside \[0, 3\): there are only 3 rows in 'x'"),
        (lambda: unpool(y, -cluster, phi), 'outside'),
        (lambda: unpool(y, cluster.float(), phi), 'torch.long'),
        (lambda: unpool(y, cluster, nan), "'transport' contains NaN"),
        (lambda: unpool(y, cluster, phi.long()), 'float tensor'),
    ]
    for call, match in cases:
        with pytest.raises(ValueError, match=match):
            call()


def test_unpool_matches_a_loop_over_the_points():
    # x_j^M = e^{-i M phi_j} x_{c(j)}^M
    gen = torch.Generator().manual_seed(4)
    y = torch.randn(4, 3, 2, dtype=torch.complex128, generator=gen)
    cluster, phi = clusters(15, 4, gen)
    out = ParallelTransportUnpool()(y, cluster, phi)
    assert out.shape == (15, 3, 2)
    for j in range(15):
        for m in range(3):
            expected = y[int(cluster[j]), m] * cmath.exp(-1j * m *
                                                         float(phi[j]))
            torch.testing.assert_close(out[j, m], expected)


def test_repr():
    assert repr(ParallelTransportUnpool()) == 'ParallelTransportUnpool()'
