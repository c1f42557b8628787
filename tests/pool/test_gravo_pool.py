"""GravoPool: constants, adjointness with the prolongation, batched equals
per-example, gradients, bad input."""
import pytest
import torch
from torch_geometric.data import Batch

from tg_intrinsic.pool import GravoPool, GravoUnpool
from tests.conftest import grid_mesh, icosphere
from tests.pool.conftest import hierarchy, small_prolongation


def test_constants_and_adjointness():
    pos, face = icosphere(4)
    data = hierarchy(pos, face)
    index, weight = data.prolong_index_1, data.prolong_weight_1
    n, m = pos.size(0), data.pos_1.size(0)
    ones = torch.ones(n, 3, dtype=torch.float64)
    assert torch.allclose(GravoPool()(ones, index, weight, m),
                          torch.ones(m, 3, dtype=torch.float64))
    # Unpooling is P; pooling is D^-1 P^T with D the column sums of P.
    g = torch.Generator().manual_seed(0)
    x = torch.randn(n, generator=g, dtype=torch.float64)
    y = torch.randn(m, generator=g, dtype=torch.float64)
    column = torch.zeros(m, dtype=torch.float64).index_add_(0, index[1],
                                                            weight)
    pooled = GravoPool()(x, index, weight, m) * column
    assert torch.allclose((pooled * y).sum(),
                          (x * GravoUnpool()(y, index, weight, n)).sum())


def test_batched_equals_per_example_and_gradients():
    a = hierarchy(*icosphere(3))
    b = hierarchy(*grid_mesh(25, jitter=0.2))
    batch = Batch.from_data_list([a, b])
    g = torch.Generator().manual_seed(1)
    x = torch.randn(batch.num_nodes, 4, generator=g, dtype=torch.float64,
                    requires_grad=True)
    pooled = GravoPool()(x, batch.prolong_index_1, batch.prolong_weight_1,
                         batch.pos_1.size(0))
    n_a, m_a = a.pos.size(0), a.pos_1.size(0)
    alone = GravoPool()(x[:n_a], a.prolong_index_1, a.prolong_weight_1, m_a)
    assert torch.allclose(pooled[:m_a], alone)
    assert torch.autograd.gradcheck(
        lambda t: GravoUnpool()(GravoPool()(t, a.prolong_index_1,
                                            a.prolong_weight_1, m_a),
                                a.prolong_index_1, a.prolong_weight_1, n_a),
        (x[:n_a].detach().clone().requires_grad_(), ))


def test_bad_input():
    data = hierarchy(*icosphere(3))
    x = torch.randn(data.pos.size(0), 2, dtype=torch.float64)
    with pytest.raises(ValueError, match=r'\[2, nnz\]'):
        GravoPool()(x, data.prolong_index_1[0], data.prolong_weight_1, 10)
    with pytest.raises(ValueError, match='one weight'):
        GravoPool()(x, data.prolong_index_1, data.prolong_weight_1[:-1], 10)
    with pytest.raises(ValueError, match='rows'):
        GravoPool()(x[:10], data.prolong_index_1, data.prolong_weight_1,
                    data.pos_1.size(0))
    assert repr(GravoPool()) == 'GravoPool()'


def test_bad_indices_weights_and_sizes():
    data = hierarchy(*icosphere(3))
    index, weight = data.prolong_index_1, data.prolong_weight_1
    n, m = data.pos.size(0), data.pos_1.size(0)
    x = torch.randn(n, 2, dtype=torch.float64)
    negative = index.clone()
    negative[1, 0] = -1
    nan = weight.clone()
    nan[0] = float('nan')
    cases = [
        (lambda: GravoPool()(x, index, weight, m - 1),
         rf"outside \[0, {m - 1}\): there are only {m - 1} coarse points"),
        (lambda: GravoPool()(x, negative, weight, m), 'outside'),
        (lambda: GravoPool()(x, index.double(), weight, m), 'torch.long'),
        (lambda: GravoPool()(x, index, nan, m),
         "'prolong_weight' contains NaN"),
        (lambda: GravoPool()(x, index, weight, -1),
         "'num_coarse' must be at least 0"),
        (lambda: GravoPool()(x.long(), index, weight, m), "'x' must be float"),
    ]
    for call, match in cases:
        with pytest.raises(ValueError, match=match):
            call()


@pytest.mark.parametrize('shape', [(5, ), (5, 3), (5, 2, 2)])
def test_pool_is_the_normalised_transposed_prolongation(shape):
    # x_c = sum_i P_ic x_i / sum_i P_ic, with P written out densely
    index, weight, dense = small_prolongation()
    x = torch.randn(shape, dtype=torch.float64,
                    generator=torch.Generator().manual_seed(0))
    out = GravoPool()(x, index, weight, 3)
    assert out.shape == (3, ) + shape[1:]
    flat = x.reshape(5, -1)
    expected = torch.stack([
        sum(dense[i, c] * flat[i] for i in range(5)) / dense[:, c].sum()
        for c in range(3)])
    torch.testing.assert_close(out.reshape(3, -1), expected)


def test_weights_in_another_dtype_keep_the_features_dtype():
    index, weight, dense = small_prolongation()
    x = torch.randn(5, 2, dtype=torch.float64)
    out = GravoPool()(x, index, weight.float(), 3)
    assert out.dtype == torch.float64
    torch.testing.assert_close(out, GravoPool()(x, index, weight, 3),
                               rtol=1e-6, atol=1e-7)


def test_a_coarse_point_without_weight_is_explained():
    index, weight, _ = small_prolongation()
    x = torch.randn(5, 2, dtype=torch.float64)
    with pytest.raises(ValueError, match='receives no weight'):
        GravoPool()(x, index, weight, 4)  # coarse point 3 has no fine one
