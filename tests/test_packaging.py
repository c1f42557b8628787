"""The package as users get it: ``python -m build`` makes an sdist and a
wheel that ``twine check`` accepts; the wheel holds every module of the
source tree and, installed into a fresh virtual environment (not editable,
not from the source tree), runs the command line and imports every
package from a folder outside the repository. The fresh environment takes
the dependencies from the test's own environment (a path entry, whose own
``.pth`` files, this checkout's editable install among them, are not
run), so nothing is downloaded."""
import glob
import os
import subprocess
import sys
import sysconfig
import zipfile

import pytest

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
PACKAGES = ('tg_intrinsic', 'tg_intrinsic.geometry', 'tg_intrinsic.transforms',
            'tg_intrinsic.nn', 'tg_intrinsic.nn.models', 'tg_intrinsic.pool',
            'tg_intrinsic.solvers', 'tg_intrinsic.datasets', 'tg_intrinsic.io',
            'tg_intrinsic.train', 'tg_intrinsic.protocols',
            'tg_intrinsic.cli')


def run(command, **kwargs):
    result = subprocess.run(command, capture_output=True, text=True,
                            **kwargs)
    assert result.returncode == 0, (
        f"{' '.join(map(str, command))} exited {result.returncode}:\n"
        f"{result.stdout[-3000:]}\n{result.stderr[-3000:]}")
    return result


@pytest.fixture(scope='module')
def dist(tmp_path_factory):
    pytest.importorskip('build')
    out = tmp_path_factory.mktemp('dist')
    # --no-isolation: the build backend of this environment, no download
    run([sys.executable, '-m', 'build', '--no-isolation', '--outdir',
         str(out), ROOT], cwd=ROOT)
    return out


def test_sdist_and_wheel_pass_twine_check(dist):
    pytest.importorskip('twine')
    sdist = glob.glob(str(dist / 'tg_intrinsic-*.tar.gz'))
    wheel = glob.glob(str(dist / 'tg_intrinsic-*-py3-none-any.whl'))
    assert len(sdist) == 1 and len(wheel) == 1
    run([sys.executable, '-m', 'twine', 'check', '--strict', *sdist, *wheel])


def test_the_wheel_holds_every_module_and_the_version(dist):
    import tg_intrinsic
    wheel, = glob.glob(str(dist / 'tg_intrinsic-*.whl'))
    assert os.path.basename(wheel).startswith(
        f'tg_intrinsic-{tg_intrinsic.__version__}-')
    names = set(zipfile.ZipFile(wheel).namelist())
    source = {os.path.relpath(path, ROOT).replace(os.sep, '/') for path in
              glob.glob(os.path.join(ROOT, 'tg_intrinsic', '**', '*'),
                        recursive=True)
              if os.path.isfile(path) and '__pycache__' not in path}
    assert source - names == set()
    entry_points = [n for n in names if n.endswith('entry_points.txt')]
    text = zipfile.ZipFile(wheel).read(entry_points[0]).decode()
    assert 'tg-intrinsic = tg_intrinsic.cli:entry_point' in text


def test_the_wheel_works_outside_the_repository(dist, tmp_path):
    import tg_intrinsic
    wheel, = glob.glob(str(dist / 'tg_intrinsic-*.whl'))
    venv = tmp_path / 'venv'
    run([sys.executable, '-m', 'venv', str(venv)])
    python = venv / 'bin' / 'python'
    site = run([str(python), '-c', 'import sysconfig; print(sysconfig.'
                'get_paths()["purelib"])']).stdout.strip()
    # the dependencies: this environment's packages, appended to the path
    with open(os.path.join(site, 'dependencies.pth'), 'w') as f:
        f.write(sysconfig.get_paths()['purelib'] + '\n')
    run([str(python), '-m', 'pip', 'install', '--no-index', '--no-deps',
         '--no-cache-dir', '-q', wheel])
    outside = tmp_path / 'elsewhere'
    outside.mkdir()
    env = {k: v for k, v in os.environ.items() if k != 'PYTHONPATH'}
    env.update(OMP_NUM_THREADS='1', NUMBA_NUM_THREADS='1')
    # every package imports, from the installed files
    where = run([str(python), '-c', '; '.join(
        [f'import {p}' for p in PACKAGES]
        + ['print(tg_intrinsic.__file__, tg_intrinsic.__version__)'])],
        cwd=outside, env=env).stdout.split()
    assert where[0].startswith(site) and where[1] == tg_intrinsic.__version__
    command = str(venv / 'bin' / 'tg-intrinsic')
    version = run([command, '--version'], cwd=outside, env=env).stdout
    assert version.strip() == f'tg-intrinsic {tg_intrinsic.__version__}'
    info = run([command, 'info'], cwd=outside, env=env).stdout
    assert tg_intrinsic.__version__ in info
    # one part of the demo, its numba kernels compiled from the installed
    # files (the SVBRDF part adds 50 s of compiling and no file the wheel
    # test above does not already find in the wheel)
    run([command, 'demo', '--quick', '--only', 'gravo', '--out',
         str(outside / 'demo')],
        cwd=outside, env=env)
    assert (outside / 'demo' / 'summary.json').is_file()


def test_the_python_versions_follow_the_pinned_torch():
    """setup.py's python_requires is the Requires-Python of the torch the
    Makefile pins (a lower one promised 3.9, where installing torch 2.13
    fails), read from the installed torch's metadata."""
    import importlib.metadata
    import re
    torch_requires = importlib.metadata.metadata('torch')['Requires-Python']
    setup = open(os.path.join(ROOT, 'setup.py')).read()
    ours = re.search(r"python_requires='([^']+)'", setup).group(1)
    assert ours == torch_requires, (ours, torch_requires)
    makefile = open(os.path.join(ROOT, 'Makefile')).read()
    pinned = re.search(r"torch==([0-9.]+)", makefile)
    assert pinned and importlib.metadata.version('torch').startswith(
        pinned.group(1))


def install_torch(index: str) -> str:
    """``make install-torch`` into this test's own environment (where torch
    2.13.0 is installed, so pip finds it satisfied and downloads nothing)
    with ``index`` as PyTorch's CPU index; the commands and their output."""
    activate = os.path.join(sys.prefix, 'bin', 'activate')
    if sys.prefix == sys.base_prefix or not os.path.isfile(activate):
        pytest.skip('the tests run outside a virtual environment')
    result = run(['make', '-s', '-C', ROOT, 'install-torch',
                  f'VENV={sys.prefix}',
                  f'TORCH_CPU_INDEX={index}'])
    return result.stdout + result.stderr


def test_torch_comes_from_the_cpu_index_where_it_answers(tmp_path):
    import functools
    import http.server
    import threading
    (tmp_path / 'torch').mkdir()
    (tmp_path / 'torch' / 'index.html').write_text('<html></html>')
    handler = functools.partial(http.server.SimpleHTTPRequestHandler,
                                directory=str(tmp_path))
    handler.log_message = lambda *args: None
    server = http.server.ThreadingHTTPServer(('127.0.0.1', 0), handler)
    threading.Thread(target=server.serve_forever, daemon=True).start()
    try:
        index = f'http://127.0.0.1:{server.server_address[1]}'
        output = install_torch(index)
    finally:
        server.shutdown()
    assert 'cannot be reached' not in output
    assert f'Looking in indexes: {index},' in output


def test_an_unreachable_cpu_index_falls_back_with_a_note():
    import socket
    with socket.socket() as probe:  # a port nothing listens on
        probe.bind(('127.0.0.1', 0))
        port = probe.getsockname()[1]
    output = install_torch(f'http://127.0.0.1:{port}')
    assert (f'note: http://127.0.0.1:{port} cannot be reached; installing '
            f'torch==2.13.0 from pip\'s default index') in output
    assert f'Looking in indexes: http://127.0.0.1:{port}' not in output
    assert 'Requirement already satisfied: torch==2.13.0' in output


def test_the_readme_names_what_make_install_installs():
    """README's install section lists the pinned torch's own requirements
    (those of the CPU build it installs) and every requirement (runtime
    and test extra) of setup.py."""
    import importlib.metadata
    import re
    readme = open(os.path.join(ROOT, 'README.md'), encoding='utf-8').read()
    section = readme[readme.index('<!-- section: install -->'):
                     readme.index('<!-- end: install -->')]
    section = ' '.join(section.split()).lower()
    import runpy
    setup = open(os.path.join(ROOT, 'setup.py')).read()
    runtime = re.findall(r"^    '([A-Za-z][\w.-]*)", setup[
        setup.index('install_requires = ['):setup.index('extras_require')],
        flags=re.M)
    extras = runpy.run_path(os.path.join(ROOT, 'tg_intrinsic', 'extras.py'))
    named = runtime + extras['EXTRAS']['test'][0]
    # the CPU build's own requirements (a CUDA build adds its toolkit)
    import torch
    torch_own = [] if torch.version.cuda else [
        r.split(';')[0] for r in importlib.metadata.requires('torch')
        if 'extra ==' not in r]
    for requirement in named + torch_own:
        name = re.split(r'[<>=!; ]', requirement)[0].lower()
        if name == 'torch':
            continue
        assert name in section, f'README does not say that {name} is installed'
