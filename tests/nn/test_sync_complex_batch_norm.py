import pytest
import torch

from tg_intrinsic.nn import ComplexBatchNorm, SyncComplexBatchNorm
from tg_intrinsic.nn.sync_complex_batch_norm import active_group

# Two processes with half batches each equal one with the whole batch:
# tests/nn/test_sync_batch_norm.py (it converts a net with both kinds).


def test_outside_a_process_group_it_is_the_complex_batch_norm():
    assert active_group() is None
    torch.manual_seed(0)
    z = torch.randn(10, 2, 3, dtype=torch.complex128)
    plain = ComplexBatchNorm(3, 2).double()
    synced = SyncComplexBatchNorm(3, 2).double()
    with torch.no_grad():
        plain.weight.uniform_(0.5, 2)
        synced.weight.copy_(plain.weight)
    assert torch.equal(plain(z), synced(z))
    assert torch.equal(plain.running_square, synced.running_square)
    plain.eval()
    synced.eval()
    assert torch.equal(plain(z[:3]), synced(z[:3]))
    assert synced.state_dict().keys() == plain.state_dict().keys()
    assert repr(synced) == 'SyncComplexBatchNorm(3, streams=2)'


def test_bad_input_is_named():
    layer = SyncComplexBatchNorm(3, 2)
    with pytest.raises(ValueError, match=r'\[N, 2, 3\]'):
        layer(torch.randn(4, 2, 4, dtype=torch.complex64))
