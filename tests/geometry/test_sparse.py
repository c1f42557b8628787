"""Conversions between torch sparse tensors and scipy.sparse against the
dense matrices, and the sparse product's gradient against autograd of the
dense product."""
import numpy as np
import pytest
import scipy.sparse as sp
import torch

from tg_intrinsic.geometry import cotan_laplacian, from_scipy, to_scipy
from tg_intrinsic.geometry.sparse import CSR, sparse_mm


def random_sparse(rows=7, cols=5, density=0.4, seed=0):
    return sp.random(rows, cols, density=density, format='csr',
                     random_state=np.random.default_rng(seed))


@pytest.mark.parametrize('layout', ['coo', 'csr', 'dense'])
def test_to_scipy_keeps_every_entry(layout):
    A = random_sparse()
    dense = torch.from_numpy(A.toarray())
    matrix = {'coo': dense.to_sparse(), 'csr': dense.to_sparse_csr(),
              'dense': dense}[layout]
    out = to_scipy(matrix)
    assert isinstance(out, sp.csr_matrix) and out.shape == (7, 5)
    assert out.dtype == np.float64
    np.testing.assert_array_equal(out.toarray(), A.toarray())


def test_from_scipy_is_coalesced_with_the_requested_dtype():
    A = random_sparse().tocoo()
    # a duplicate entry: scipy sums duplicates, so must the conversion
    dup = sp.coo_matrix((np.r_[A.data, 2.0], (np.r_[A.row, 0],
                                              np.r_[A.col, 0])),
                        shape=A.shape)
    out = from_scipy(dup, dtype=torch.float32)
    assert out.is_coalesced() and out.dtype == torch.float32
    torch.testing.assert_close(out.to_dense(),
                               torch.from_numpy(dup.toarray()).float())


def test_round_trip_of_a_laplacian(sphere_mesh):
    pos, face = sphere_mesh
    S = cotan_laplacian(pos, face)
    back = from_scipy(to_scipy(S))
    assert torch.equal(back.indices(), S.indices())
    assert torch.allclose(back.values(), S.values())
    assert abs(to_scipy(S.to_sparse_csr()) - to_scipy(S)).max() == 0


def test_sparse_product_gradient_matches_the_dense_product():
    A = torch.from_numpy(random_sparse(6, 4).toarray())
    x = torch.randn(4, 3, dtype=torch.float64, requires_grad=True)
    matrix = CSR.of(A.to_sparse_csr())
    transposed = CSR.of(A.t().to_sparse_csr())
    y = sparse_mm(matrix, transposed, x)
    torch.testing.assert_close(y, A @ x)
    w = torch.randn(6, 3, dtype=torch.float64)
    (grad,) = torch.autograd.grad((y * w).sum(), x)
    torch.testing.assert_close(grad, A.t() @ w)
    assert torch.autograd.gradcheck(
        lambda v: sparse_mm(matrix, transposed, v),
        (x.detach().clone().requires_grad_(),))


def test_bad_input():
    with pytest.raises(ValueError, match='2-D torch tensor'):
        to_scipy(np.eye(3))
    with pytest.raises(ValueError, match='2-D torch tensor'):
        to_scipy(torch.ones(3))
    with pytest.raises(ValueError, match='scipy.sparse'):
        from_scipy(np.eye(3))
