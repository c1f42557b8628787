"""DeltaNetSegmentation: batched equals per example (with and without the
MLSOperators transform), per-point logits that follow the points when they
are reordered, the category embedding, shapes and bad input."""
import pytest
import torch
from torch_geometric.data import Batch

from tg_intrinsic.nn.models import DeltaNetSegmentation
from tg_intrinsic.transforms import MLSOperators
from tests.nn.conftest import make_batch


def test_deltanet_batched_equals_per_example():
    torch.manual_seed(0)
    data_list = make_batch(frames=False)
    model = DeltaNetSegmentation(3, 5, k=12).double()
    model(Batch.from_data_list(data_list))  # populate running statistics
    model.eval()
    together = model(Batch.from_data_list(data_list))
    apart = torch.cat([model(Batch.from_data_list([d])) for d in data_list])
    assert torch.allclose(together, apart, atol=1e-10)
    # Precomputed operators (the transform) give the same result.
    pre = [MLSOperators(k=12)(d) for d in data_list]
    assert torch.allclose(model(Batch.from_data_list(pre)), together,
                          atol=1e-10)


def test_shapes_and_parameter_count():
    seg = DeltaNetSegmentation(3, 50, num_categories=16)
    n_seg = sum(p.numel() for p in seg.parameters())
    assert 1.3e6 < n_seg < 1.5e6
    data_list = make_batch(dtype=torch.float32, frames=False)
    for i, d in enumerate(data_list):
        d.category = torch.tensor([i])
    batch = Batch.from_data_list(data_list)
    assert seg(batch).shape == (batch.num_nodes, 50)


@pytest.mark.parametrize('make,match', [
    (lambda: DeltaNetSegmentation(0, 5), "'in_channels' must be at least"),
    (lambda: DeltaNetSegmentation(3, 0), "'num_classes' must be at least"),
    (lambda: DeltaNetSegmentation(3, 5, num_categories=0),
     "'num_categories' must be at least 1"),
    (lambda: DeltaNetSegmentation(3, 5, conv_channels=(8, -1)),
     r"'conv_channels\[1\]' must be at least 1"),
])
def test_layer_constructors_need_positive_sizes(make, match):
    with pytest.raises(ValueError, match=match):
        make()
