"""Circular-harmonic terms against their definition, edge by edge."""
import math

import torch

from tg_intrinsic.geometry.geodesics.harmonic import (harmonic_terms,
                                                      ring_weights)

D64 = torch.float64


def test_ring_weights_interpolate_and_vanish_at_the_radius():
    r = torch.tensor([0.0, 0.1, 0.25, 0.49, 0.5, 0.7], dtype=torch.float64)
    mu = ring_weights(r, 0.5, 4)  # rings at 0, .125, .25, .375
    assert torch.allclose(mu[0], torch.tensor([1., 0, 0, 0],
                                              dtype=torch.float64))
    assert torch.allclose(mu[1], torch.tensor([.2, .8, 0, 0],
                                              dtype=torch.float64))
    assert torch.allclose(mu[2], torch.tensor([0., 0, 1, 0],
                                              dtype=torch.float64))
    assert mu[3].sum() < 0.1 and (mu[4:] == 0).all()


def test_terms_follow_their_definition_edge_by_edge():
    # h[e, q, m] = w_j / sum_{k in N(i)} w_k * mu_q(r_ij) * e^{i m theta_ij}
    g = torch.Generator().manual_seed(3)
    n = 12
    j, i = torch.cartesian_prod(torch.arange(n), torch.arange(n)).t()
    keep = torch.rand(j.numel(), generator=g) < 0.5
    keep |= j == i
    edge_index = torch.stack([j[keep], i[keep]])
    r = torch.rand(edge_index.size(1), generator=g, dtype=D64) * 0.6
    r[edge_index[0] == edge_index[1]] = 0.0
    theta = (torch.rand(edge_index.size(1), generator=g, dtype=D64) - 0.5) \
        * 2 * math.pi
    weight = torch.rand(n, generator=g, dtype=D64) + 0.5
    h = harmonic_terms(edge_index, torch.stack([r, theta], 1), weight, 0.5,
                       rings=5, max_order=2)
    assert h.shape == (edge_index.size(1), 5, 3)
    total = torch.zeros(n, dtype=D64).index_add_(0, edge_index[1],
                                                 weight[edge_index[0]])
    mu = ring_weights(r, 0.5, 5)
    for e in range(edge_index.size(1)):
        share = weight[edge_index[0, e]] / total[edge_index[1, e]]
        for m in range(3):
            angle = 0.0 if (m and r[e] == 0) else m * float(theta[e])
            want = share * mu[e] * complex(math.cos(angle),
                                           math.sin(angle))
            if m and r[e] == 0:
                want = torch.zeros_like(want)
            torch.testing.assert_close(h[e, :, m],
                                       want.to(h.dtype), rtol=1e-12,
                                       atol=1e-14)
