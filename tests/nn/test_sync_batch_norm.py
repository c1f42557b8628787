import pytest
import torch
from torch_geometric.nn.norm import BatchNorm as PyGBatchNorm

from tests.spawn import run_on_processes
from tg_intrinsic.nn import (ComplexBatchNorm, SyncBatchNorm,
                             SyncComplexBatchNorm, convert_sync_batch_norm)

# rows of the full batch each of two processes holds: unequal on purpose
SHARDS = [slice(0, 3), slice(3, 8)]


class Net(torch.nn.Module):
    """Every kind of batch norm the models use: torch's BatchNorm1d on
    [N, C] and on [1, C, N] (DeltaNet's embedding), PyG's wrapper, and
    HSN's complex one."""
    def __init__(self):
        super().__init__()
        self.lin = torch.nn.Linear(3, 4, dtype=torch.float64)
        self.norm = torch.nn.BatchNorm1d(4, dtype=torch.float64)
        self.pyg = PyGBatchNorm(4).double()
        self.points = torch.nn.BatchNorm1d(4, momentum=None,
                                           dtype=torch.float64)
        self.complex = ComplexBatchNorm(4, 2).double()

    def forward(self, x):
        h = self.pyg(self.norm(self.lin(x)).relu())
        points = self.points(h.t().unsqueeze(0)).squeeze(0).t()
        z = torch.complex(h, points).unsqueeze(1).expand(-1, 2, -1)
        z = self.complex(z * torch.tensor([1.0, 2.0], dtype=h.dtype).view(
            1, 2, 1))
        return torch.cat([points, z.real.flatten(1), z.imag.flatten(1)], 1)


def inputs():
    torch.manual_seed(0)
    x = torch.randn(8, 3, dtype=torch.float64) * 2 + 1
    weight = torch.randn(8, 20, dtype=torch.float64)
    return x, weight


def step(net, x, weight):
    """Output, input gradient and (summed) parameter gradients of
    ``sum(net(x) * weight)``, twice (running statistics move too)."""
    x = x.clone().requires_grad_()
    for _ in range(2):
        net.zero_grad()
        x.grad = None
        out = net(x)
        (out * weight).sum().backward()
    return out.detach(), x.grad, {n: p.grad for n, p in
                                  net.named_parameters()}


def _two_processes(rank, world_size, folder):
    x, weight = inputs()
    torch.manual_seed(1)
    synced = convert_sync_batch_norm(Net())
    out, grad_x, grads = step(synced, x[SHARDS[rank]], weight[SHARDS[rank]])
    for g in grads.values():   # what DDP does (it divides by 2 as well)
        torch.distributed.all_reduce(g)
    torch.manual_seed(1)
    alone, _, _ = step(Net(), x[SHARDS[rank]], weight[SHARDS[rank]])
    torch.save({'out': out, 'grad_x': grad_x, 'grads': grads,
                'state': synced.state_dict(), 'alone': alone},
               f'{folder}/{rank}.pt')


def test_two_processes_with_parts_of_the_batch_equal_one_with_all(tmp_path):
    x, weight = inputs()
    torch.manual_seed(1)
    net = Net()
    out, grad_x, grads = step(net, x, weight)
    run_on_processes(_two_processes, 2, str(tmp_path))
    parts = [torch.load(tmp_path / f'{r}.pt') for r in range(2)]
    # float64, the two-pass variance of one process: equal to rounding
    for rank, part in enumerate(parts):
        torch.testing.assert_close(part['out'], out[SHARDS[rank]],
                                   rtol=1e-12, atol=1e-12)
        torch.testing.assert_close(part['grad_x'], grad_x[SHARDS[rank]],
                                   rtol=1e-12, atol=1e-12)
        assert part['grads'].keys() == grads.keys()
        for name, g in grads.items():
            torch.testing.assert_close(part['grads'][name], g, rtol=1e-12,
                                       atol=1e-12)
        # the running statistics (same names as the plain model's)
        state = net.state_dict()
        assert part['state'].keys() == state.keys()
        for name, value in state.items():
            torch.testing.assert_close(part['state'][name], value,
                                       rtol=1e-12, atol=1e-12)
    # per-process statistics (no synchronisation) give other outputs
    assert not torch.allclose(parts[0]['alone'], out[SHARDS[0]], atol=1e-3)


def test_one_process_is_the_ordinary_batch_norm():
    x, weight = inputs()
    torch.manual_seed(1)
    plain = step(Net(), x, weight)
    torch.manual_seed(1)
    synced = convert_sync_batch_norm(Net())
    assert isinstance(synced.norm, SyncBatchNorm)
    assert isinstance(synced.pyg.module, SyncBatchNorm)
    assert isinstance(synced.complex, SyncComplexBatchNorm)
    same = step(synced, x, weight)
    for a, b in zip(plain[:2], same[:2]):
        assert torch.equal(a, b)
    for name, g in plain[2].items():
        assert torch.equal(same[2][name], g)
    # the sums layers compute themselves (DeltaConv's neighbour maximum)
    sums = torch.randn(5)
    assert synced.norm.all_reduce(sums) is sums
    # evaluation uses the running statistics, as the plain layer does
    synced.eval()
    h = torch.randn(5, 4, dtype=torch.float64)
    assert torch.equal(synced.norm(h), torch.nn.functional.batch_norm(
        h, synced.norm.running_mean, synced.norm.running_var,
        synced.norm.weight, synced.norm.bias, False, 0.0, synced.norm.eps))


def test_conversion_shares_parameters_and_keeps_names():
    net = torch.nn.Sequential(torch.nn.Linear(2, 3),
                              torch.nn.BatchNorm1d(3, affine=False))
    state = net.state_dict()
    converted = convert_sync_batch_norm(net)
    assert isinstance(converted[1], SyncBatchNorm)
    assert converted.state_dict().keys() == state.keys()
    net = torch.nn.BatchNorm1d(3).eval()
    layer = convert_sync_batch_norm(net)
    assert layer.weight is net.weight and not layer.training
    assert convert_sync_batch_norm(layer) is layer   # converted once
    assert 'SyncBatchNorm(3' in repr(layer)


def test_bad_input_is_named():
    layer = SyncBatchNorm(3)
    with pytest.raises(ValueError, match=r'expected features \[N, 3\]'):
        layer(torch.randn(3))
    with pytest.raises(ValueError, match=r'got \[4, 2\]'):
        layer(torch.randn(4, 2))
    with pytest.raises(ValueError, match='must be a torch.Tensor'):
        layer([[1.0, 2.0, 3.0]])
