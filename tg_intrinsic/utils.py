"""Small I/O helpers: outputs are written atomically (temp file + rename), so
an interrupted run never leaves a half-written result or checkpoint."""
import io
import json
import os
import platform
import tempfile
from typing import Any

import torch


# Temporary files of atomic writes start with this, e.g.
# '.tmp-k2j4h8checkpoint.pt'; a process killed while writing leaves one.
TEMPORARY_PREFIX = '.tmp-'


def _temporary_beside(path: str, make_folder: bool):
    """``(descriptor, name)`` of a new temporary file in ``path``'s folder,
    which is created when ``make_folder``. A missing folder is named in
    the error (not the temporary file, which the user never asked for)."""
    folder = os.path.dirname(os.path.abspath(path))
    if make_folder:
        os.makedirs(folder, exist_ok=True)
    try:
        # the name's end (its extension) tells it apart; all of a long
        # name would not fit beside the prefix
        return tempfile.mkstemp(dir=folder, prefix=TEMPORARY_PREFIX,
                                suffix=os.path.basename(path)[-64:])
    except (FileNotFoundError, NotADirectoryError):
        if os.path.isdir(folder):
            raise
        problem = 'is not a folder' if os.path.exists(folder) else \
            'does not exist'
        raise FileNotFoundError(
            f"cannot write '{path}': the folder '{folder}' {problem}; "
            f"create it first (e.g. os.makedirs) or write the file "
            f"elsewhere") from None


def os_error_reason(error: OSError) -> str:
    """An operating-system error's reason in words, without ``[Errno N]``
    and the file name (``'no space left on device'``)."""
    return (error.strerror or str(error) or type(error).__name__).lower()


def current_umask() -> int:
    """The process's umask (read by setting it and putting it back)."""
    umask = os.umask(0)
    os.umask(umask)
    return umask


def _move_into_place(temporary: str, path: str):
    # mkstemp creates 0600 files; give the result the usual permissions.
    os.chmod(temporary, 0o666 & ~current_umask())
    os.replace(temporary, path)


def atomic_write(path: str, write, mode: str, make_folder: bool = True):
    """Calls ``write(f)`` on a temporary file beside ``path`` (opened with
    ``mode``) and renames it onto ``path``: readers see the old file or the
    whole new one, never a part. The folder is created if missing, unless
    ``make_folder=False``: then a missing folder raises a
    :class:`FileNotFoundError` that names it."""
    fd, tmp = _temporary_beside(path, make_folder)
    try:
        with os.fdopen(fd, mode) as f:
            write(f)
        _move_into_place(tmp, path)
    except BaseException:
        if os.path.exists(tmp):
            os.remove(tmp)
        raise


def atomic_write_file(path: str, write_to, make_folder: bool = True):
    """:func:`atomic_write` for writers that take a file name:
    ``write_to(temporary)`` writes a temporary file beside ``path`` (with
    the same extension) that then replaces ``path``."""
    fd, tmp = _temporary_beside(path, make_folder)
    os.close(fd)
    try:
        write_to(tmp)
        _move_into_place(tmp, path)
    except BaseException:
        if os.path.exists(tmp):
            os.remove(tmp)
        raise


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
        if name.startswith(TEMPORARY_PREFIX) and os.path.isfile(path):
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
