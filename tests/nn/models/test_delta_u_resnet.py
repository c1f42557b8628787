"""DeltaUResNet: output shape and levels, rotation invariance, batched
equals per example, the Gravo pooling option, bad input, and learning."""
import pytest
import torch
from torch_geometric.data import Batch

from tg_intrinsic.data import IntrinsicData
from tg_intrinsic.nn.models import DeltaUResNet
from tg_intrinsic.pool import GravoPool
from tg_intrinsic.transforms import PoolingLevels
from tests.conftest import fibonacci_sphere
from tests.nn.conftest import assert_eval_matches_batch_statistics
from tests.symmetry import random_rotation


def _blob(n=512, seed=0, dtype=torch.float64):
    """A bumpy closed surface with normals, inputs invariant to rotations
    (distance to the centre, and its product with the normal)."""
    g = torch.Generator().manual_seed(seed)
    unit = fibonacci_sphere(n, dtype)
    unit = unit[torch.randperm(n, generator=g)]
    radius = 1 + 0.2 * torch.sin(3 * unit[:, 0]) * torch.cos(2 * unit[:, 1])
    pos = unit * radius[:, None]
    return IntrinsicData(pos=pos, normal=unit)


def _features(data):
    data.x = torch.stack([data.pos.norm(dim=1),
                          (data.pos * data.normal).sum(1)], 1)
    return data


def _prepared(n=512, seed=0, method='fps', rotation=None,
              dtype=torch.float64):
    data = _blob(n, seed, dtype)
    if rotation is not None:
        data.pos, data.normal = data.pos @ rotation.T, \
            data.normal @ rotation.T
    return _features(PoolingLevels(method=method)(data))


def _model(method='fps', **kwargs):
    torch.manual_seed(0)
    return DeltaUResNet(2, 5, channels=16, final_channels=32,
                        pooling=method, **kwargs).double().eval()


def test_output_shape_levels_and_repr():
    data = _prepared()
    assert [data[f'pos_{l}'].size(0) for l in (1, 2, 3)] == [128, 32, 8]
    model = _model(num_categories=3)
    data.category = torch.tensor([2])
    out = model(data)
    assert out.shape == (512, 5) and torch.isfinite(out).all()
    assert repr(model) == ("DeltaUResNet(2, 5, channels=16, "
                           "final_channels=32, pooling='fps', "
                           "num_categories=3)")
    # four scales of doubling width, vector streams in the first three
    full = DeltaUResNet(3, 50)
    widths = [blocks[1].up[0].out_features for blocks in full.encoder]
    assert widths == [64, 128, 256, 512]
    assert [blocks[0].vector for blocks in full.encoder] == \
        [True, True, True, False]
    assert all(block.up[0].out_features == 128 for block in full.final)


@pytest.mark.parametrize('method', ['fps', 'gravo'])
def test_logits_are_invariant_to_rotations(method):
    model = _model(method)
    out = model(_prepared(method=method))
    turned = model(_prepared(method=method, rotation=random_rotation()))
    assert torch.allclose(out, turned, atol=1e-8)


@pytest.mark.parametrize('method', ['fps', 'gravo'])
def test_batched_equals_per_example(method):
    model = _model(method, num_categories=2)
    a, b = _prepared(512, 0, method), _prepared(600, 1, method)
    a.category, b.category = torch.tensor([0]), torch.tensor([1])
    batched = model(Batch.from_data_list([a, b]))
    assert torch.allclose(batched[:512], model(a), atol=1e-10)
    assert torch.allclose(batched[512:], model(b), atol=1e-10)


def test_gravo_pooling_of_a_constant_is_constant():
    data = _prepared(method='gravo')
    sizes = [data.pos.size(0)] + [data[f'pos_{l}'].size(0) for l in (1, 2, 3)]
    for level in (1, 2, 3):
        ones = torch.ones(sizes[level - 1], 4, dtype=torch.float64)
        pooled = GravoPool()(ones, data[f'pool_edge_index_{level}'],
                             data[f'pool_weight_{level}'], sizes[level])
        assert torch.allclose(pooled, torch.ones_like(pooled))


def test_bad_input_is_explained():
    model = _model()
    with pytest.raises(ValueError, match='too small for 3 pooling levels'):
        PoolingLevels()(_blob(300))
    plain = _features(_blob())
    with pytest.raises(ValueError, match='apply tg_intrinsic.transforms.'
                       'PoolingLevels'):
        model(plain)
    data = _prepared()
    with pytest.raises(ValueError, match='expects 2 input channels'):
        model(IntrinsicData(**{**data.to_dict(), 'x': data.pos}))
    with pytest.raises(ValueError, match="pools with 'gravo'"):
        _model('gravo')(data)
    with pytest.raises(ValueError, match="needs 'data.category'"):
        _model(num_categories=2)(data)
    with pytest.raises(ValueError, match="'pooling' must be one of"):
        DeltaUResNet(3, 4, pooling='mean')
    with pytest.raises(ValueError, match="'channels' must be at least 1"):
        DeltaUResNet(3, 4, channels=0)


def test_it_learns_a_tiny_segmentation():
    torch.manual_seed(0)
    data = _prepared(512, 0, dtype=torch.float32)
    data.y = (data.pos[:, 2] > 0.2).long() + (data.pos[:, 0] > 0.3).long()
    data.x = data.pos.clone()
    model = DeltaUResNet(3, 3, channels=16, final_channels=32,
                         dropout=0.0)
    optimizer = torch.optim.Adam(model.parameters(), lr=1e-2)
    losses = []
    for _ in range(12):
        optimizer.zero_grad()
        loss = torch.nn.functional.cross_entropy(model(data), data.y)
        loss.backward()
        optimizer.step()
        losses.append(float(loss.detach()))
    assert losses[-1] < 0.5 * losses[0]
    with torch.no_grad():  # batch statistics, as in training
        accuracy = (model(data).argmax(1) == data.y).float().mean()
    assert accuracy > 0.85



def test_eval_after_recalibrating_on_a_batch_gives_its_batch_output():
    # every batch norm of the U-ResNet: point MLPs on four levels, the
    # neighbour maxima's closed-form statistics, the decoder and head
    assert_eval_matches_batch_statistics(
        _model(), Batch.from_data_list([_prepared(seed=s) for s in (0, 1)]))
