"""Runs a test function on several CPU processes joined by a gloo process
group, as ``torchrun`` would start them: ``RANK``, ``LOCAL_RANK``,
``WORLD_SIZE``, ``MASTER_ADDR`` and ``MASTER_PORT`` are set, and the group
is created from them (``env://``) unless the function does it itself."""
import os
import socket

import torch
import torch.multiprocessing as mp


def free_port() -> int:
    with socket.socket() as s:
        s.bind(('127.0.0.1', 0))
        return s.getsockname()[1]


def torchrun_environment(rank: int, world_size: int, port: int) -> dict:
    return {'RANK': str(rank), 'LOCAL_RANK': str(rank),
            'WORLD_SIZE': str(world_size), 'LOCAL_WORLD_SIZE':
            str(world_size), 'MASTER_ADDR': '127.0.0.1',
            'MASTER_PORT': str(port), 'OMP_NUM_THREADS': '1'}


def _worker(rank, fn, world_size, port, init, args):
    os.environ.update(torchrun_environment(rank, world_size, port))
    torch.set_num_threads(1)
    if init:
        torch.distributed.init_process_group('gloo', rank=rank,
                                             world_size=world_size)
    try:
        fn(rank, world_size, *args)
    finally:
        if init and torch.distributed.is_initialized():
            torch.distributed.destroy_process_group()


def run_on_processes(fn, world_size: int, *args, init: bool = True):
    """Calls ``fn(rank, world_size, *args)`` on :obj:`world_size` fresh
    processes (``fn`` must be a module-level function; results go through
    files). A failure in any process fails the caller."""
    mp.start_processes(_worker, args=(fn, world_size, free_port(), init,
                                      args), nprocs=world_size, join=True,
                       start_method='spawn')
