"""tg-intrinsic info: the versions, the device and the optional extras,
as a table and as JSON."""
import importlib.metadata
import json

import pytest

from tg_intrinsic.cli import info
from tg_intrinsic.extras import EXTRAS

from tests.cli import run_cli


def test_info(capsys):
    code, out, _ = run_cli(capsys, 'info')
    assert code == 0
    for name in ('torch', 'torch_geometric', 'tg_intrinsic', 'device',
                 *EXTRAS):
        assert name in out
    code, out, _ = run_cli(capsys, 'info', '--json')
    report = json.loads(out)
    assert code == 0 and set(report['extras']) == set(EXTRAS)


def test_the_versions_are_the_installed_ones():
    import numpy
    import torch
    import torch_geometric
    import trimesh
    import tg_intrinsic
    report = info.collect()
    assert report['tg_intrinsic'] == tg_intrinsic.__version__
    assert report['torch'] == torch.__version__
    assert report['torch_geometric'] == torch_geometric.__version__
    assert report['numpy'] == numpy.__version__
    assert report['trimesh'] == trimesh.__version__
    assert report['cuda_version'] == torch.version.cuda
    assert report['device'] == ('cuda' if torch.cuda.is_available()
                                else 'cpu')
    for name, (requirements, needed_by) in EXTRAS.items():
        extra = report['extras'][name]
        assert extra['needed_by'] == needed_by
        assert extra['install'] == f'pip install "tg_intrinsic[{name}]"'
        for requirement in requirements:
            distribution = info._distribution(requirement)
            try:
                version = importlib.metadata.version(distribution)
            except importlib.metadata.PackageNotFoundError:
                version = None
            assert extra['installed'][distribution] == version


def test_missing_and_installed_extras(capsys, monkeypatch):
    # docs: every requirement installed but furo, whatever this machine has
    versions = {info._distribution(r): '1.0' for r in EXTRAS['docs'][0]}
    versions.update({'potpourri3d': None, 'OpenEXR': '3.9.1', 'furo': None})
    real = info._installed
    monkeypatch.setattr(info, '_installed', lambda name: versions[name]
                        if name in versions else real(name))
    code, out, _ = run_cli(capsys, 'info')
    assert code == 0
    lines = out.splitlines()
    start = lines.index('optional extras (pip install "tg_intrinsic[NAME]"):')
    extras = {line.split()[0]: line for line in lines[start + 1:]}
    assert list(extras) == list(EXTRAS)
    assert "missing potpourri3d: log maps with method='vector_heat'" in \
        extras['heat']
    assert 'installed (OpenEXR 3.9.1): reading and writing .exr' in \
        extras['exr']
    assert 'missing furo: the documentation site' in extras['docs']


def test_the_table_is_aligned_and_says_when_there_is_no_gpu(capsys,
                                                           monkeypatch):
    import torch
    monkeypatch.setattr(torch.cuda, 'is_available', lambda: False)
    code, out, _ = run_cli(capsys, 'info')
    assert code == 0
    table = out.split('optional extras')[0].splitlines()
    names = [line.split('  ')[0].rstrip() for line in table]
    assert names[:4] == ['tg_intrinsic', 'python', 'torch', 'torch_geometric']
    assert names[-1] == 'device'
    assert table[-1].split(None, 1)[1] == 'cpu (no CUDA device)'
    # the values start in one column, two spaces after the longest name
    column = max(len(name) for name in names) + 2
    for line in table:
        assert line[column - 2:column] == '  ' and line[column] != ' ', line
    code, out, _ = run_cli(capsys, 'info', '--json')
    report = json.loads(out)
    assert report['device'] == 'cpu' and report['cuda'] is None


@pytest.mark.parametrize('argv,needle', [
    (['info', '--yaml'], 'unrecognized arguments: --yaml'),
    (['info', 'extra'], 'unrecognized arguments: extra'),
])
def test_a_mistake_is_one_line_and_exit_code_2(capsys, argv, needle):
    code, out, err = run_cli(capsys, *argv)
    assert code == 2 and out == ''
    assert 'Traceback' not in err and len(err.strip().splitlines()) == 1
    assert needle in err and err.startswith('tg-intrinsic')
