"""Checks every HSN model must pass, shared by the classification and
segmentation tests: gauge invariance of the predictions (evaluation and
training mode, with gradients), batches equal to their examples, and the
constructors' refusals."""
import math

import pytest
import torch
from torch_geometric.data import Batch

from tests.conftest import rel
from tests.nn.conftest import RINGS, two_level_data


def check_gauge_invariance(model_class, max_order):
    gen = torch.Generator().manual_seed(9)
    angle0 = torch.rand(50, dtype=torch.float64, generator=gen) * 2 * math.pi
    angle1 = torch.rand(12, dtype=torch.float64, generator=gen) * 2 * math.pi
    torch.manual_seed(0)
    model = model_class(3, 5, channels=(4, 6), max_order=max_order,
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


def check_batched_equals_per_example(model_class, shape):
    torch.manual_seed(0)
    model = model_class(3, 5, channels=(4, 6), max_order=1,
                        rings=RINGS).double()
    model.eval()
    data = [two_level_data(s, max_order=1) for s in (1, 2, 3)]
    out = model(Batch.from_data_list(data))
    single = torch.cat([model(d) for d in data])
    assert rel(out, single) < 1e-10
    assert out.shape == shape


def check_constructors_need_positive_sizes(model_class):
    with pytest.raises(ValueError, match="'in_channels' must be at least 1"):
        model_class(0, 5)
    with pytest.raises(ValueError, match="'num_classes' must be at least 1"):
        model_class(3, 0)
    with pytest.raises(ValueError, match="'channels' must hold exactly 2"):
        model_class(3, 5, channels=(4, ))
    with pytest.raises(ValueError, match=r"'channels\[1\]' must be at least"):
        model_class(3, 5, channels=(4, 0))
    with pytest.raises(ValueError, match="'rings' must be at least 1"):
        model_class(3, 5, rings=0)


#: A key the models need, removed, and what the error must say.
MISSING_LEVELS = [
    ('cluster_1', "the data lacks 'cluster_1'; build the pooling levels "
                  "with MultiscaleSupports"),
    ('pool_transport_1', "the data lacks 'pool_transport_1'"),
    ('transport', r"the data lacks \['transport'\]; build it with LogMap"),
    ('edge_index_1', r"the data lacks \['edge_index_1'\]"),
]


def check_missing_level_is_explained(model_class, key, match):
    model = model_class(3, 5, channels=(4, 6), max_order=1,
                        rings=RINGS).double()
    data = two_level_data(1, max_order=1)
    del data[key]
    with pytest.raises(ValueError, match=match):
        model(data)


def check_training_equals_evaluation(make_model, data_list):
    """With the per-shape normalisation, a model computes the same function
    in training and evaluation mode, and a shape's outputs do not depend
    on the other shapes of its batch; with batch norm they do (so the
    check can fail). ``make_model(norm)`` builds the model."""
    batch = Batch.from_data_list(data_list)
    torch.manual_seed(0)
    model = make_model('instance').double()
    for module in model.modules():   # no dropout: compare the normalisation
        if isinstance(module, torch.nn.Dropout):
            module.p = 0.0
    if hasattr(model, 'dropout'):
        model.dropout = 0.0
    with torch.no_grad():
        for p in model.parameters():
            p.add_(0.05 * torch.randn_like(p))
    trained = model.train()(batch)
    alone = torch.cat([model(d) for d in data_list])
    evaluated = model.eval()(batch)
    assert rel(evaluated, trained) < 1e-12
    assert rel(alone, trained) < 1e-10
    torch.manual_seed(0)
    batch_norm = make_model('batch').double().train()
    assert rel(torch.cat([batch_norm(d) for d in data_list]),
               batch_norm(batch)) > 1e-3


def check_norm_is_validated(make_model):
    with pytest.raises(ValueError, match=r"'norm' must be one of "
                       r"\('instance', 'batch', None\), got 'layer'"):
        make_model('layer')


def single_precision(data):
    return data.apply(lambda t: t.float() if t.is_floating_point() else
                      t.to(torch.complex64) if t.is_complex() else t)


def check_compile_and_precision(model_class, backend='eager'):
    """torch.compile (one graph for batches of every size, as eager),
    bfloat16 autocast close to float32, and half weights refused in words
    (complex maths has no half kernels).

    The backend is dynamo's own (``'eager'``): its trace runs every op on
    fake tensors, so graph breaks, recompiles and outputs are checked.
    AOTAutograd and inductor (15 s more per model: aot_eager took 18.3 s,
    the trace 3.4 s) run on HSNClassification, which has the shared
    layers (HarmonicConv, the complex norms and non-linearities, pooling);
    the other models add unpooling, an index and a complex product."""
    from tests.nn.models.machinery_checks import (check_autocast,
                                                  check_compiles)
    torch.manual_seed(0)
    batches = [Batch.from_data_list([two_level_data(s, n=n, n1=n1)
                                     for s in range(count)])
               for count, n, n1 in ((3, 50, 12), (2, 60, 15), (4, 40, 10))]
    model = model_class(3, 5, channels=(4, 6), rings=RINGS).double()
    check_compiles(model, batches, backend=backend, rtol=1e-9)
    model = model_class(3, 5, channels=(4, 6), rings=RINGS)
    check_autocast(model, single_precision(batches[0]))
    half = single_precision(batches[0]).apply(
        lambda t: t.half() if t.is_floating_point() else t)
    with pytest.raises(ValueError, match='torch.autocast'):
        model.half()(half)
