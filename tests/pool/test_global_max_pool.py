import pytest
import torch
from torch_geometric.nn import global_max_pool as pyg_global_max_pool

from tg_intrinsic.pool import dense_max_pool, global_max_pool


def _features(sizes, channels=5, seed=0):
    generator = torch.Generator().manual_seed(seed)
    x = torch.randn(sum(sizes), channels, generator=generator,
                    dtype=torch.float64, requires_grad=True)
    batch = torch.repeat_interleave(torch.arange(len(sizes)),
                                    torch.tensor(sizes))
    return x, batch


@pytest.mark.parametrize('sizes', [[7], [4, 4, 4], [3, 9, 1, 6]])
def test_values_and_gradients_match_pyg(sizes):
    # Random features have no ties, so the arg-max gradient is PyG's.
    x, batch = _features(sizes)
    weight = torch.randn(len(sizes), 5, dtype=torch.float64)
    ours = global_max_pool(x, batch)
    (grad_ours, ) = torch.autograd.grad((ours * weight).sum(), x)
    theirs = pyg_global_max_pool(x, batch)
    (grad_theirs, ) = torch.autograd.grad((theirs * weight).sum(), x)
    torch.testing.assert_close(ours, theirs)
    torch.testing.assert_close(grad_ours, grad_theirs)


def test_empty_example_gives_zero_like_pyg():
    x, batch = _features([3, 2])
    batch = torch.where(batch == 1, 2, batch)   # example 1 has no points
    out = global_max_pool(x, batch, size=4)
    torch.testing.assert_close(out, pyg_global_max_pool(x, batch, 4))
    assert out[1].abs().sum() == 0 and out[3].abs().sum() == 0


def test_unsorted_batch_and_no_batch():
    x, batch = _features([4, 5, 3])
    order = torch.randperm(x.size(0), generator=torch.Generator()
                           .manual_seed(1))
    torch.testing.assert_close(global_max_pool(x[order], batch[order]),
                               pyg_global_max_pool(x, batch))
    torch.testing.assert_close(global_max_pool(x, None),
                               x.max(dim=0, keepdim=True).values)


def test_ties_share_the_gradient_like_pyg():
    x = torch.tensor([[1.0, 2.0], [1.0, 0.0], [0.5, 2.0], [3.0, 3.0]],
                     requires_grad=True)
    batch = torch.tensor([0, 0, 0, 1])
    (ours, ) = torch.autograd.grad(global_max_pool(x, batch).sum(), x)
    (theirs, ) = torch.autograd.grad(pyg_global_max_pool(x, batch).sum(), x)
    torch.testing.assert_close(ours, theirs)
    assert ours[0, 0] == 0.5 and ours[1, 0] == 0.5


def _reference_max_gradient(dense, grad):
    # Independent: the mask formula, ties sharing evenly.
    hit = (dense == dense.amax(dim=1, keepdim=True)).to(dense.dtype)
    return hit * (grad / hit.sum(dim=1)).unsqueeze(1)


@pytest.mark.parametrize('dtype', [torch.float32, torch.float64])
def test_dense_max_pool_on_a_permuted_layout_with_ties(dtype):
    # The layout DeltaNet uses: channels first [C, B * n], seen as (B, n, C).
    generator = torch.Generator().manual_seed(0)
    h = torch.randint(0, 4, (6, 3 * 5), generator=generator).to(dtype)
    h.requires_grad_(True)
    dense = h.view(6, 3, 5).permute(1, 2, 0)
    out = dense_max_pool(dense)
    torch.testing.assert_close(out, dense.amax(dim=1))
    grad = torch.randn(out.shape, generator=generator, dtype=dtype)
    (ours, ) = torch.autograd.grad(out, h, grad)
    expected = _reference_max_gradient(dense.detach(), grad)
    torch.testing.assert_close(ours.view(6, 3, 5).permute(1, 2, 0), expected)


def test_dense_max_pool_propagates_nan_like_torch():
    dense = torch.tensor([[[1.0, 2.0], [float('nan'), 0.0], [3.0, 1.0]]])
    out = dense_max_pool(dense)
    assert torch.isnan(out[0, 0]) and out[0, 1] == 2.0
    assert torch.isnan(dense.amax(dim=1)[0, 0])


def test_dense_max_pool_gradcheck():
    dense = torch.randn(2, 4, 3, dtype=torch.float64, requires_grad=True)
    assert torch.autograd.gradcheck(dense_max_pool, (dense, ))
