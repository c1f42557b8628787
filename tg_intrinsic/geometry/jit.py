r"""The one decorator of every numba kernel of the package: numba's
``njit`` with its compile cache on wherever a cache folder is writable.

numba's ``cache=True`` picks the folder when a function is decorated, at
import: ``NUMBA_CACHE_DIR``, else the ``__pycache__`` beside the source,
else the user-wide cache (``~/.cache/numba``). Where none of them can be
written (a shared read-only install, a container whose home is read-only)
numba raises ``RuntimeError: cannot cache function ...: no locator
available`` and the import fails. :func:`jit` compiles such a kernel
without the cache instead (each process compiles what it uses) and warns
once per process (:class:`NumbaCacheWarning`) how to turn the cache back
on.

One rule for the kernels, checked by ``tests/test_numba_cache.py``: a
kernel without ``parallel=True`` never calls one with it, directly or
through helpers. numba links the callee into the caller's object code, but
records "start the parallel runtime before loading" only in kernels
compiled with ``parallel=True`` (and in callers that compiled the parallel
callee in the same process). A serial caller compiled in a process that
loaded its parallel callee from the cache is therefore cached without that
record, and a later process that loads it before any parallel kernel
aborts with ``LLVM ERROR: Symbol not found: allocate_sched``. Call the
shared per-element code as a serial helper from both instead, or make the
caller parallel too.
"""
import os
import threading
import warnings

import numba

__all__ = ['jit', 'NumbaCacheWarning']


class NumbaCacheWarning(UserWarning):
    """numba's compile cache is off because no cache folder is writable."""


_warned = False
_lock = threading.Lock()


def _user_cache_dir() -> str:
    """numba's user-wide cache folder (where its locator looks)."""
    try:
        from numba.misc.appdirs import AppDirs
        return AppDirs(appname='numba', appauthor=False).user_cache_dir
    except Exception:  # noqa: BLE001 - only words for the message
        return '~/.cache/numba'


def cache_off_message() -> str:
    """What the warning says: why the cache is off, and how to turn it
    back on."""
    cache_dir = numba.config.CACHE_DIR or os.environ.get('NUMBA_CACHE_DIR')
    tried = (f"NUMBA_CACHE_DIR '{cache_dir}' is not writable"
             if cache_dir else 'NUMBA_CACHE_DIR is not set')
    return (f"numba's compile cache is off because no cache location is "
            f"writable ({tried}, and neither the package's __pycache__ "
            f"folders nor '{_user_cache_dir()}' can be written): numba "
            f"kernels are compiled again in every process; set "
            f"NUMBA_CACHE_DIR to a writable folder to turn the cache back "
            f"on")


def _warn_once():
    global _warned
    with _lock:
        if _warned:
            return
        _warned = True
    # One line: it fires while the package is imported, before the
    # command line can format it, and the kernel's source line (which
    # Python would print below) says nothing to a user.
    warnings.warn_explicit(cache_off_message(), NumbaCacheWarning,
                           filename=__file__, lineno=0,
                           module=__name__)


def _no_locator(error: RuntimeError) -> bool:
    return 'no locator available' in str(error)


def _compile(function, options):
    if not options.get('cache', True):
        return numba.njit(**options)(function)
    try:
        return numba.njit(**dict(options, cache=True))(function)
    except RuntimeError as error:
        if not _no_locator(error):
            raise
    _warn_once()
    return numba.njit(**dict(options, cache=False))(function)


def jit(function=None, **options):
    r"""``numba.njit(cache=True, **options)``, or ``cache=False`` with one
    :class:`NumbaCacheWarning` per process where numba finds no writable
    cache folder. Used bare (``@jit``) or with numba's options
    (``@jit(parallel=True)``, ``@jit(inline='always')``, ...).

    A kernel without ``parallel=True`` must not call one with it (see the
    module's docstring): its cached copy could not be loaded by a later
    process.

    Args:
        function (callable, optional): The Python function to compile.
            (default: :obj:`None`, returns a decorator)
        **options: Options of :func:`numba.njit`; ``cache`` defaults to
            :obj:`True`.
    """
    if function is None:
        return lambda f: _compile(f, options)
    return _compile(function, options)
