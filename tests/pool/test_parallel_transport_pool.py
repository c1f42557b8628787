import pytest
import torch

from tg_intrinsic.pool import ParallelTransportPool
from tests.conftest import rel
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
