import pytest
import torch
from torch_geometric.data import Batch, Data
from torch_geometric.nn import global_max_pool, global_mean_pool

from tg_intrinsic.nn.models import DeltaNetClassification


def _clouds(sizes, seed=0):
    generator = torch.Generator().manual_seed(seed)
    items = []
    for n in sizes:
        pos = torch.randn(n, 3, generator=generator, dtype=torch.float64)
        items.append(Data(pos=pos, normal=pos / pos.norm(dim=1,
                                                         keepdim=True)))
    return Batch.from_data_list(items)


def _reference(model, data):
    # The plain PyG path: embedding MLP on [N, C], PyG's pooling.
    x = model.embedding(torch.cat(model.base(data), dim=1))
    pooled = torch.cat([global_max_pool(x, data.batch),
                        global_mean_pool(x, data.batch)], dim=1)
    return model.head(pooled)


@pytest.mark.parametrize('training', [True, False])
def test_channels_first_embedding_matches_the_mlp(training):
    # Equal-size batches take the channels-first path; it must give the
    # MLP's outputs and gradients in training (batch statistics) and
    # evaluation (running statistics) mode.
    torch.manual_seed(0)
    model = DeltaNetClassification(3, 4, conv_channels=(8, 8), k=6,
                                   embedding_size=32).double()
    model.head.eval()   # no dropout, so both paths are comparable
    model.embedding.train(training)
    data = _clouds([40, 40, 40])
    model.embedding.norms[0].module.momentum = 0.0   # stats stay as they are
    ours = model(data)
    (grad_ours, ) = torch.autograd.grad(ours.square().sum(),
                                        model.embedding.lins[0].weight)
    theirs = _reference(model, data)
    (grad_theirs, ) = torch.autograd.grad(theirs.square().sum(),
                                          model.embedding.lins[0].weight)
    torch.testing.assert_close(ours, theirs)
    torch.testing.assert_close(grad_ours, grad_theirs)


def test_unequal_batches_take_the_plain_path():
    torch.manual_seed(1)
    model = DeltaNetClassification(3, 4, conv_channels=(8, 8), k=6,
                                   embedding_size=16).double().eval()
    data = _clouds([30, 45])
    torch.testing.assert_close(model(data), _reference(model, data))
