"""GravoUnpool: the prolongation against its dense matrix (values and
gradients), constants, batched equals per-example, bad input."""
import pytest
import torch
from torch_geometric.data import Batch

from tg_intrinsic.pool import GravoPool, GravoUnpool
from tests.conftest import grid_mesh, icosphere
from tests.pool.conftest import hierarchy, small_prolongation


def test_constants():
    pos, face = icosphere(4)
    data = hierarchy(pos, face)
    index, weight = data.prolong_index_1, data.prolong_weight_1
    n, m = pos.size(0), data.pos_1.size(0)
    assert torch.allclose(GravoUnpool()(torch.ones(m, dtype=torch.float64),
                                        index, weight, n),
                          torch.ones(n, dtype=torch.float64))


def test_batched_equals_per_example():
    a = hierarchy(*icosphere(3))
    b = hierarchy(*grid_mesh(25, jitter=0.2))
    batch = Batch.from_data_list([a, b])
    g = torch.Generator().manual_seed(1)
    x = torch.randn(batch.num_nodes, 4, generator=g, dtype=torch.float64)
    pooled = GravoPool()(x, batch.prolong_index_1, batch.prolong_weight_1,
                         batch.pos_1.size(0))
    n_a, m_a = a.pos.size(0), a.pos_1.size(0)
    alone = GravoPool()(x[:n_a], a.prolong_index_1, a.prolong_weight_1, m_a)
    back = GravoUnpool()(pooled, batch.prolong_index_1,
                         batch.prolong_weight_1, batch.num_nodes)
    assert torch.allclose(back[:n_a], GravoUnpool()(
        alone, a.prolong_index_1, a.prolong_weight_1, n_a))


def test_bad_input():
    data = hierarchy(*icosphere(3))
    x = torch.randn(data.pos.size(0), 2, dtype=torch.float64)
    with pytest.raises(ValueError, match='rows'):
        GravoUnpool()(x[:3], data.prolong_index_1, data.prolong_weight_1,
                      data.pos.size(0))


def test_bad_indices_weights_and_sizes():
    data = hierarchy(*icosphere(3))
    index, weight = data.prolong_index_1, data.prolong_weight_1
    n, m = data.pos.size(0), data.pos_1.size(0)
    y = torch.randn(m, 2, dtype=torch.float64)
    negative = index.clone()
    negative[1, 0] = -1
    nan = weight.clone()
    nan[0] = float('nan')
    cases = [
        (lambda: GravoUnpool()(y, index, weight, n - 1),
         rf"outside \[0, {n - 1}\): there are only {n - 1} fine points"),
        (lambda: GravoUnpool()(y, negative, weight, n), 'outside'),
        (lambda: GravoUnpool()(y, index.float(), weight, n), 'torch.long'),
        (lambda: GravoUnpool()(y, index, nan, n),
         "'prolong_weight' contains NaN"),
        (lambda: GravoUnpool()(y, index, weight, 2.5),
         "'num_fine' must be an integer"),
    ]
    for call, match in cases:
        with pytest.raises(ValueError, match=match):
            call()


@pytest.mark.parametrize('shape', [(3, ), (3, 4), (3, 2, 2)])
def test_unpool_is_the_prolongation(shape):
    # x_i = sum_c P_ic x_c, with P written out densely
    index, weight, dense = small_prolongation()
    y = torch.randn(shape, dtype=torch.float64, requires_grad=True,
                    generator=torch.Generator().manual_seed(0))
    out = GravoUnpool()(y, index, weight, 5)
    assert out.shape == (5, ) + shape[1:]
    flat = y.detach().reshape(3, -1)
    expected = torch.stack([sum(dense[i, c] * flat[c] for c in range(3))
                            for i in range(5)])
    torch.testing.assert_close(out.detach().reshape(5, -1), expected)
    # the backward pass is the transpose
    g = torch.randn(out.shape, dtype=torch.float64)
    (grad, ) = torch.autograd.grad(out, y, g)
    torch.testing.assert_close(grad.reshape(3, -1),
                               dense.t() @ g.reshape(5, -1))


def test_fine_points_without_a_coarse_one_get_zero():
    index, weight, _ = small_prolongation()
    out = GravoUnpool()(torch.ones(3, dtype=torch.float64), index, weight, 7)
    assert out.shape == (7, ) and (out[5:] == 0).all() and (out[:5] > 0).all()


def test_repr():
    assert repr(GravoUnpool()) == 'GravoUnpool()'
