"""The shared numba decorator: cached where numba finds a writable folder,
uncached with one warning where it finds none. The package-wide checks
(every kernel uses it, no serial kernel calls a parallel one, a cache left
by other processes loads, the command line on a read-only install) are in
tests/test_numba_cache.py."""
import warnings

import numba
import numpy as np
import pytest

import tg_intrinsic.geometry.jit as jit_module
from tg_intrinsic.geometry.jit import NumbaCacheWarning, jit


def cached(dispatcher) -> bool:
    return type(dispatcher._cache).__name__ != 'NullCache'


def _twice(x):  # pragma: no cover (numba)
    return 2 * x


def test_bare_and_with_options_are_cached_njit():
    plain = jit(_twice)
    parallel = jit(parallel=True, fastmath=True)(_twice)
    assert isinstance(plain, numba.core.registry.CPUDispatcher)
    assert cached(plain) and cached(parallel)
    assert not plain.targetoptions.get('parallel')
    assert parallel.targetoptions['parallel'] and \
        parallel.targetoptions['fastmath']
    assert not cached(jit(cache=False)(_twice))


def source_less(name: str):
    """A function whose source file does not exist: numba finds no cache
    folder for it (its real 'no locator available' error, no mock)."""
    scope = {}
    exec(compile(f'def {name}(x):\n    return x + 1\n',
                 f'<no file: {name}>', 'exec'), scope)
    return scope[name]


def test_no_cache_folder_compiles_uncached_with_one_warning(monkeypatch):
    monkeypatch.setattr(jit_module, '_warned', False)
    with pytest.raises(RuntimeError, match='no locator available'):
        numba.njit(cache=True)(source_less('direct'))
    with pytest.warns(NumbaCacheWarning) as record:
        first = jit(source_less('first'))
        second = jit(parallel=True)(source_less('second'))
    assert len(record) == 1
    message = str(record[0].message)
    assert "compile cache is off" in message and 'NUMBA_CACHE_DIR' in message
    assert not cached(first) and not cached(second)
    assert second.targetoptions['parallel']
    assert first(1) == 2 and second(np.arange(3)).tolist() == [1, 2, 3]
    with warnings.catch_warnings():  # once per process
        warnings.simplefilter('error')
        jit(source_less('third'))


def test_other_errors_are_not_hidden(monkeypatch):
    def broken(**options):
        raise RuntimeError('something else')
    monkeypatch.setattr(numba, 'njit', broken)
    with pytest.raises(RuntimeError, match='something else'):
        jit(_twice)
