"""Data-parallel training across processes started by ``torchrun``: what
:mod:`tg_intrinsic.train` needs from :mod:`torch.distributed`.

``torchrun`` (or ``python -m torch.distributed.run``, or a cluster
launcher that sets the same variables) starts one process per device and
describes the run in each one's environment: ``RANK``, ``WORLD_SIZE``,
``LOCAL_RANK``, ``MASTER_ADDR`` and ``MASTER_PORT``. :func:`start` joins
the process group they describe (backend ``gloo`` on the CPU, ``nccl`` on
CUDA, device ``cuda:LOCAL_RANK``); without them every function here is the
single-process identity, so one training loop serves both.

The training batches are a function of (seed, epoch) only: every epoch
shuffles the training set with a generator seeded by both, cuts it into
global batches of ``batch_size`` (the remainder dropped, unless the set
is smaller than one batch), and gives each process its contiguous part of
every batch (:func:`epoch_batches`). So one process and N processes see
the same global batches, and a run resumed at an epoch boundary, with any
number of processes, continues as an uninterrupted one.
"""
import os
from typing import Callable, List, Optional, Tuple

import numpy as np
import torch

from tg_intrinsic.devices import resolve_device

__all__ = [
    'start', 'stop', 'rank', 'world_size', 'torchrun_environment',
    'launched_world_size', 'all_reduce_sum', 'broadcast_object',
    'broadcast_buffers', 'rank_zero_first', 'derived_seed',
    'global_batches', 'shard', 'epoch_batches', 'BACKENDS',
]

#: The process-group backends of :func:`start` ('auto': nccl on CUDA, else
#: gloo).
BACKENDS = ('auto', 'gloo', 'nccl')


def torchrun_environment(environ=None) -> Optional[dict]:
    """``{'rank', 'world_size', 'local_rank'}`` from the variables
    ``torchrun`` sets, or :obj:`None` outside a ``torchrun`` launch."""
    environ = os.environ if environ is None else environ
    if 'RANK' not in environ or 'WORLD_SIZE' not in environ:
        return None
    out = {}
    for key, name in (('rank', 'RANK'), ('world_size', 'WORLD_SIZE'),
                      ('local_rank', 'LOCAL_RANK')):
        text = environ.get(name, environ['RANK'] if key == 'local_rank'
                           else None)
        try:
            out[key] = int(text)
        except ValueError:
            raise ValueError(f"the environment variable {name}={text!r} "
                             f"is not a whole number; start the processes "
                             f"with torchrun") from None
    if not 0 <= out['rank'] < out['world_size']:
        raise ValueError(f"RANK={out['rank']} is not in 0..WORLD_SIZE-1 "
                         f"(WORLD_SIZE={out['world_size']})")
    return out


def launched_world_size(environ=None) -> int:
    """The number of processes ``torchrun`` started (1 outside it)."""
    env = torchrun_environment(environ)
    return 1 if env is None else env['world_size']


def start(backend: str = 'auto', device: str = 'auto'
          ) -> Tuple[torch.device, bool]:
    """The device of this process, after joining the process group that
    ``torchrun``'s environment describes (``backend`` ``'auto'``: ``nccl``
    on CUDA, ``gloo`` on the CPU; a CUDA device without an index becomes
    ``cuda:LOCAL_RANK``). Returns ``(device, started)``: ``started`` is
    whether this call created the group (then :func:`stop` ends it); a
    group created by the caller is used as it is."""
    import torch.distributed as dist
    if backend not in BACKENDS:
        raise ValueError(f"backend must be one of {BACKENDS}, got "
                         f"{backend!r}")
    env = torchrun_environment()
    device = resolve_device(device, rank=None if env is None
                            else env['local_rank'])
    if device.type == 'cuda':
        torch.cuda.set_device(device)
    if env is None or dist.is_initialized():
        return device, False
    if backend == 'auto':
        backend = 'nccl' if device.type == 'cuda' else 'gloo'
    if backend == 'nccl' and device.type != 'cuda':
        raise ValueError("the nccl backend needs CUDA devices; use "
                         "--backend gloo (or auto) on the CPU")
    dist.init_process_group(backend, rank=env['rank'],
                            world_size=env['world_size'])
    return device, True


def stop() -> None:
    """Ends the process group (if there is one)."""
    import torch.distributed as dist
    if dist.is_available() and dist.is_initialized():
        dist.destroy_process_group()


def _active() -> bool:
    import torch.distributed as dist
    return dist.is_available() and dist.is_initialized()


def rank() -> int:
    """This process's rank (0 outside a process group)."""
    import torch.distributed as dist
    return dist.get_rank() if _active() else 0


def world_size() -> int:
    """The number of processes (1 outside a process group)."""
    import torch.distributed as dist
    return dist.get_world_size() if _active() else 1


def all_reduce_sum(tensor: torch.Tensor) -> torch.Tensor:
    """:obj:`tensor` summed over the processes, in place (on the device of
    the backend: CUDA for nccl); returns it."""
    import torch.distributed as dist
    if world_size() > 1:
        dist.all_reduce(tensor)
    return tensor


def broadcast_object(obj, src: int = 0):
    """Rank :obj:`src`'s :obj:`obj` (any picklable object) on every
    process; also a barrier."""
    import torch.distributed as dist
    if world_size() == 1:
        return obj
    box = [obj]
    dist.broadcast_object_list(box, src=src)
    return box[0]


def broadcast_buffers(module: torch.nn.Module, src: int = 0) -> None:
    """Copies rank :obj:`src`'s buffers (batch norm running statistics)
    of :obj:`module` to every process."""
    import torch.distributed as dist
    if world_size() > 1:
        for buffer in module.buffers():
            dist.broadcast(buffer, src=src)


def rank_zero_first(fn: Callable):
    """Calls :obj:`fn` on rank 0 and, once it returned, on the other ranks,
    which then read what rank 0 wrote (such as a data cache) instead of
    racing to write it. A failure on rank 0 is raised on every rank."""
    if world_size() == 1:
        return fn()
    if rank() == 0:
        try:
            result = fn()
        except BaseException as error:
            broadcast_object(f'{type(error).__name__}: {error}')
            raise
        broadcast_object(None)
        return result
    failed = broadcast_object(None)
    if failed is not None:
        raise RuntimeError(f"rank 0 failed while preparing the data: "
                           f"{failed}")
    return fn()


def derived_seed(*numbers: int) -> int:
    """A 32-bit seed derived from :obj:`numbers` (such as seed, epoch and
    rank), independent streams for different tuples."""
    return int(np.random.SeedSequence([int(n) for n in numbers])
               .generate_state(1)[0])


def global_batches(length: int, batch_size: int, seed: int, epoch: int
                   ) -> List[np.ndarray]:
    """The epoch's batches of indices into a set of :obj:`length` items:
    a permutation seeded by (seed, epoch) cut into ``length //
    batch_size`` batches (the rest dropped), or one batch of all items
    when the set is smaller than a batch."""
    order = np.random.default_rng(derived_seed(seed, epoch)).permutation(
        length)
    if length < batch_size:
        return [order] if length else []
    count = length // batch_size
    return list(order[:count * batch_size].reshape(count, batch_size))


def shard(items, rank: int, world_size: int):
    """Process :obj:`rank`'s contiguous part of :obj:`items` (parts differ
    by at most one item)."""
    return np.array_split(np.asarray(items), world_size)[rank]


def epoch_batches(length: int, batch_size: int, seed: int, epoch: int,
                  rank: int = 0, world_size: int = 1) -> List[List[int]]:
    """Process :obj:`rank`'s part of every batch of
    :func:`global_batches`: a ``batch_sampler`` for a
    :class:`~torch_geometric.loader.DataLoader`."""
    if length and min(length, batch_size) < world_size:
        raise ValueError(f"{min(length, batch_size)} training items per "
                         f"batch cannot be split over {world_size} "
                         f"processes; use fewer processes or more data")
    return [shard(batch, rank, world_size).tolist()
            for batch in global_batches(length, batch_size, seed, epoch)]
