"""Small I/O helpers: outputs are written atomically (temp file + rename), so
an interrupted run never leaves a half-written result or checkpoint."""
import json
import os
import platform
import tempfile
from typing import Any

import torch


def atomic_write(path: str, write, mode: str):
    """Calls ``write(f)`` on a temporary file beside ``path`` (opened with
    ``mode``) and renames it onto ``path``: readers see the old file or the
    whole new one, never a part."""
    folder = os.path.dirname(os.path.abspath(path))
    os.makedirs(folder, exist_ok=True)
    fd, tmp = tempfile.mkstemp(dir=folder, prefix='.tmp-',
                               suffix=os.path.basename(path))
    try:
        with os.fdopen(fd, mode) as f:
            write(f)
        # mkstemp creates 0600 files; give the result the usual permissions.
        umask = os.umask(0)
        os.umask(umask)
        os.chmod(tmp, 0o666 & ~umask)
        os.replace(tmp, path)
    except BaseException:
        if os.path.exists(tmp):
            os.remove(tmp)
        raise


def atomic_write_json(path: str, obj: Any):
    """Writes ``obj`` as indented JSON to ``path`` atomically."""
    atomic_write(path, lambda f: json.dump(obj, f, indent=2, sort_keys=False), 'w')


def atomic_torch_save(obj: Any, path: str):
    """``torch.save`` that never leaves a truncated file behind."""
    atomic_write(path, lambda f: torch.save(obj, f), 'wb')


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
