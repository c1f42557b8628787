"""The one place that turns a device request (``auto``, ``cpu``, ``cuda``,
``cuda:N``, ``mps``) into a :class:`torch.device`, and sets the thread
count a process takes by the cores it shares.

Every command's ``--device`` and the training loop go through
:func:`resolve_device`: ``auto`` is a GPU when there is one, and a CUDA
device always carries its index (``cuda:0``, or ``cuda:LOCAL_RANK`` under
``torchrun``), which :func:`torch.cuda.set_device` needs.
"""
import contextlib
import os
from typing import Optional

import torch

__all__ = [
    'resolve_device', 'check_device', 'local_rank', 'default_threads',
    'PRECISIONS', 'check_precision', 'autocast',
]

ACCEPTED = "auto, cpu, cuda, cuda:N (N a GPU's index) or mps"


def check_device(device: str, name: str = 'device') -> None:
    """Raises a :class:`ValueError` naming ``name`` unless ``device`` is
    ``'auto'``, ``'cpu'``, ``'cuda'``, ``'cuda:N'`` or ``'mps'`` and this
    machine has it."""
    if device == 'auto':
        return
    try:
        parsed = torch.device(device)
    except (RuntimeError, ValueError, TypeError):
        raise ValueError(f"{name} {device!r} is not a device; use "
                         f"{ACCEPTED}") from None
    if parsed.type == 'cuda':
        count = torch.cuda.device_count() if torch.cuda.is_available() \
            else 0
        if not count:
            raise ValueError(f"{name} {device!r}: PyTorch finds no CUDA "
                             f"device on this machine; use cpu or auto")
        if parsed.index is not None and parsed.index >= count:
            raise ValueError(f"{name} {device!r}: this machine has {count} "
                             f"CUDA device(s), cuda:0 to cuda:{count - 1}")
    elif parsed.type == 'mps':
        mps = getattr(torch.backends, 'mps', None)
        if mps is None or not mps.is_available():
            raise ValueError(f"{name} {device!r}: PyTorch finds no MPS "
                             f"(Apple GPU) device on this machine; use cpu "
                             f"or auto")
    elif parsed.type != 'cpu':
        raise ValueError(f"{name} {device!r} is not supported; use "
                         f"{ACCEPTED}")


def local_rank(environ=None) -> Optional[int]:
    """This process's ``LOCAL_RANK`` under ``torchrun``, else :obj:`None`."""
    value = (os.environ if environ is None else environ).get('LOCAL_RANK')
    return None if value in (None, '') else int(value)


def resolve_device(device='auto', name: str = 'device',
                   rank: Optional[int] = None) -> torch.device:
    """The :class:`torch.device` that ``device`` asks for on this machine
    (checked by :func:`check_device`): ``'auto'`` is CUDA when available,
    else the CPU; a CUDA device without an index gets ``rank`` (default:
    ``LOCAL_RANK`` under ``torchrun``, else the current device, 0 unless
    changed). A :class:`torch.device` is checked the same way."""
    text = str(device)
    check_device(text, name)
    if text == 'auto':
        text = 'cuda' if torch.cuda.is_available() else 'cpu'
    parsed = torch.device(text)
    if parsed.type == 'cuda' and parsed.index is None:
        index = local_rank() if rank is None else rank
        if index is None:
            index = torch.cuda.current_device()
        parsed = torch.device('cuda', index)
        check_device(str(parsed), name)
    return parsed


def default_threads(environ=None) -> int:
    """Torch threads for a process that shares this machine's cores with
    the other processes ``torchrun`` started on it (``LOCAL_WORLD_SIZE``):
    the cores this process may run on (its CPU affinity) divided among
    them, at least 1."""
    environ = os.environ if environ is None else environ
    try:
        cores = len(os.sched_getaffinity(0))
    except AttributeError:  # not on Linux
        cores = os.cpu_count() or 1
    sharing = int(environ.get('LOCAL_WORLD_SIZE') or 1)
    return max(1, cores // max(1, sharing))


#: Training precisions, named as Lightning names them: float32 throughout,
#: or ``torch.autocast`` to bfloat16 / float16 (with gradient scaling). The
#: layers run their sparse and complex maths in float32 inside either.
PRECISIONS = ('32-true', 'bf16-mixed', '16-mixed')


def check_precision(precision: str, device: torch.device) -> None:
    """``precision`` must be one of :data:`PRECISIONS` that ``device`` can
    run: float16 autocast with gradient scaling is a CUDA feature."""
    if precision not in PRECISIONS:
        raise ValueError(f"precision must be one of {', '.join(PRECISIONS)}, "
                         f"got {precision!r}")
    if precision == '16-mixed' and device.type != 'cuda':
        raise ValueError(f"precision 16-mixed needs a CUDA device (float16 "
                         f"gradients need scaling there), but the device is "
                         f"{device}; use bf16-mixed on {device.type}")


def autocast(precision: str, device: torch.device):
    """The context in which a model runs at ``precision``: nothing for
    ``'32-true'``, else ``torch.autocast`` to bfloat16 or float16."""
    if precision == '32-true':
        return contextlib.nullcontext()
    dtype = torch.bfloat16 if precision == 'bf16-mixed' else torch.float16
    return torch.autocast(device.type, dtype=dtype)
