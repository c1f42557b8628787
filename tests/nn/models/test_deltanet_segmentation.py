"""DeltaNetSegmentation: batched equals per example (with and without the
MLSOperators transform), per-point logits that follow the points when they
are reordered, the category embedding, shapes and bad input."""
import pytest
import torch
from torch_geometric.data import Batch, Data

from tg_intrinsic.nn.models import DeltaNetSegmentation
from tg_intrinsic.transforms import MLSOperators
from tests.nn.conftest import make_batch
from tests.nn.models.machinery_checks import check_autocast, check_compiles


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


def tiny_model(**kwargs):
    torch.manual_seed(0)
    return DeltaNetSegmentation(3, 5, conv_channels=(8, 8), k=6,
                                embedding_size=16, **kwargs).double()


def test_logits_follow_the_points_when_they_are_reordered():
    model = tiny_model()
    data_list = make_batch((40, 50), frames=False)
    model(Batch.from_data_list(data_list))  # running statistics
    model.eval()
    out = model(Batch.from_data_list(data_list))
    generator = torch.Generator().manual_seed(1)
    orders = [torch.randperm(d.num_nodes, generator=generator)
              for d in data_list]
    shuffled = [Data(pos=d.pos[o], normal=d.normal[o])
                for d, o in zip(data_list, orders)]
    out2 = model(Batch.from_data_list(shuffled))
    expected = torch.cat([part[o] for part, o in
                          zip(out.split([40, 50]), orders)])
    assert out.shape == (90, 5)
    torch.testing.assert_close(out2, expected, rtol=1e-9, atol=1e-12)
    # The points get different logits: the comparison can fail.
    assert not torch.allclose(out2, out, rtol=1e-3, atol=1e-6)


def test_category_indices_are_one_hot_vectors():
    model = tiny_model(num_categories=4).eval()
    data_list = make_batch((30, 30), frames=False)
    for data, category in zip(data_list, (2, 0)):
        data.category = torch.tensor([category])
    by_index = model(Batch.from_data_list(data_list))
    for data in data_list:
        data.category = torch.nn.functional.one_hot(data.category, 4)
    by_vector = model(Batch.from_data_list(data_list))
    torch.testing.assert_close(by_index, by_vector, rtol=0, atol=0)
    # The category enters the logits.
    data_list[0].category = torch.tensor([[0, 1, 0, 0]])
    changed = model(Batch.from_data_list(data_list))
    assert not torch.allclose(changed[:30], by_vector[:30])
    torch.testing.assert_close(changed[30:], by_vector[30:])


def test_missing_category_is_explained():
    model = tiny_model(num_categories=4)
    batch = Batch.from_data_list(make_batch((30, ), frames=False))
    with pytest.raises(ValueError, match=r"num_categories=4; it needs "
                                         r"'data.category'"):
        model(batch)
    with pytest.raises(ValueError, match='expects 4 input channels but '
                                         r'data.x \(or data.pos\) has 3'):
        DeltaNetSegmentation(4, 5, conv_channels=(8, ), k=6)(batch)


def test_vector_stream_ablation_runs():
    model = tiny_model(vector_stream=False)
    batch = Batch.from_data_list(make_batch((30, 40), frames=False))
    assert model(batch).shape == (70, 5)


def test_repr_shows_the_architecture():
    assert repr(tiny_model(num_categories=4, vector_stream=False)) == (
        'DeltaNetSegmentation(3, 5, conv_channels=(8, 8), num_categories=4, '
        'vector_stream=False)')


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


@pytest.mark.parametrize('category,match', [
    (torch.tensor([4]), r"'data.category' holds indices in \[4, 4\], "
                        r"outside \[0, 4\): there are only 4 categories"),
    (torch.tensor([-1]), r"'data.category' holds indices in \[-1, -1\]"),
    (torch.tensor([1.0]), "'data.category' must hold integer indices"),
    (torch.tensor([[1.0, 0.0, 0.0]]), r"'data.category' must hold a category "
                                      r"index per example \[B\] = \[2\] or "
                                      r"one-hot vectors \[B, num_categories\]"
                                      r" = \[2, 4\], got \[2, 3\]"),
])
def test_bad_categories_are_explained(category, match):
    # one_hot and the category embedding used to fail with RuntimeErrors
    model = tiny_model(num_categories=4)
    data_list = make_batch((30, 30), frames=False)
    for data in data_list:
        data.category = category
    with pytest.raises(ValueError, match=match):
        model(Batch.from_data_list(data_list))


def test_torch_compile_with_precomputed_operators():
    # MLSOperators' weights read from the batch (the training path), with
    # categories; aot_eager traces what inductor would compile
    torch.manual_seed(0)
    batches = []
    for sizes in ((120, 150), (100, 130, 90)):
        items = [MLSOperators(k=10)(data) for data in
                 make_batch(sizes, dtype=torch.float32)]
        for index, item in enumerate(items):
            item.category = torch.tensor([index % 2])
        batches.append(Batch.from_data_list(items))
    # two narrow layers: the same operations as the default three
    model = DeltaNetSegmentation(3, 5, conv_channels=(16, 32), k=10,
                                 embedding_size=64, num_categories=2)
    check_compiles(model, batches, backend='aot_eager')


def test_bfloat16_autocast():
    torch.manual_seed(0)
    batch = Batch.from_data_list(make_batch(dtype=torch.float32))
    check_autocast(DeltaNetSegmentation(3, 5, k=12), batch)
