"""numba's compile cache (issue 40): every cached kernel can be loaded by a
later process, and the command line works where no cache folder is
writable.

* A kernel without ``parallel=True`` that calls one with it is cached
  without numba's "start the parallel runtime first" record when its
  callee came from the cache; a later process loading it then aborts with
  ``LLVM ERROR: Symbol not found: allocate_sched`` (SIGABRT). The call
  graph test forbids the pattern everywhere; the subprocess test replays
  the rasteriser case that crashed ``tg-intrinsic svbrdf --write-example``.
* With no writable cache folder numba raised ``RuntimeError: cannot cache
  function '_fps_update': no locator available`` at import; now the
  kernels compile without the cache after one warning.
"""
import os
import re
import shutil
import subprocess
import sys
import types

import pytest
from numba.core.registry import CPUDispatcher

import tg_intrinsic

PACKAGE = os.path.dirname(tg_intrinsic.__file__)
ROOT = os.path.dirname(PACKAGE)
DECORATOR = os.path.join(PACKAGE, 'geometry', 'jit.py')
WARNING = "numba's compile cache is off"


def kernel_modules():
    """The modules that define numba kernels (through the shared ``jit``)."""
    names = []
    for folder, _, files in os.walk(PACKAGE):
        for file in sorted(files):
            path = os.path.join(folder, file)
            if not file.endswith('.py') or path == DECORATOR:
                continue
            with open(path, encoding='utf-8') as f:
                source = f.read()
            if re.search(r'^\s*@jit\b', source, flags=re.M):
                module = os.path.relpath(path, ROOT)[:-3]
                names.append(module.replace(os.sep, '.'))
    return sorted(names)


def test_every_kernel_goes_through_the_shared_decorator():
    # one owner for the caching decision: nobody calls numba.njit itself
    direct = []
    for folder, _, files in os.walk(PACKAGE):
        for file in files:
            path = os.path.join(folder, file)
            if not file.endswith('.py') or path == DECORATOR:
                continue
            with open(path, encoding='utf-8') as f:
                for number, line in enumerate(f, 1):
                    if re.search(r'\bnjit\b|numba\.jit\b|cache\s*=\s*True',
                                 line):
                        direct.append(f'{os.path.relpath(path, ROOT)}:'
                                      f'{number}: {line.strip()}')
    assert not direct, '\n'.join(direct)
    assert len(kernel_modules()) >= 20


def _dispatchers():
    import importlib
    found = {}
    for name in kernel_modules():
        module = importlib.import_module(name)
        for value in vars(module).values():
            if isinstance(value, CPUDispatcher) and \
                    value.py_func.__module__ == name:
                found[f'{name}.{value.py_func.__name__}'] = value
    return found


def _referenced_names(code):
    names = set(code.co_names)
    for const in code.co_consts:
        if isinstance(const, types.CodeType):
            names |= _referenced_names(const)
    return names


def _callees(dispatcher):
    """The numba kernels a kernel refers to: globals, and attributes of
    modules it refers to (``heap.sift_up``)."""
    names = _referenced_names(dispatcher.py_func.__code__)
    scope = dispatcher.py_func.__globals__
    out = []
    for name in names:
        value = scope.get(name)
        if isinstance(value, CPUDispatcher):
            out.append(value)
        elif isinstance(value, types.ModuleType):
            out += [getattr(value, attr) for attr in names
                    if isinstance(getattr(value, attr, None), CPUDispatcher)]
    return out


def test_no_serial_kernel_calls_a_parallel_one():
    kernels = _dispatchers()
    assert len(kernels) > 50

    def parallel(kernel):
        return bool(kernel.targetoptions.get('parallel'))

    def name(kernel):
        return f'{kernel.py_func.__module__}.{kernel.py_func.__name__}'

    bad = []
    for kernel in kernels.values():
        if parallel(kernel):
            continue
        seen, todo, path = set(), list(_callees(kernel)), {}
        for callee in todo:
            path.setdefault(id(callee), [name(kernel), name(callee)])
        while todo:
            callee = todo.pop()
            if id(callee) in seen:
                continue
            seen.add(id(callee))
            if parallel(callee):
                bad.append(' -> '.join(path[id(callee)]))
                continue
            for deeper in _callees(callee):
                path.setdefault(id(deeper),
                                path[id(callee)] + [name(deeper)])
                todo.append(deeper)
    assert not bad, ('serial kernels calling parallel ones (their cached '
                     'copies abort a later process):\n' + '\n'.join(bad))


def test_every_kernel_is_cached_where_a_folder_is_writable():
    kernels = _dispatchers()
    uncached = [name for name, kernel in kernels.items()
                if type(kernel._cache).__name__ == 'NullCache']
    assert not uncached


# --------------------------------------------- a cache left by a process
RASTER_STEP = r'''
import importlib
import sys

import numpy as np
import torch
import trimesh

step, modules = sys.argv[1], sys.argv[2:]
for name in modules:  # every kernel module imports from a warm cache
    importlib.import_module(name)
from tg_intrinsic.geometry.appearance import raster

mesh = trimesh.creation.icosphere(1)
V = torch.tensor(mesh.vertices) + torch.tensor([0.0, 0.0, 4.0])
F = torch.tensor(mesh.faces).t().contiguous()
K = torch.tensor([[16.0, 0, 8], [0, 16, 8], [0, 0, 1]], dtype=torch.float64)
E = torch.cat([torch.eye(3, dtype=torch.float64),
               torch.zeros(3, 1, dtype=torch.float64)], 1)
# contiguous, as real cameras are: the kernels see the same types
Ks, Es = K.repeat(3, 1, 1), E.repeat(3, 1, 1)
if step == 'rasterize':
    face_id = raster.rasterize(V, F, K, E, 16, 16)[0]
    assert (face_id >= 0).any()
elif step == 'one camera':
    seen = raster.point_visibility(V, V, F, K[None], E[None], 16, 16)
    assert seen.any()
else:  # the cameras kernel of svbrdf --write-example, then the others
    needed = torch.ones(V.shape[0], 3, dtype=torch.bool)
    many = raster.point_visibility(V, V, F, Ks, Es, 16, 16, needed=needed)
    one = raster.point_visibility(V, V, F, K[None], E[None], 16, 16)
    assert torch.equal(many[:, :1], one) and one.any()
    assert (raster.rasterize(V, F, K, E, 16, 16)[0] >= 0).any()
print('ok', step)
'''


def _python(args, env, cwd, timeout=300):
    return subprocess.run([sys.executable] + args, env=env, cwd=cwd,
                          capture_output=True, text=True, timeout=timeout)


def _unsafe_entries(cache_dir):
    """Cached kernels whose object code calls numba's parallel scheduler
    but that do not start the parallel runtime when loaded (numba's own
    names: the scheduler's ``allocate_sched``, the ``_reload_parfors``
    record); None when no entry has the record (other names in this numba
    version: nothing to check)."""
    unsafe, recorded = [], False
    for folder, _, files in os.walk(cache_dir):
        for file in files:
            if not file.endswith('.nbc'):
                continue
            with open(os.path.join(folder, file), 'rb') as f:
                data = f.read()
            recorded |= b'_reload_parfors' in data
            if b'allocate_sched' in data and b'_reload_parfors' not in data:
                unsafe.append(file)
    return unsafe if recorded else None


def test_kernels_load_from_a_cache_left_by_other_processes(tmp_path):
    # 1. rasterize compiles the parallel _face_extents; 2. one camera's
    # visibility loads it from the cache and compiles the grid of
    # candidates around it; 3. the cameras kernel of svbrdf --write-example
    # loads that grid from the cache before any parallel kernel ran
    # (before the fix: LLVM ERROR: Symbol not found: allocate_sched)
    cache = tmp_path / 'numba_cache'
    cache.mkdir()
    env = dict(os.environ, NUMBA_CACHE_DIR=str(cache),
               PYTHONPATH=os.pathsep.join(
                   [ROOT] + [p for p in [os.environ.get('PYTHONPATH')] if p]))
    modules = kernel_modules()
    for step in ('rasterize', 'one camera', 'cameras'):
        done = _python(['-c', RASTER_STEP, step]
                       + (modules if step == 'cameras' else []),
                       env, str(tmp_path))
        assert done.returncode == 0 and 'LLVM ERROR' not in done.stderr, \
            f'{step}: exit {done.returncode}\n{done.stderr[-3000:]}'
        assert f'ok {step}' in done.stdout
    unsafe = _unsafe_entries(str(cache))
    assert not unsafe, unsafe


# ------------------------------------------- no writable cache location
def _can_make_read_only_mounts() -> bool:
    if shutil.which('unshare') is None or shutil.which('mount') is None:
        return False
    try:
        done = subprocess.run(['unshare', '-m', 'true'], capture_output=True,
                              timeout=30)
    except (OSError, subprocess.SubprocessError):
        return False
    return done.returncode == 0


# Root (a container, CI) writes through any chmod, so there a read-only bind
# mount in a private mount namespace makes the folders read-only for the
# command only, as they are for a user of a shared install; the probe makes
# sure they are.
READ_ONLY = r'''
set -e
for folder in "$1" "$2"; do
    mount --bind "$folder" "$folder"
    mount -o remount,bind,ro "$folder"
done
if touch "$1/tg_intrinsic/.probe" 2>/dev/null || \
        touch "$2/.probe" 2>/dev/null; then
    echo "the read-only folders are still writable" >&2
    exit 97
fi
shift 2
exec "$@"
'''


@pytest.fixture
def read_only_install(tmp_path):
    """A copy of the package and a home folder, neither writable, and a
    runner of commands that see them so: ``run(args) -> CompletedProcess``
    with NUMBA_CACHE_DIR and XDG_CACHE_HOME unset."""
    install = tmp_path / 'install'
    shutil.copytree(PACKAGE, install / 'tg_intrinsic',
                    ignore=shutil.ignore_patterns('__pycache__', '*.pyc'))
    home = tmp_path / 'home'
    home.mkdir()
    work = tmp_path / 'work'
    work.mkdir()
    env = {key: value for key, value in os.environ.items()
           if key not in ('NUMBA_CACHE_DIR', 'XDG_CACHE_HOME', 'PYTHONPATH')}
    # matplotlib's own notice about an unwritable home is not this test's
    # concern: it gets a writable config folder
    env.update(HOME=str(home), PYTHONPATH=str(install),
               MPLCONFIGDIR=str(tmp_path / 'matplotlib'))
    root = os.geteuid() == 0 if hasattr(os, 'geteuid') else False
    if root and not _can_make_read_only_mounts():
        pytest.skip('running as root without mount namespaces: no folder '
                    'can be made unwritable')
    if not root:
        for folder, dirs, files in os.walk(install):
            for file in files:
                os.chmod(os.path.join(folder, file), 0o444)
        for folder in [home] + [p for p, _, _ in os.walk(install)]:
            os.chmod(folder, 0o555)
        assert not os.access(install / 'tg_intrinsic', os.W_OK)

    def run(args, timeout=300):
        command = [sys.executable] + args
        if root:
            command = ['unshare', '-m', 'sh', '-c', READ_ONLY, 'sh',
                       str(install), str(home)] + command
        return subprocess.run(command, env=env, cwd=str(work),
                              capture_output=True, text=True,
                              timeout=timeout)

    yield run
    if not root:
        for folder in [home] + [p for p, _, _ in os.walk(install)]:
            os.chmod(folder, 0o755)


def _check_one_warning(done):
    output = done.stdout + done.stderr
    assert done.returncode == 0, output[-3000:]
    assert 'Traceback' not in output and 'no locator' not in output, \
        output[-3000:]
    lines = [line for line in output.splitlines() if WARNING in line]
    assert len(lines) == 1, output[-3000:]
    assert 'NUMBA_CACHE_DIR' in lines[0] and 'writable' in lines[0]
    assert '@jit' not in output   # one line, no source line below it


def test_info_and_solve_run_without_a_writable_cache(read_only_install,
                                                     tmp_path):
    _check_one_warning(read_only_install(['-m', 'tg_intrinsic', 'info']))

    import trimesh
    mesh = str(tmp_path / 'sphere.obj')
    trimesh.creation.icosphere(2).export(mesh)
    out = tmp_path / 'out'
    # a hierarchy (numba kernels of Gravo MG), not one direct solve
    done = read_only_install(['-m', 'tg_intrinsic', '--quiet', 'solve', mesh,
                              '--smooth', '1e-2', '--ratio', '4',
                              '--lower-bound', '10', '--out', str(out)])
    _check_one_warning(done)
    assert (out / 'report.json').is_file()
