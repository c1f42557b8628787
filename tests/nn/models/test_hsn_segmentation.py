import math

import pytest
import torch
from torch_geometric.data import Batch

from tg_intrinsic.nn.models import HSNSegmentation
from tests.conftest import rel
from tests.nn.conftest import RINGS, permute_points, two_level_data


@pytest.mark.parametrize('max_order', [1, 2])
def test_predictions_are_gauge_invariant(max_order):
    gen = torch.Generator().manual_seed(9)
    angle0 = torch.rand(50, dtype=torch.float64, generator=gen) * 2 * math.pi
    angle1 = torch.rand(12, dtype=torch.float64, generator=gen) * 2 * math.pi
    torch.manual_seed(0)
    model = HSNSegmentation(3, 5, channels=(4, 6), max_order=max_order,
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


def test_batched_equals_per_example():
    torch.manual_seed(0)
    model = HSNSegmentation(3, 5, channels=(4, 6), max_order=1,
                            rings=RINGS).double()
    model.eval()
    data = [two_level_data(s, max_order=1) for s in (1, 2, 3)]
    batch = Batch.from_data_list(data)
    out = model(batch)
    single = torch.cat([model(d) for d in data])
    assert rel(out, single) < 1e-10
    assert out.shape == (150, 5)


def test_constructors_need_positive_sizes():
    with pytest.raises(ValueError, match="'in_channels' must be at least 1"):
        HSNSegmentation(0, 5)
    with pytest.raises(ValueError, match="'num_classes' must be at least 1"):
        HSNSegmentation(3, 0)
    with pytest.raises(ValueError, match="'channels' must hold exactly 2"):
        HSNSegmentation(3, 5, channels=(4, ))
    with pytest.raises(ValueError, match=r"'channels\[1\]' must be at least"):
        HSNSegmentation(3, 5, channels=(4, 0))
    with pytest.raises(ValueError, match="'rings' must be at least 1"):
        HSNSegmentation(3, 5, rings=0)


def test_logits_follow_the_points_when_they_are_reordered():
    # the logits of a point do not depend on where it is listed
    torch.manual_seed(0)
    model = HSNSegmentation(3, 5, channels=(4, 6), max_order=1,
                            rings=RINGS).double().eval()
    with torch.no_grad():
        for p in model.parameters():  # no trivial zero outputs
            p.add_(0.05 * torch.randn_like(p))
    data = two_level_data(1, max_order=1)
    order = torch.randperm(50, generator=torch.Generator().manual_seed(3))
    out = model(data)
    out2 = model(permute_points(data, order))
    expected = out[order]
    assert out.shape == (50, 5)
    assert rel(out2, expected) < 1e-10
    # the points get different logits: the comparison can fail
    assert rel(out2, out) > 1e-3


def test_repr():
    model = HSNSegmentation(3, 5, channels=(4, 6), max_order=2, rings=RINGS)
    assert repr(model) == ('HSNSegmentation(3, 5, channels=(4, 6), '
                           'max_order=2, rings=4)')


@pytest.mark.parametrize('key,match', [
    ('cluster_1', "the data lacks 'cluster_1'; build the pooling levels "
                  "with MultiscaleSupports"),
    ('pool_transport_1', "the data lacks 'pool_transport_1'"),
    ('transport', r"the data lacks \['transport'\]; build it with LogMap"),
    ('edge_index_1', r"the data lacks \['edge_index_1'\]"),
])
def test_missing_levels_are_explained(key, match):
    model = HSNSegmentation(3, 5, channels=(4, 6), max_order=1,
                            rings=RINGS).double()
    data = two_level_data(1, max_order=1)
    del data[key]
    with pytest.raises(ValueError, match=match):
        model(data)
