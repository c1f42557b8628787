"""Every command that writes a folder leaves it, and everything in it, as
any other tool would under the user's umask (0755 folders and 0644 files
under umask 022): results a user shares with a group, or serves, stay
readable. (Temporary folders, which tempfile makes private, must not
leak their 0700 into the results.)"""
import os
import stat

import pytest
import trimesh

from tests.cli import run_cli

TINY_EXAMPLE = ['--example-views', '6', '--example-image-size', '24',
                '--example-subdivisions', '1']


@pytest.fixture
def umask_022():
    previous = os.umask(0o022)
    try:
        yield
    finally:
        os.umask(previous)


def modes_under(folder):
    """The permission bits of ``folder`` and of everything under it,
    by path relative to it."""
    modes = {'.': stat.S_IMODE(os.stat(folder).st_mode)}
    for root, folders, files in os.walk(folder):
        for name in folders + files:
            path = os.path.join(root, name)
            modes[os.path.relpath(path, folder)] = stat.S_IMODE(
                os.lstat(path).st_mode)
    return modes


def assert_shareable(folder, *expected):
    modes = modes_under(folder)
    for name in expected:  # the command wrote what it should
        assert name in modes, (name, sorted(modes))
    for name, mode in modes.items():
        wanted = 0o755 if os.path.isdir(os.path.join(folder, name)) \
            else 0o644
        assert mode == wanted, f'{name}: {oct(mode)}, not {oct(wanted)}'


def a_mesh(tmp_path):
    path = tmp_path / 'sphere.obj'
    trimesh.creation.icosphere(2).export(str(path))
    return path


def test_solve(capsys, tmp_path, umask_022):
    out = tmp_path / 'solved'
    code, _, err = run_cli(capsys, '--quiet', 'solve', a_mesh(tmp_path),
                           '--smooth', '1e-2', '--ratio', '4', '--lower-bound',
                           '10', '--out', out)
    assert code == 0, err
    assert_shareable(out, 'result.ply', 'report.json')


def test_precompute(capsys, tmp_path, umask_022):
    inputs = tmp_path / 'meshes'
    (inputs / 'sub').mkdir(parents=True)
    trimesh.creation.icosphere(1).export(str(inputs / 'sub' / 'a.obj'))
    out = tmp_path / 'operators'
    code, _, err = run_cli(capsys, '--quiet', 'precompute', 'mls', inputs,
                           out, '--k', '8')
    assert code == 0, err
    assert_shareable(out, 'sub', os.path.join('sub', 'a.pt'),
                     'precompute.json')


def test_svbrdf_example_and_recovery(capsys, tmp_path, umask_022):
    example = tmp_path / 'capture'
    code, _, err = run_cli(capsys, 'svbrdf', '--write-example', example,
                           '--format', 'colmap', *TINY_EXAMPLE)
    assert code == 0, err
    assert_shareable(example, 'images', os.path.join('sparse', '0'))
    out = tmp_path / 'maps'
    code, _, err = run_cli(capsys, 'svbrdf', example, '--out', out,
                           '--refine', '0', '--quiet')
    assert code == 0, err
    assert_shareable(out, 'maps.npz', 'report.json', 'cameras.png')


def test_train(capsys, tmp_path, umask_022):
    out = tmp_path / 'run'
    code, _, err = run_cli(
        capsys, 'train', 'deltanet', '--dataset', 'synthetic-modelnet',
        '--root', tmp_path / 'data', '--out', out, '--num-points', '64',
        '--shapes-per-class', '2', '--batch-size', '8', '--conv-channels',
        '8', '--k', '6', '--epochs', '1', '--quiet')
    assert code == 0, err
    assert_shareable(out, 'metrics.csv', 'checkpoint.pt')
    assert_shareable(tmp_path / 'data')  # the data set's cache too


def test_demo(capsys, tmp_path, umask_022):
    out = tmp_path / 'demo'
    code, _, err = run_cli(capsys, 'demo', '--quick', '--quiet', '--only',
                           'gravo', '--out', out, '--root', tmp_path / 'data')
    assert code == 0, err
    assert_shareable(out, 'summary.json', 'summary.md')
