"""One place resolves devices: 'auto' and 'cuda' become an indexed CUDA
device (what torch.cuda.set_device needs), under torchrun the local rank's;
and a training process takes its share of the cores. CUDA is faked here,
so these run on any machine."""
import pytest
import torch

import tg_intrinsic.training.loop as training_loop
import tg_intrinsic.training.prepare as training_prepare
from tg_intrinsic import distributed
from tg_intrinsic.cli import main
from tg_intrinsic.cli.common import UsageError
from tg_intrinsic.devices import default_threads, resolve_device


@pytest.fixture
def two_gpus(monkeypatch):
    """torch.cuda reports two devices; set_device calls are recorded."""
    calls = []
    monkeypatch.setattr(torch.cuda, 'is_available', lambda: True)
    monkeypatch.setattr(torch.cuda, 'device_count', lambda: 2)
    monkeypatch.setattr(torch.cuda, 'current_device', lambda: 0)
    monkeypatch.setattr(torch.cuda, 'set_device', calls.append)
    monkeypatch.delenv('LOCAL_RANK', raising=False)
    return calls


def test_auto_and_cuda_get_an_index(two_gpus, monkeypatch):
    for request in ('auto', 'cuda', torch.device('cuda')):
        assert resolve_device(request) == torch.device('cuda', 0)
    assert resolve_device('cuda:1') == torch.device('cuda', 1)
    assert resolve_device('cpu') == torch.device('cpu')
    monkeypatch.setenv('LOCAL_RANK', '1')  # under torchrun
    assert resolve_device('auto') == torch.device('cuda', 1)
    with pytest.raises(ValueError, match=r"--device 'cuda:2': this machine "
                                         r"has 2 CUDA device\(s\)"):
        resolve_device('cuda:2', '--device')


def test_without_cuda():
    if torch.cuda.is_available():
        pytest.skip('this machine has CUDA')
    assert resolve_device('auto') == torch.device('cpu')
    with pytest.raises(ValueError, match="no CUDA device"):
        resolve_device('cuda')
    with pytest.raises(ValueError, match="'bogus' is not a device"):
        resolve_device('bogus')


def test_start_sets_an_indexed_device(two_gpus, monkeypatch):
    # the default --device auto stopped every training on a CUDA machine:
    # set_device(torch.device('cuda')) needs an index
    monkeypatch.setattr(distributed, 'torchrun_environment', lambda: None)
    device, started = distributed.start('auto', 'auto')
    assert device == torch.device('cuda', 0) and not started
    assert two_gpus == [torch.device('cuda', 0)]
    # under torchrun (a group already made): the local rank's device
    monkeypatch.setattr(distributed, 'torchrun_environment', lambda: {
        'rank': 3, 'local_rank': 1, 'world_size': 4})
    monkeypatch.setattr(torch.distributed, 'is_initialized', lambda: True)
    for request in ('auto', 'cuda'):
        device, _ = distributed.start('auto', request)
        assert device == torch.device('cuda', 1)
    assert two_gpus[-1] == torch.device('cuda', 1)


def test_threads_are_the_cores_shared(monkeypatch):
    import os
    cores = len(os.sched_getaffinity(0))
    assert default_threads({}) == cores
    assert default_threads({'LOCAL_WORLD_SIZE': str(2 * cores)}) == 1
    assert default_threads({'LOCAL_WORLD_SIZE': '2'}) == max(1, cores // 2)


def test_train_takes_its_share_of_the_cores(monkeypatch, tmp_path):
    # three trainings at once each took every core
    threads = []
    monkeypatch.setattr(torch, 'set_num_threads', threads.append)
    monkeypatch.setattr(training_loop, 'default_threads', lambda: 3)

    def stop(args):
        raise UsageError('stopped')
    monkeypatch.setattr(training_prepare, 'source_splits', stop)
    argv = ['train', 'deltanet', '--quiet', '--out', str(tmp_path / 'a')]
    assert main(argv) == 2 and threads == [3]
    assert main(argv + ['--threads', '5']) == 2 and threads[-1] == 5
