import pytest
import torch
from torch_geometric.data import Data

from tg_intrinsic.transforms import MLSOperators


def test_mls_operators_refuse_neighbourhoods_too_small_to_fit():
    # k = 1 (the point alone) used to give all-zero weights silently
    from tg_intrinsic.geometry import build_mls_operators
    for k in (1, 2):
        with pytest.raises(ValueError, match="'k' must be at least 3"):
            MLSOperators(k=k)
        with pytest.raises(ValueError, match="'k' must be at least 3"):
            build_mls_operators(torch.randn(20, 3), k)
    with pytest.raises(ValueError, match="'regularizer' must be positive"):
        MLSOperators(regularizer=0)
    with pytest.raises(ValueError, match="'kernel_width' must be finite"):
        MLSOperators(kernel_width=float('nan'))
    out = MLSOperators(k=3)(Data(pos=torch.randn(20, 3,
                                                 dtype=torch.float64)))
    assert bool((out.grad_weight.abs().sum(1) > 0).any())
