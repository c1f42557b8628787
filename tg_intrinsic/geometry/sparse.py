"""Conversions between torch sparse tensors and scipy.sparse matrices, and
a sparse product with a precomputed adjoint for autograd."""
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


class SparseMM(torch.autograd.Function):
    """``A @ x`` whose backward uses a precomputed ``A^T`` (torch's own
    backward transposes and re-sorts the sparse matrix on every call)."""
    @staticmethod
    def forward(ctx, matrix: Tensor, transposed: Tensor, x: Tensor):
        ctx.transposed = transposed
        return torch.sparse.mm(matrix, x)

    @staticmethod
    def backward(ctx, grad_out: Tensor):
        return None, None, torch.sparse.mm(ctx.transposed, grad_out)
