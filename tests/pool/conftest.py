"""Shared inputs of the pooling tests: a two-level Gravo hierarchy, and
clusters of fine points with their transport angles."""
import pytest
import torch
from torch_geometric.data import Data

from tg_intrinsic.transforms import GravoHierarchy


def hierarchy(pos, face):
    return GravoHierarchy(lower_bound=20, max_levels=2)(
        Data(pos=pos, face=face))


def clusters(n, n_coarse, generator):
    """A cluster index of n fine points onto n_coarse coarse ones, every
    cluster non-empty, and an arbitrary transport angle per fine point."""
    cluster = torch.cat([torch.arange(n_coarse),
                         torch.randint(0, n_coarse, (n - n_coarse,),
                                       generator=generator)])
    phi = torch.rand(n, dtype=torch.float64, generator=generator) * 6
    return cluster, phi


@pytest.fixture
def gauge_setup():
    """Fine features, clusters, angles, frame turns of the fine and coarse
    points and the transport angles seen in the turned frames."""
    gen = torch.Generator().manual_seed(2)
    n, n_coarse = 50, 12
    cluster, phi = clusters(n, n_coarse, gen)
    x = torch.randn(n, 3, 4, dtype=torch.complex128, generator=gen)
    fine_angle = torch.rand(n, dtype=torch.float64, generator=gen) * 6
    coarse_angle = torch.rand(n_coarse, dtype=torch.float64,
                              generator=gen) * 6
    # transport j -> c(j) seen in turned frames
    phi2 = phi - coarse_angle[cluster] + fine_angle
    return n_coarse, cluster, phi, x, fine_angle, coarse_angle, phi2


def small_prolongation():
    """A hand-made prolongation of 5 fine points onto 3 coarse ones:
    ``(prolong_index, prolong_weight, P)`` with ``P`` the dense
    ``[5, 3]`` matrix, built entry by entry."""
    index = torch.tensor([[0, 1, 1, 2, 3, 3, 4, 4],
                          [0, 0, 1, 1, 1, 2, 2, 0]])
    weight = torch.tensor([1.0, 0.25, 0.75, 1.0, 0.5, 0.5, 0.9, 0.1],
                          dtype=torch.float64)
    dense = torch.zeros(5, 3, dtype=torch.float64)
    for (fine, coarse), w in zip(index.t().tolist(), weight.tolist()):
        dense[fine, coarse] += w
    return index, weight, dense
