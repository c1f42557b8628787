import os
import shutil
import sys

import numpy as np
import pytest
import torch

import tg_intrinsic.train as train_module
from tests.spawn import free_port, run_on_processes, torchrun_environment
from tg_intrinsic import distributed
from tg_intrinsic.train import main, parse_args

# Tiny DeltaNet runs with random augmentation (rotation, scale,
# translation), constant-rate SGD and no dropout: dropout masks are drawn
# per process, so with dropout N processes equal one only in distribution.
ARGS = ['--dataset', 'synthetic_modelnet', '--num-points', '64',
        '--shapes-per-class', '2', '--batch-size', '4', '--conv-channels',
        '8', '8', '--k', '8', '--embedding-size', '32', '--eval-every', '1',
        '--optimizer', 'sgd', '--lr', '0.05', '--schedule', 'step',
        '--milestones', '100', '--dropout', '0', '--no-anisotropic',
        '--rotate', '--translate', '0.1', '--quiet']


def test_every_process_takes_its_part_of_the_same_global_batches():
    for length, batch_size in ((26, 8), (24, 8), (6, 8)):
        alone = distributed.epoch_batches(length, batch_size, 3, 5)
        assert [np.array_equal(a, b) for a, b in zip(
            alone, distributed.global_batches(length, batch_size, 3, 5))]
        parts = [distributed.epoch_batches(length, batch_size, 3, 5, r, 2)
                 for r in range(2)]
        assert len(parts[0]) == len(parts[1]) == len(alone) == \
            (max(length // batch_size, 1))
        for k, batch in enumerate(alone):
            assert parts[0][k] + parts[1][k] == batch
            assert abs(len(parts[0][k]) - len(parts[1][k])) <= 1
        # the remainder is dropped, unless the set is smaller than a batch
        used = sum(len(b) for b in alone)
        assert used == (length if length < batch_size else
                        length // batch_size * batch_size)
        assert len(set(sum(alone, []))) == used
    # a function of (seed, epoch): another epoch or seed, another order
    first = distributed.epoch_batches(24, 8, 3, 5)
    assert first == distributed.epoch_batches(24, 8, 3, 5)
    assert first != distributed.epoch_batches(24, 8, 3, 6)
    assert first != distributed.epoch_batches(24, 8, 4, 5)
    with pytest.raises(ValueError, match='cannot be split over 4'):
        distributed.epoch_batches(3, 8, 0, 1, 0, 4)


def test_the_torchrun_environment():
    assert distributed.torchrun_environment({}) is None
    assert distributed.launched_world_size({}) == 1
    env = torchrun_environment(1, 2, 1234)
    assert distributed.torchrun_environment(env) == {
        'rank': 1, 'world_size': 2, 'local_rank': 1}
    assert distributed.launched_world_size(env) == 2
    with pytest.raises(ValueError, match='not a whole number'):
        distributed.torchrun_environment({**env, 'WORLD_SIZE': 'two'})
    with pytest.raises(ValueError, match='not in 0..WORLD_SIZE-1'):
        distributed.torchrun_environment({**env, 'RANK': '2'})


def test_one_process_is_the_identity():
    device, started = distributed.start()
    assert not started and (distributed.rank(), distributed.world_size()) \
        == (0, 1)
    value = torch.tensor([1.0, 2.0])
    assert distributed.all_reduce_sum(value) is value
    assert torch.equal(value, torch.tensor([1.0, 2.0]))
    assert distributed.broadcast_object({'a': 1}) == {'a': 1}
    assert distributed.rank_zero_first(lambda: 7) == 7
    assert distributed.shard(range(5), 1, 2).tolist() == [3, 4]
    assert distributed.derived_seed(0, 1) != distributed.derived_seed(0, 2)
    with pytest.raises(ValueError, match='backend must be one of'):
        distributed.start('mpi')


def test_the_batch_must_split_evenly(monkeypatch, capsys):
    monkeypatch.setattr(os, 'environ', {**os.environ,
                                        **torchrun_environment(0, 3, 1)})
    assert parse_args(['--batch-size', '6']).batch_size == 6
    with pytest.raises(SystemExit) as exit_info:
        parse_args(['--batch-size', '8'])
    assert exit_info.value.code == 2
    assert ('--batch-size 8 is the global batch, split evenly over the 3 '
            'processes: make it a multiple of 3') in capsys.readouterr().err


WRITERS = ('atomic_torch_save', 'atomic_write_json', 'write_metrics_csv',
           'plot_history', 'remove_temporaries')


def _scenarios(rank, world_size, folder, ports):
    """The runs of two processes, with torchrun's environment: what rank
    1 printed and which writers it called go to files."""
    calls = []
    if rank:
        for name in WRITERS:
            def record(*args, name=name, **kwargs):
                calls.append(name)
            setattr(train_module, name, record)
    runs = {'sync': ['--sync-batch-norm', '--epochs', '1', '--root',
                     f'{folder}/fresh'],
            'per_rank': ['--epochs', '1'],
            'resumed_1_to_2': ['--sync-batch-norm', '--epochs', '2',
                               '--resume', '--allow-changes', 'epochs']}
    for (name, extra), port in zip(runs.items(), ports):
        os.environ['MASTER_PORT'] = str(port)
        stdout = sys.stdout
        with open(f'{folder}/{name}.{rank}.txt', 'w') as sys.stdout:
            try:
                main(ARGS + ['--root', f'{folder}/data', '--out',
                             f'{folder}/{name}'] + extra)
            finally:
                sys.stdout = stdout
    with open(f'{folder}/calls.{rank}.txt', 'w') as f:
        f.write('\n'.join(calls))


def weights(folder):
    return torch.load(os.path.join(folder, 'checkpoint.pt'),
                      weights_only=False)


def assert_close_runs(a, b, tolerance):
    """Parameters and buffers of two checkpoints within :obj:`tolerance`
    of the largest of them, the momenta (sums of gradients, which carry
    more rounding than the weights) within 10 times that (counts equal);
    the same history."""
    assert a['epoch'] == b['epoch']
    for key, tolerance in (('model', tolerance),
                           ('optimizer', 10 * tolerance)):
        flat_a, flat_b = _tensors(a[key]), _tensors(b[key])
        assert flat_a.keys() == flat_b.keys()
        scale = max(float(v.abs().max()) for v in flat_b.values()
                    if v.is_floating_point() and v.numel())
        for name, value in flat_b.items():
            if not value.is_floating_point():
                assert torch.equal(flat_a[name], value), (key, name)
                continue
            torch.testing.assert_close(
                flat_a[name].double(), value.double(), rtol=0,
                atol=tolerance * scale,
                msg=lambda m, k=key, n=name: f'{k} {n}: {m}')
    for x, y in zip(a['history'], b['history']):
        assert x['epoch'] == y['epoch']
        assert x['train_loss'] == pytest.approx(y['train_loss'], rel=1e-5)
        for score in ('train_accuracy', 'test_accuracy'):
            assert x[score] == y[score]


def _tensors(tree, prefix=''):
    if isinstance(tree, dict):
        return {k: v for key, value in tree.items()
                for k, v in _tensors(value, f'{prefix}{key}.').items()}
    if isinstance(tree, (list, tuple)):
        return {k: v for i, value in enumerate(tree)
                for k, v in _tensors(value, f'{prefix}{i}.').items()}
    return {prefix: tree} if isinstance(tree, torch.Tensor) else {}


def test_two_processes_train_as_one(tmp_path):
    # Tolerances relative to the largest weight (10 times more for the
    # momenta, sums of gradients): float32, and two processes sum the
    # gradients and the batch statistics in another order (two partial
    # sums, then the all-reduce) than one. That is rounding, of the size of
    # the thread count's, which these tiny nets (batch norm over 4 shapes,
    # SGD at 0.05) amplify step by step. Measured: after 1 epoch (3 steps)
    # two processes differ from one by 4.6e-6; after 2 epochs the same
    # one-process run on 1 and on 2 threads differs by 5.6e-5, resumed
    # runs by up to 2.3e-4 (2 -> 1 processes). Hence 1e-4 after one epoch
    # and 1e-3 after two. Per-process batch norm statistics differ by 2.8.
    root = str(tmp_path / 'data')

    def single(out, *extra):
        return main(ARGS + ['--root', root, '--out', str(tmp_path / out),
                            *extra])

    single('one', '--epochs', '1')
    shutil.copytree(tmp_path / 'one', tmp_path / 'resumed_1_to_2')
    single('straight', '--epochs', '2')
    run_on_processes(_scenarios, 2, str(tmp_path),
                     [free_port() for _ in range(3)], init=False)
    one, straight = weights(tmp_path / 'one'), weights(tmp_path / 'straight')
    synced = weights(tmp_path / 'sync')
    assert synced['world_size'] == 2
    assert_close_runs(synced, one, 1e-4)
    # per-process batch norm statistics: another run
    with pytest.raises(AssertionError):
        assert_close_runs(weights(tmp_path / 'per_rank'), one, 0.1)
    # resumed with two processes from one process's checkpoint ...
    assert_close_runs(weights(tmp_path / 'resumed_1_to_2'), straight,
                      1e-3)
    # ... and with one from two processes' checkpoint
    shutil.copytree(tmp_path / 'sync', tmp_path / 'resumed_2_to_1')
    metrics = single('resumed_2_to_1', '--epochs', '2', '--resume',
                     '--allow-changes', 'epochs', '--sync-batch-norm')
    assert [h['epoch'] for h in metrics['history']] == [1, 2]
    assert_close_runs(weights(tmp_path / 'resumed_2_to_1'), straight,
                      1e-3)
    # only rank 0 wrote and printed
    assert sorted(os.listdir(tmp_path / 'sync')) == [
        '.tg-intrinsic.json', 'checkpoint.pt', 'learning_curve.png',
        'metrics.csv', 'metrics.json']
    assert (tmp_path / 'calls.1.txt').read_text() == ''
    assert (tmp_path / 'sync.1.txt').read_text() == ''
    assert 'final test accuracy' in (tmp_path / 'sync.0.txt').read_text()
    assert '2 processes' in (tmp_path / 'sync.0.txt').read_text()
