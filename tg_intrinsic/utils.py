"""Small I/O helpers: outputs are written atomically (temp file + rename), so
an interrupted run never leaves a half-written result or checkpoint."""
import io
import json
import os
import platform
import secrets
from typing import Any

import torch


# Temporary files of atomic writes start with this, e.g.
# '.tmp-k2j4h8checkpoint.pt'; a process killed while writing leaves one.
TEMPORARY_PREFIX = '.tmp-'


def _temporary_beside(path: str, make_folder: bool) -> str:
    """A new temporary file's name beside ``path`` (the file is not
    created yet: see :func:`_create`); its folder is created when
    ``make_folder``."""
    folder = os.path.dirname(os.path.abspath(path))
    if make_folder:
        os.makedirs(folder, exist_ok=True)
    # the name's end (its extension) tells it apart; all of a long name
    # would not fit beside the prefix
    return os.path.join(folder, TEMPORARY_PREFIX + secrets.token_hex(8)
                        + os.path.basename(path)[-64:])


def _create(temporary: str, path: str) -> int:
    """Creates ``temporary`` (exclusively, with 0666 minus the umask, the
    permissions of any new file) and returns its descriptor. A missing
    folder is named in the error (not the temporary file, which the user
    never asked for)."""
    flags = (os.O_WRONLY | os.O_CREAT | os.O_EXCL
             | getattr(os, 'O_NOFOLLOW', 0) | getattr(os, 'O_BINARY', 0))
    try:
        return os.open(temporary, flags, 0o666)
    except (FileNotFoundError, NotADirectoryError):
        folder = os.path.dirname(temporary)
        if os.path.isdir(folder):
            raise
        problem = 'is not a folder' if os.path.exists(folder) else \
            'does not exist'
        raise FileNotFoundError(
            f"cannot write '{path}': the folder '{folder}' {problem}; "
            f"create it first (e.g. os.makedirs) or write the file "
            f"elsewhere") from None


def _discard(temporary: str, error: BaseException):
    """Removes ``temporary`` after ``error`` stopped a write; not when the
    error is that the name was taken (the file is someone else's)."""
    if isinstance(error, FileExistsError) and error.filename == temporary:
        return
    try:
        os.remove(temporary)
    except (FileNotFoundError, NotADirectoryError):  # never made
        pass


def os_error_reason(error: OSError) -> str:
    """An operating-system error's reason in words, without ``[Errno N]``
    and the file name (``'no space left on device'``)."""
    return (error.strerror or str(error) or type(error).__name__).lower()


def current_umask() -> int:
    """The process's umask (read by setting it and putting it back)."""
    umask = os.umask(0)
    os.umask(umask)
    return umask


def atomic_write(path: str, write, mode: str, make_folder: bool = True):
    """Calls ``write(f)`` on a temporary file beside ``path`` (opened with
    ``mode``) and renames it onto ``path``: readers see the old file or the
    whole new one, never a part. The folder is created if missing, unless
    ``make_folder=False``: then a missing folder raises a
    :class:`FileNotFoundError` that names it."""
    def write_to(temporary):
        with open(temporary, mode) as f:
            write(f)
    atomic_write_file(path, write_to, make_folder)


def atomic_write_file(path: str, write_to, make_folder: bool = True):
    """:func:`atomic_write` for writers that take a file name:
    ``write_to(temporary)`` writes a temporary file beside ``path`` (with
    the same extension) that then replaces ``path``."""
    # The name is bound before the file exists, so a Ctrl-C at any point
    # after (even inside os.open) finds it to remove: with mkstemp, one
    # landing between the file's creation and the return left it behind.
    tmp = _temporary_beside(path, make_folder)
    try:
        os.close(_create(tmp, path))
        write_to(tmp)
        os.replace(tmp, path)
    except BaseException as error:
        _discard(tmp, error)
        raise


def is_temporary(name: str) -> bool:
    """Whether the file ``name`` (a path or a bare name) is the temporary
    file of an atomic write."""
    return os.path.basename(name).startswith(TEMPORARY_PREFIX)


def remove_temporaries(folder: str) -> list:
    """Removes the temporary files that atomic writes into ``folder`` left
    behind when their process was killed (names starting with
    :data:`TEMPORARY_PREFIX`); returns their names. Call it only where no
    other process is writing into ``folder``."""
    removed = []
    try:
        names = sorted(os.listdir(folder))
    except FileNotFoundError:
        return removed
    for name in names:
        path = os.path.join(folder, name)
        if is_temporary(name) and os.path.isfile(path):
            try:
                os.remove(path)
            except FileNotFoundError:
                continue
            removed.append(name)
    return removed


def atomic_write_json(path: str, obj: Any):
    """Writes ``obj`` as indented JSON to ``path`` atomically."""
    atomic_write(path, lambda f: json.dump(obj, f, indent=2, sort_keys=False), 'w')


def atomic_torch_save(obj: Any, path: str):
    """``torch.save`` that never leaves a truncated file behind."""
    # Serialised in memory first: while torch writes into a Python file
    # object, a Ctrl-C surfaces as torch's RuntimeError ("enforce fail at
    # inline_container.cc") instead of KeyboardInterrupt, and the command
    # would take it for a bad file and go on. (Saving by file name would
    # put the random temporary name into the archive, and the bytes would
    # differ from run to run.)
    buffer = io.BytesIO()
    torch.save(obj, buffer)
    atomic_write(path, lambda f: f.write(buffer.getbuffer()), 'wb')


def machine_info() -> dict:
    """Machine and library versions, recorded next to every benchmark."""
    import numpy
    import scipy
    import torch_geometric
    info = {
        'platform': platform.platform(),
        'processor': platform.processor() or platform.machine(),
        'cpu_count': os.cpu_count(),
        'python': platform.python_version(),
        'torch': torch.__version__,
        'torch_geometric': torch_geometric.__version__,
        'numpy': numpy.__version__,
        'scipy': scipy.__version__,
        'torch_threads': torch.get_num_threads(),
        'cuda': torch.cuda.get_device_name(0) if torch.cuda.is_available()
        else None,
    }
    try:
        import numba
        info['numba'] = numba.__version__
    except ImportError:
        pass
    return info
