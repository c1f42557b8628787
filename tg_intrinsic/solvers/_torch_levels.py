"""GravoMG's torch backend: the Galerkin levels of one matrix as torch
sparse CSR tensors on one device and dtype, cycles with Chebyshev
smoothing on blocks of right-hand sides, and the coarsest level solved by
the shared sparse LU on the CPU (up to ratio x lower_bound unknowns: a
dense Cholesky of 6400 took 200 ms per solve, the LU 1 ms). Runs wherever
torch's sparse-dense products do (CPU and CUDA, float32 and float64)."""
from typing import List

import numpy as np
import scipy.sparse as sp
import torch
from torch import Tensor

# Chebyshev smoothing damps the upper part [top / LOWER_FRACTION, top] of
# the spectrum of D^-1 A, where top is the power-iteration estimate of its
# largest eigenvalue times SAFETY. Measured on icospheres (M + 1e-3 S,
# degree 2): 4 cycles with a fraction of 5 at 40k, 15 with pyamg's 30.
LOWER_FRACTION = 5.0
SAFETY = 1.1
POWER_STEPS = 15


def _to_torch(A: sp.csr_matrix, device, dtype) -> Tensor:
    A = A.tocsr()
    return torch.sparse_csr_tensor(
        torch.from_numpy(A.indptr.astype(np.int64)),
        torch.from_numpy(A.indices.astype(np.int64)),
        torch.from_numpy(A.data), A.shape,
        check_invariants=False).to(device=device, dtype=dtype)


class TorchLevels:
    """Torch copies of scipy Galerkin levels ``A`` (fine to coarse) with
    prolongations ``P`` and restrictions ``R`` = P^T."""

    def __init__(self, A: List[sp.csr_matrix], P: List[sp.csr_matrix],
                 R: List[sp.csr_matrix], coarse, device, dtype):
        self.device, self.dtype = torch.device(device), dtype
        self.A = [_to_torch(a, device, dtype) for a in A[:-1]]
        self.P = [_to_torch(p, device, dtype) for p in P]
        self.R = [_to_torch(r, device, dtype) for r in R]
        self.inv_diag = [torch.from_numpy(1.0 / a.diagonal()).to(
            device=device, dtype=dtype)[:, None] for a in A[:-1]]
        generator = torch.Generator().manual_seed(0)
        self.top = []
        for a, inv_diag in zip(self.A, self.inv_diag):
            v = torch.rand(a.size(0), 1, generator=generator,
                           dtype=torch.float64).to(device, dtype)
            estimate = 1.0
            for _ in range(POWER_STEPS):  # largest eigenvalue of D^-1 A
                v = inv_diag * (a @ v)
                estimate = float(v.norm())
                v = v / estimate
            self.top.append(SAFETY * estimate)
        self.coarse = coarse  # scipy's SuperLU of the coarsest matrix

    def coarse_solve(self, b: Tensor) -> Tensor:
        x = self.coarse.solve(b.detach().cpu().double().numpy())
        return torch.from_numpy(x).to(self.device, self.dtype)

    def smooth(self, level: int, x: Tensor, b: Tensor, steps: int) -> Tensor:
        """``steps`` Chebyshev iterations preconditioned by the diagonal."""
        if steps == 0:
            return x
        A, inv_diag = self.A[level], self.inv_diag[level]
        upper = self.top[level]
        lower = upper / LOWER_FRACTION
        theta, delta = (upper + lower) / 2, (upper - lower) / 2
        sigma = theta / delta
        rho = 1.0 / sigma
        r = b - A @ x
        d = inv_diag * r / theta
        for step in range(steps):
            x = x + d
            if step == steps - 1:
                break
            r = r - A @ d
            rho_next = 1.0 / (2.0 * sigma - rho)
            d = rho_next * rho * d + (2.0 * rho_next / delta) * (inv_diag * r)
            rho = rho_next
        return x

    def cycle(self, level: int, b: Tensor, x: Tensor, kind: str, pre: int,
              post: int) -> Tensor:
        if level == len(self.A):
            return self.coarse_solve(b)
        x = self.smooth(level, x, b, pre)
        coarse_b = self.R[level] @ (b - self.A[level] @ x)
        coarse_x = torch.zeros_like(coarse_b)
        for _ in range(2 if kind == 'W' else 1):
            coarse_x = self.cycle(level + 1, coarse_b, coarse_x, kind, pre,
                                  post)
        if kind == 'F':
            coarse_x = self.cycle(level + 1, coarse_b, coarse_x, 'V', pre,
                                  post)
        x = x + self.P[level] @ coarse_x
        return self.smooth(level, x, b, post)
