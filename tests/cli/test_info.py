"""tg-intrinsic info: the versions, the device and the optional extras,
as a table and as JSON."""
import importlib
import json
import types

import pytest

from tg_intrinsic.cli import info

from tests.cli import run_cli


def test_info(capsys):
    code, out, _ = run_cli(capsys, 'info')
    assert code == 0
    for name in ('torch', 'torch_geometric', 'tg_intrinsic', 'device',
                 'potpourri3d', 'OpenEXR', 'mitsuba', 'torch_scatter'):
        assert name in out
    code, out, _ = run_cli(capsys, 'info', '--json')
    info = json.loads(out)
    assert code == 0 and set(info['extras']) == {
        'potpourri3d', 'OpenEXR', 'mitsuba', 'torch_scatter'}


def fake_importlib(modules):
    """``importlib`` whose import_module returns ``modules[name]``, or
    raises it when it is an exception."""
    real = importlib.import_module

    def import_module(name):
        if name not in modules:
            return real(name)
        if isinstance(modules[name], BaseException):
            raise modules[name]
        return modules[name]
    return types.SimpleNamespace(import_module=import_module)


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
    for name, adds, how in info.EXTRAS:
        extra = report['extras'][name]
        assert (extra['adds'], extra['install']) == (adds, how)
        try:
            module = importlib.import_module(name)
        except Exception:  # noqa: BLE001 - absent or broken
            assert extra['version'] is None
        else:
            assert extra['version'] == str(getattr(module, '__version__',
                                                   'installed'))


def test_missing_broken_and_installed_extras(capsys, monkeypatch):
    monkeypatch.setattr(info, 'importlib', fake_importlib({
        'potpourri3d': ImportError('No module named potpourri3d'),
        'OpenEXR': RuntimeError('broken build'),  # broken counts as missing
        'mitsuba': types.SimpleNamespace(__version__='3.9.1'),
        'torch_scatter': types.SimpleNamespace(),  # no __version__
    }))
    report = info.collect()
    assert [report['extras'][n]['version'] for n, _, _ in info.EXTRAS] == \
        [None, None, '3.9.1', 'installed']
    code, out, _ = run_cli(capsys, 'info')
    assert code == 0
    lines = out.splitlines()
    start = lines.index('optional extras:')
    extras = {line.split()[0]: line for line in lines[start + 1:]}
    assert set(extras) == {name for name, _, _ in info.EXTRAS}
    assert "missing (pip install tg_intrinsic[heat]): log maps with " \
        "method='vector_heat'" in extras['potpourri3d']
    assert 'missing (pip install tg_intrinsic[exr])' in extras['OpenEXR']
    assert ' 3.9.1: the external renderer' in extras['mitsuba']
    assert ' installed: compiled scatter kernels' in extras['torch_scatter']


def test_the_table_is_aligned_and_says_when_there_is_no_gpu(capsys,
                                                           monkeypatch):
    import torch
    monkeypatch.setattr(torch.cuda, 'is_available', lambda: False)
    code, out, _ = run_cli(capsys, 'info')
    assert code == 0
    table = out.split('optional extras:')[0].splitlines()
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
