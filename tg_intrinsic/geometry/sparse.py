"""Conversions between torch sparse tensors and scipy.sparse matrices, and
a sparse product with a precomputed adjoint for autograd."""
from typing import NamedTuple

import numpy as np
import scipy.sparse as sp
import torch
from torch import Tensor


def to_scipy(matrix: Tensor) -> sp.csr_matrix:
    r"""Converts a 2-D torch sparse tensor (COO or CSR) or a dense tensor to a
    ``scipy.sparse.csr_matrix`` with the same dtype, on the CPU.

    Example:
        >>> S = cotan_laplacian(pos, face)
        >>> scipy.sparse.linalg.spsolve(to_scipy(S) + eps * I, b)
    """
    if not isinstance(matrix, Tensor) or matrix.dim() != 2:
        raise ValueError("'matrix' must be a 2-D torch tensor")
    matrix = matrix.detach().cpu()
    if matrix.layout == torch.sparse_csr:
        return sp.csr_matrix((matrix.values().numpy(),
                              matrix.col_indices().numpy(),
                              matrix.crow_indices().numpy()),
                             shape=tuple(matrix.shape))
    if matrix.layout == torch.sparse_coo:
        matrix = matrix.coalesce()
        row, col = matrix.indices().numpy()
        return sp.coo_matrix((matrix.values().numpy(), (row, col)),
                             shape=tuple(matrix.shape)).tocsr()
    if matrix.layout == torch.strided:
        return sp.csr_matrix(matrix.numpy())
    raise ValueError(f"unsupported layout {matrix.layout}")


def from_scipy(matrix, dtype: torch.dtype = None,
               device: torch.device = None) -> Tensor:
    """Converts a ``scipy.sparse`` matrix to a coalesced torch sparse COO
    tensor."""
    if not sp.issparse(matrix):
        raise ValueError("'matrix' must be a scipy.sparse matrix")
    coo = matrix.tocoo()
    index = torch.from_numpy(np.vstack([coo.row, coo.col]).astype(np.int64))
    value = torch.from_numpy(np.asarray(coo.data))
    if dtype is not None:
        value = value.to(dtype)
    out = torch.sparse_coo_tensor(index, value, coo.shape,
                                  check_invariants=False).coalesce()
    return out.to(device) if device is not None else out


@torch.library.custom_op('tg_intrinsic::csr_mm', mutates_args=())
def _csr_mm(crow: Tensor, col: Tensor, values: Tensor, crow_t: Tensor,
            col_t: Tensor, values_t: Tensor, x: Tensor) -> Tensor:
    # A custom operator, so that torch.compile calls the sparse kernel as
    # it is (it cannot trace sparse tensors) and fuses what lies around it.
    matrix = torch.sparse_csr_tensor(crow, col, values,
                                     (crow.numel() - 1, x.size(0)),
                                     check_invariants=False)
    return torch.sparse.mm(matrix, x)


@_csr_mm.register_fake
def _(crow, col, values, crow_t, col_t, values_t, x):
    return x.new_empty(crow.size(0) - 1, x.size(1))


def _csr_mm_context(ctx, inputs, output):
    ctx.transposed = inputs[3:6]
    ctx.forward = inputs[:3]


def _csr_mm_backward(ctx, grad):
    # d(A x)/dx^H g = A^H g: the transposed (adjoint, for complex values)
    # matrix given, whose own adjoint is A
    grad_x = _csr_mm(*ctx.transposed, *ctx.forward, grad.contiguous())
    return None, None, None, None, None, None, grad_x


_csr_mm.register_autograd(_csr_mm_backward, setup_context=_csr_mm_context)


class CSR(NamedTuple):
    """A CSR matrix kept as its three dense arrays: ``torch.compile`` can
    hold those (not a sparse tensor), and :func:`sparse_mm` reads them."""
    crow: Tensor
    col: Tensor
    values: Tensor

    @classmethod
    def of(cls, matrix: Tensor) -> 'CSR':
        """The arrays of a torch sparse CSR tensor (copies: views into a
        sparse tensor's storage confuse torch.compile's guards)."""
        return cls(matrix.crow_indices().clone(),
                   matrix.col_indices().clone(), matrix.values().clone())

    def cast(self, dtype: torch.dtype) -> 'CSR':
        return self._replace(values=self.values.to(dtype))

    def on(self, device) -> 'CSR':
        return CSR(*(array.to(device) for array in self))


def sparse_mm(matrix: CSR, transposed: CSR, x: Tensor) -> Tensor:
    """``matrix @ x`` for a :class:`CSR` ``matrix`` of ``x.size(0)``
    columns, whose backward uses the precomputed ``transposed``
    (:math:`A^T`, or :math:`A^H` for complex values; torch's own backward
    transposes and re-sorts a sparse matrix on every call). The matrix is
    constant: no gradient flows to it. A custom operator:
    ``torch.compile`` calls the sparse kernel as it is."""
    return _csr_mm(*matrix, *transposed, x.contiguous())
