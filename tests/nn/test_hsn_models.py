import math

import pytest
import torch
from torch_geometric.data import Batch

from tg_intrinsic.data import IntrinsicData
from tg_intrinsic.geometry.geodesics.harmonic import harmonic_terms
from tg_intrinsic.nn.models import HSNClassification, HSNSegmentation
from tests.nn.test_harmonic_conv import rel
from tests.symmetry import gauge_change

RINGS = 4


def disc_graph(pos, radius):
    j, i = (torch.cdist(pos, pos) < radius).nonzero().t()
    diff = pos[j] - pos[i]
    logmap = torch.stack([diff.norm(dim=1),
                          torch.atan2(diff[:, 1], diff[:, 0])], 1)
    return torch.stack([j, i]), logmap


def two_level_data(seed, n=50, n1=12, angle0=None, angle1=None,
                   max_order=2):
    """Two levels of planar discs with arbitrary transport angles, seen in
    frames turned by angle0 (level 0) and angle1 (level 1)."""
    gen = torch.Generator().manual_seed(seed)
    pos = torch.rand(n, 2, dtype=torch.float64, generator=gen)
    sample = torch.randperm(n, generator=gen)[:n1]
    cluster = torch.cdist(pos, pos[sample]).argmin(1)
    edge_index, logmap = disc_graph(pos, 0.35)
    edge_index1, logmap1 = disc_graph(pos[sample], 0.6)
    transport = torch.rand(edge_index.size(1), dtype=torch.float64,
                           generator=gen) * 6
    transport1 = torch.rand(edge_index1.size(1), dtype=torch.float64,
                            generator=gen) * 6
    pool_transport = torch.rand(n, dtype=torch.float64, generator=gen) * 6
    x = torch.randn(n, 3, dtype=torch.float64, generator=gen)
    area = torch.rand(n, dtype=torch.float64, generator=gen) + 0.5
    if angle0 is not None:
        logmap, transport = gauge_change(edge_index, logmap, transport,
                                         angle0)
        logmap1, transport1 = gauge_change(edge_index1, logmap1, transport1,
                                           angle1)
        pool_transport = pool_transport - angle1[cluster] + angle0
    return IntrinsicData(
        x=x, pos=torch.cat([pos, torch.zeros(n, 1, dtype=pos.dtype)], 1),
        edge_index=edge_index, transport=transport,
        harmonic=harmonic_terms(edge_index, logmap, area, 0.35, RINGS,
                                max_order),
        pos_1=pos[sample], edge_index_1=edge_index1, transport_1=transport1,
        harmonic_1=harmonic_terms(edge_index1, logmap1, area[sample], 0.6,
                                  RINGS, max_order),
        cluster_1=cluster, sample_index_1=sample,
        pool_transport_1=pool_transport, y=torch.tensor([seed % 3]))


@pytest.mark.parametrize('Model', [HSNClassification, HSNSegmentation])
@pytest.mark.parametrize('max_order', [1, 2])
def test_predictions_are_gauge_invariant(Model, max_order):
    gen = torch.Generator().manual_seed(9)
    angle0 = torch.rand(50, dtype=torch.float64, generator=gen) * 2 * math.pi
    angle1 = torch.rand(12, dtype=torch.float64, generator=gen) * 2 * math.pi
    torch.manual_seed(0)
    model = Model(3, 5, channels=(4, 6), max_order=max_order,
                  rings=RINGS).double()
    model.eval()
    with torch.no_grad():
        for p in model.parameters():  # no trivial zero outputs
            p.add_(0.05 * torch.randn_like(p))
    out = model(two_level_data(1, max_order=max_order))
    out2 = model(two_level_data(1, angle0=angle0, angle1=angle1,
                                max_order=max_order))
    assert out.abs().max() > 1e-3
    assert rel(out2, out) < 1e-8
    # training mode (batch statistics) too, with gradients
    model.train()
    out = model(two_level_data(1, max_order=max_order))
    grads = torch.autograd.grad(out.square().sum(), model.parameters())
    out2 = model(two_level_data(1, angle0=angle0, angle1=angle1,
                                max_order=max_order))
    grads2 = torch.autograd.grad(out2.square().sum(), model.parameters())
    assert rel(out2, out) < 1e-8
    for a, b in zip(grads2, grads):
        assert rel(a, b) < 1e-7


@pytest.mark.parametrize('Model', [HSNClassification, HSNSegmentation])
def test_batched_equals_per_example(Model):
    torch.manual_seed(0)
    model = Model(3, 5, channels=(4, 6), max_order=1, rings=RINGS).double()
    model.eval()
    data = [two_level_data(s, max_order=1) for s in (1, 2, 3)]
    batch = Batch.from_data_list(data)
    out = model(batch)
    single = torch.cat([model(d) for d in data])
    assert rel(out, single) < 1e-10
    assert out.shape == ((3, 5) if Model is HSNClassification else (150, 5))


def test_missing_precomputation_is_explained():
    model = HSNClassification(3, 5, rings=RINGS)
    data = two_level_data(1)
    del data.harmonic_1
    with pytest.raises(ValueError, match='HarmonicPrecompute'):
        model.double()(data)
    with pytest.raises(ValueError, match='expects 3 input channels'):
        data = two_level_data(1)
        data.x = data.x[:, :2]
        model(data)


@pytest.mark.parametrize('Model', [HSNClassification, HSNSegmentation])
def test_constructors_need_positive_sizes(Model):
    with pytest.raises(ValueError, match="'in_channels' must be at least 1"):
        Model(0, 5)
    with pytest.raises(ValueError, match="'num_classes' must be at least 1"):
        Model(3, 0)
    with pytest.raises(ValueError, match="'channels' must hold exactly 2"):
        Model(3, 5, channels=(4, ))
    with pytest.raises(ValueError, match=r"'channels\[1\]' must be at least"):
        Model(3, 5, channels=(4, 0))
    with pytest.raises(ValueError, match="'rings' must be at least 1"):
        Model(3, 5, rings=0)


def test_pooling_level_mismatch_is_explained():
    model = HSNClassification(3, 5, rings=RINGS).double()
    data = two_level_data(1)
    data.cluster_1 = data.cluster_1.float()
    with pytest.raises(ValueError, match="'cluster' must hold integer"):
        model(data)
