"""tg-intrinsic solve: outputs against the library called directly and a
direct scipy solve, fairing, bi-Laplacian, the conformal flow, point
clouds, and every bad input ending in one line with exit code 2."""
import errno
import json
import os
import subprocess
import sys

import numpy as np
import pytest
import scipy.sparse as sp
import torch
import trimesh
from scipy.sparse.linalg import spsolve
from torch_geometric.data import Data

from tg_intrinsic.io import read_surface, write_ply
from tg_intrinsic.solvers import (conformal_flow, poisson, smooth,
                                  stiffness_and_mass)

from tests.cli import assert_user_error, run_cli

# 162 vertices: ratio 4 and lower bound 10 give levels 162 -> 42 -> 10
HIERARCHY = ['--ratio', '4', '--lower-bound', '10']


def cli(argv, capsys):
    """Runs the command line: (exit code, stdout, stderr)."""
    return run_cli(capsys, *argv)


@pytest.fixture(scope='module')
def files(tmp_path_factory):
    root = tmp_path_factory.mktemp('solve')
    mesh = trimesh.creation.icosphere(2)
    rng = np.random.default_rng(0)
    signal = rng.normal(size=(162, 2))
    heat = rng.normal(size=162)
    paths = {'obj': str(root / 'sphere.obj'), 'npy': str(root / 'y.npy'),
             'ply': str(root / 'sphere.ply'),
             'cloud': str(root / 'cloud.ply'),
             'short': str(root / 'short.npy')}
    mesh.export(paths['obj'])
    pos, face, _ = read_surface(paths['obj'])  # as the OBJ stores them
    np.save(paths['npy'], signal)
    np.save(paths['short'], signal[:10])
    write_ply(paths['ply'], pos, face, properties={'heat': heat})
    cloud = rng.normal(size=(200, 3))
    cloud /= np.linalg.norm(cloud, axis=1, keepdims=True)
    write_ply(paths['cloud'], cloud, properties={'quality': cloud[:, 2]})
    bad = {'garbage.off': 'this is not a mesh\n',
           'nan.off': 'OFF\n3 1 0\n0 0 0\nnan 0 0\n0 1 0\n3 0 1 2\n',
           'past.off': 'OFF\n3 1 0\n0 0 0\n1 0 0\n0 1 0\n3 0 1 5\n'}
    for name, text in bad.items():
        (root / name).write_text(text)
        paths[name] = str(root / name)
    return paths, pos, face, signal, heat


def mesh_data(pos, face):
    return Data(pos=torch.from_numpy(pos),
                face=torch.from_numpy(face).t().contiguous())


def test_smooth_signal_outputs_and_report(files, tmp_path, capsys):
    paths, pos, face, signal, _ = files
    out = str(tmp_path / 'out')
    code, stdout, stderr = cli(['solve', paths['obj'], '--smooth', '1e-2',
                                '--signal', paths['npy'], '--out', out]
                               + HIERARCHY, capsys)
    assert code == 0, stderr
    assert 'building the hierarchy' in stderr and 'solving' in stderr
    assert 'solved (M + alpha S) x = M y' in stdout and 'cotan' in stdout
    for name in ('result.ply', 'result.png', 'report.json'):
        assert os.path.getsize(os.path.join(out, name)) > 0
    # The PLY round-trips with the input signal and the result.
    ply_pos, ply_face, props = read_surface(os.path.join(out, 'result.ply'))
    assert np.array_equal(ply_pos, pos) and np.array_equal(ply_face, face)
    result = np.stack([props['result_0'], props['result_1']], 1)
    assert np.array_equal(np.stack([props['signal_0'], props['signal_1']],
                                   1), signal)
    # ... equal to the library called directly
    direct = smooth(mesh_data(pos, face), 1e-2, y=torch.from_numpy(signal),
                    ratio=4.0, lower_bound=10).numpy()
    assert np.abs(result - direct).max() < 1e-12
    with open(os.path.join(out, 'report.json')) as f:
        report = json.load(f)
    assert report['input'] == os.path.abspath(paths['obj'])
    assert (report['vertices'], report['faces']) == (162, 320)
    assert report['laplacian'] == 'cotan' and report['problem'] == 'smooth'
    assert report['parameters'] == {'alpha': 1e-2}
    assert report['channels'] == 2
    assert report['hierarchy']['level_sizes'] == [162, 42, 10]
    solver = report['solver']
    assert solver['converged'] and solver['direct'] is None
    assert solver['cycles'] == len(solver['residuals']) >= 2
    assert solver['final_relative_residual'] == solver['residuals'][-1] \
        < 1e-8
    assert {'hierarchy', 'setup', 'solve', 'total'} <= set(report['seconds'])


def test_fairing_is_the_default_for_smooth(files, tmp_path, capsys):
    paths, pos, face, _, _ = files
    out = str(tmp_path / 'fair')
    code, stdout, stderr = cli(['--quiet', 'solve', paths['obj'], '--smooth',
                                '1e-2', '--out', out], capsys)
    assert code == 0, stderr
    assert stdout == '' and stderr == ''  # --quiet
    faired, ply_face, props = read_surface(os.path.join(out, 'result.ply'))
    direct = smooth(mesh_data(pos, face), 1e-2,
                    y=torch.from_numpy(pos)).numpy()
    assert np.abs(faired - direct).max() < 1e-12  # smoothed positions
    assert np.array_equal(ply_face, face)
    assert np.array_equal(np.stack([props[f'signal_{k}'] for k in range(3)],
                                   1), pos)
    assert np.linalg.norm(faired, axis=1).mean() < 1  # it shrinks
    with open(os.path.join(out, 'report.json')) as f:
        report = json.load(f)
    assert report['problem'] == 'fairing'
    assert report['signal'] == 'vertex positions'
    # 162 points are below the default lower bound: one direct solve
    assert report['hierarchy']['level_sizes'] == [162]
    assert report['solver']['direct'] and report['solver']['converged']


def test_bilaplacian_matches_a_direct_solve(files, tmp_path, capsys):
    paths, pos, face, signal, _ = files
    out = str(tmp_path / 'bi')
    code, _, stderr = cli(['--quiet', 'solve', paths['obj'], '--smooth',
                           '1e-2', '--bilaplacian', '1e-3', '--signal',
                           paths['npy'], '--out', out, '--cycle', 'W']
                          + HIERARCHY, capsys)
    assert code == 0, stderr
    _, _, props = read_surface(os.path.join(out, 'result.ply'))
    result = np.stack([props['result_0'], props['result_1']], 1)
    S, m = stiffness_and_mass(mesh_data(pos, face))
    A = (sp.diags(m) + 1e-2 * S + 1e-3 * S @ sp.diags(1 / m) @ S).tocsc()
    exact = np.stack([spsolve(A, m * c) for c in signal.T], 1)
    assert np.abs(result - exact).max() < 1e-6 * np.abs(exact).max()
    with open(os.path.join(out, 'report.json')) as f:
        report = json.load(f)
    assert report['problem'] == 'bilaplacian smooth'
    assert report['parameters'] == {'alpha': 1e-2, 'beta': 1e-3}
    assert report['solver']['cycle'] == 'W'


def test_conformal_flow_is_the_library_flow(files, tmp_path, capsys):
    paths, pos, face, _, _ = files
    out = str(tmp_path / 'flow')
    code, stdout, stderr = cli(['solve', paths['obj'], '--conformal-flow',
                                '0.05', '--steps', '3', '--out', out]
                               + HIERARCHY, capsys)
    assert code == 0, stderr
    flowed, _, props = read_surface(os.path.join(out, 'result.ply'))
    expected = conformal_flow(mesh_data(pos, face), 0.05, 3, ratio=4,
                              lower_bound=10)[-1].numpy()
    assert np.abs(flowed - expected).max() < 1e-6
    assert np.array_equal(np.stack([props[f'signal_{k}'] for k in range(3)],
                                   1), pos)
    with open(os.path.join(out, 'report.json')) as f:
        report = json.load(f)
    assert report['problem'] == 'conformal flow'
    assert report['parameters'] == {'step': 0.05, 'steps': 3}
    solver = report['solver']
    assert solver['method'] == 'pcg' and solver['converged']
    assert solver['cycles'] == len(solver['residuals']) >= 3
    assert 'PCG iterations (one V-cycle each) over 3 steps' in stdout


@pytest.mark.parametrize('source', ['heat', 'PLY:heat'])
def test_poisson_solution_satisfies_the_system(files, tmp_path, capsys,
                                               source):
    paths, pos, face, _, heat = files
    source = source.replace('PLY', paths['ply'])
    out = str(tmp_path / 'poisson')
    code, _, stderr = cli(['--quiet', 'solve', paths['ply'], '--poisson',
                           '2.5', '--signal', source, '--out', out,
                           '--tol', '1e-9', '--cycle', 'F'] + HIERARCHY,
                          capsys)
    assert code == 0, stderr
    _, _, props = read_surface(os.path.join(out, 'result.ply'))
    x = props['result']
    assert np.array_equal(props['signal'], heat)
    S, m = stiffness_and_mass(mesh_data(pos, face))
    rhs = m * heat
    assert np.linalg.norm(rhs - (S + 2.5 * sp.diags(m)) @ x) <= \
        1e-9 * np.linalg.norm(rhs)
    direct = poisson(mesh_data(pos, face), 2.5, y=torch.from_numpy(heat),
                     tol=1e-9, ratio=4.0, lower_bound=10, cycle='F')
    assert np.abs(x - direct.numpy()).max() < 1e-12


def test_point_cloud_uses_the_robust_laplacian(files, tmp_path, capsys):
    paths = files[0]
    out = str(tmp_path / 'cloud')
    code, stdout, stderr = cli(['solve', paths['cloud'], '--smooth', '1e-2',
                                '--signal', 'quality', '--out', out,
                                '--lower-bound', '20', '--ratio', '4'],
                               capsys)
    assert code == 0, stderr
    assert 'point cloud' in stdout and 'robust' in stdout
    cloud, face, props = read_surface(os.path.join(out, 'result.ply'))
    assert face is None and cloud.shape == (200, 3)
    with open(os.path.join(out, 'report.json')) as f:
        report = json.load(f)
    assert report['faces'] == 'point cloud'
    assert report['laplacian'].startswith('robust')
    assert report['hierarchy']['graph'].startswith('k-nearest')
    assert len(report['hierarchy']['level_sizes']) >= 2
    assert report['solver']['converged']
    direct = smooth(Data(pos=torch.from_numpy(cloud)), 1e-2,
                    y=torch.from_numpy(props['signal'].copy()), ratio=4.0,
                    lower_bound=20)
    assert np.abs(props['result'] - direct.numpy()).max() < 1e-12


def test_one_column_signal_is_one_property(files, tmp_path, capsys):
    paths, _, _, signal, _ = files
    column = str(tmp_path / 'column.npy')
    np.save(column, signal[:, :1])  # (N, 1)
    out = str(tmp_path / 'column')
    code, _, stderr = cli(['--quiet', 'solve', paths['obj'], '--poisson',
                           '1', '--signal', column, '--out', out], capsys)
    assert code == 0, stderr
    with open(os.path.join(out, 'report.json')) as f:
        report = json.load(f)
    assert report['channels'] == 1
    assert report['ply_properties'] == ['signal', 'result']
    _, _, props = read_surface(os.path.join(out, 'result.ply'))
    assert {'signal', 'result'} <= set(props)


def test_a_solve_that_does_not_converge_warns(files, tmp_path, capsys):
    paths = files[0]
    out = str(tmp_path / 'short')
    code, stdout, stderr = cli(['solve', paths['obj'], '--smooth', '1e-2',
                                '--signal', paths['npy'], '--out', out,
                                '--max-cycles', '1'] + HIERARCHY, capsys)
    assert code == 0, stderr
    # in the options the user can change, not the library's arguments
    # (max_iter, method='pcg'; issue 40)
    warning = [line for line in stderr.splitlines() if 'warning' in line]
    assert len(warning) == 1, stderr
    assert warning[0].startswith(
        'tg-intrinsic: warning: the solve did not converge: stopped at '
        '--max-cycles 1 cycles with relative residual '), stderr
    assert warning[0].endswith(
        'above --tol 1e-08; raise --max-cycles, or use --method pcg'), stderr
    assert 'max_iter' not in stderr and 'method=' not in stderr
    assert 'NOT converged' in stdout
    with open(os.path.join(out, 'report.json')) as f:
        solver = json.load(f)['solver']
    assert not solver['converged'] and solver['cycles'] == 1
    assert solver['final_relative_residual'] > 1e-8


@pytest.mark.parametrize('argv, message', [
    (['MISSING', '--smooth', '1'], 'does not exist'),
    (['garbage.off', '--smooth', '1'], 'could not read'),
    (['nan.off', '--smooth', '1'], 'NaN'),
    (['past.off', '--smooth', '1'], 'face indices outside'),
    (['obj', '--smooth', '-1'], 'argument --smooth: must be greater than 0'),
    (['obj', '--smooth', '0'], 'argument --smooth: must be greater than 0'),
    (['obj', '--poisson', '0', '--signal', 'npy'],
     'argument --poisson: must be greater than 0'),
    (['obj', '--smooth', 'nan'], 'must be finite'),
    (['obj', '--smooth', '1', '--signal', 'short'], '162 vertices'),
    (['obj', '--poisson', '1'], '--poisson needs a right-hand side'),
    (['obj', '--poisson', '1', '--signal', 'npy', '--bilaplacian', '1'],
     '--bilaplacian adds to --smooth'),
    (['obj', '--smooth', '1', '--signal', 'no_such_property'],
     'neither'),
    (['obj', '--smooth', '1', '--ratio', '0.5'], '--ratio must be greater'),
    (['obj'], 'one of the arguments --smooth --poisson --conformal-flow '
     'is required'),
    (['cloud', '--conformal-flow', '0.1'], 'needs a triangle mesh'),
    (['obj', '--conformal-flow', '0.1', '--signal', 'npy'],
     'leave out --signal'),
    (['obj', '--smooth', '1', '--method', 'gmres'],
     "argument --method: invalid choice"),
])
def test_bad_input_is_one_line_and_exit_code_2(files, tmp_path, capsys,
                                               argv, message):
    paths = files[0]
    argv = [paths.get(a, a) if not a.startswith('-') else a for a in argv]
    argv = [str(tmp_path / 'missing.obj') if a == 'MISSING' else a
            for a in argv]
    code, stdout, stderr = cli(['--quiet', 'solve'] + argv
                               + ['--out', str(tmp_path / 'out')], capsys)
    assert code == 2
    assert 'Traceback' not in stderr and stdout == ''
    lines = stderr.strip().splitlines()
    assert len(lines) == 1, stderr
    assert lines[0].startswith('tg-intrinsic solve: error:')
    assert message in lines[0]


def test_bad_input_progress_lines_end_cleanly(files, tmp_path, capsys):
    # without --quiet the failed stage is closed before the error line
    code, _, stderr = cli(['solve', files[0]['nan.off'], '--smooth', '1',
                           '--out', str(tmp_path)], capsys)
    assert code == 2
    lines = stderr.strip().splitlines()
    assert lines[-2].endswith('failed')
    assert lines[-1].startswith('tg-intrinsic solve: error:')


def test_as_a_subprocess(files, tmp_path):
    # one run (starting Python with torch takes seconds); the exit codes of
    # bad input are those of main() above, which the entry point exits with
    paths = files[0]
    out = str(tmp_path / 'sub')
    done = subprocess.run(
        [sys.executable, '-m', 'tg_intrinsic', 'solve', paths['obj'],
         '--smooth', '1e-2', '--signal', paths['npy'], '--out', out]
        + HIERARCHY, capture_output=True, text=True, timeout=300,
        env=dict(os.environ, OMP_NUM_THREADS='1'))
    assert done.returncode == 0, done.stderr
    assert 'Traceback' not in done.stderr
    assert done.stdout.startswith('solved (M + alpha S) x = M y')
    # and the record of the files this run wrote
    assert sorted(os.listdir(out)) == ['.tg-intrinsic.json', 'report.json',
                                       'result.ply', 'result.png']


# ----------------------------------------------------------------------
# The files other tools write, and result folders that are never damaged

def _soup(tmp_path, pos, face, fmt):
    """The sphere as a triangle soup: every triangle with its own three
    vertices (STL always; many OBJ exporters)."""
    path = str(tmp_path / f'soup.{fmt}')
    soup = trimesh.Trimesh(pos[face].reshape(-1, 3),
                           np.arange(3 * len(face)).reshape(-1, 3),
                           process=False)
    soup.export(path)
    return path


@pytest.mark.parametrize('fmt', ['stl', 'obj'])
def test_a_triangle_soup_is_welded_into_one_surface(files, tmp_path, capsys,
                                                    fmt):
    paths, pos, face, _, _ = files
    soup = _soup(tmp_path, pos, face, fmt)
    out = str(tmp_path / 'out')
    code, _, stderr = cli(['solve', soup, '--smooth', '1e-2', '--out', out,
                           '--quiet'] + HIERARCHY, capsys)
    assert code == 0, stderr
    assert 'welded 798 vertices' in stderr and '960 -> 162' in stderr
    welded, welded_face, _ = read_surface(os.path.join(out, 'result.ply'))
    assert len(welded) == 162 and len(welded_face) == 320
    # the same fairing as of the connected mesh (a torn surface would not)
    code, _, _ = cli(['solve', paths['obj'], '--smooth', '1e-2', '--out',
                      str(tmp_path / 'mesh'), '--quiet'] + HIERARCHY, capsys)
    reference, _, _ = read_surface(str(tmp_path / 'mesh' / 'result.ply'))
    # (STL stores float32)
    assert np.abs(np.sort(welded, 0) - np.sort(reference, 0)).max() < 1e-6
    # read without welding, the file is the soup it is
    assert len(read_surface(soup, weld=False)[0]) == 960


def test_a_signal_per_stored_vertex_follows_the_weld(files, tmp_path,
                                                     capsys):
    paths, pos, face, signal, _ = files
    soup = _soup(tmp_path, pos, face, 'stl')
    stored = signal[face.reshape(-1)]  # one row per corner as stored
    np.save(tmp_path / 'stored.npy', stored)
    out = str(tmp_path / 'out')
    code, _, stderr = cli(['solve', soup, '--smooth', '1e-2', '--signal',
                           str(tmp_path / 'stored.npy'), '--out', out,
                           '--quiet'] + HIERARCHY, capsys)
    assert code == 0, stderr
    welded, _, props = read_surface(os.path.join(out, 'result.ply'))
    back = np.stack([props['signal_0'], props['signal_1']], 1)
    # (STL stores float32: the nearest input vertex)
    match = np.linalg.norm(welded[:, None] - pos[None], axis=2).argmin(1)
    assert np.array_equal(back, signal[match])
    # copies that disagree cannot be welded silently
    stored[1] += 1.0
    np.save(tmp_path / 'stored.npy', stored)
    code, _, stderr = cli(['solve', soup, '--smooth', '1e-2', '--signal',
                           str(tmp_path / 'stored.npy'), '--out', out,
                           '--quiet'], capsys)
    assert code == 2 and 'copies of welded vertices' in stderr


def test_ascii_ply_with_properties(files, tmp_path, capsys):
    paths, pos, face, _, heat = files
    mesh = trimesh.Trimesh(pos, face, process=False,
                           vertex_attributes={'heat': heat})
    ascii_ply = str(tmp_path / 'ascii.ply')
    with open(ascii_ply, 'wb') as f:
        f.write(trimesh.exchange.ply.export_ply(mesh, encoding='ascii'))
    assert b'format ascii' in open(ascii_ply, 'rb').read(100)
    out = str(tmp_path / 'out')
    code, _, stderr = cli(['solve', ascii_ply, '--poisson', '1', '--signal',
                           'heat', '--out', out, '--quiet'], capsys)
    assert code == 0, stderr
    _, _, props = read_surface(os.path.join(out, 'result.ply'))
    assert np.allclose(props['signal'], heat, atol=1e-6)  # float32 text
    # a NaN in an ASCII PLY is named
    text = open(ascii_ply).read().split('\n')
    first = text.index('end_header') + 1
    text[first] = 'nan ' + text[first].split(' ', 1)[1]
    open(ascii_ply, 'w').write('\n'.join(text))
    code, _, stderr = cli(['solve', ascii_ply, '--smooth', '1', '--out',
                           out, '--quiet'], capsys)
    assert_user_error(code, stderr, 'solve', 'ascii.ply', 'NaN')


def test_a_mesh_of_three_triangles(tmp_path, capsys):
    # the figure took a (3, 3) face array for the other layout
    path = str(tmp_path / 'three.obj')
    trimesh.Trimesh([[0, 0, 0], [1, 0, 0], [0, 1, 0], [0, 0, 1]],
                    [[0, 1, 2], [0, 1, 3], [0, 2, 3]],
                    process=False).export(path)
    out = tmp_path / 'out'
    code, _, stderr = cli(['solve', path, '--smooth', '1e-2', '--out', out,
                           '--quiet'], capsys)
    assert code == 0, stderr
    assert {'result.ply', 'result.png', 'report.json'} <= set(
        os.listdir(out))


@pytest.mark.parametrize('text, message', [
    ('v 0 0 0\n', 'only 1 vertex; a surface needs at least 3'),
    ('v 0 0 0\nv 1 0 0\n', 'only 2 vertices'),
])
def test_tiny_meshes(tmp_path, capsys, text, message):
    path = tmp_path / 'tiny.obj'
    path.write_text(text)
    code, _, stderr = cli(['solve', path, '--smooth', '1', '--out',
                           tmp_path / 'out', '--quiet'], capsys)
    assert_user_error(code, stderr, 'solve', 'tiny.obj', message)


def test_a_signal_of_three_dimensions(files, tmp_path, capsys):
    np.save(tmp_path / 'cube.npy', np.zeros((162, 2, 2)))
    code, _, stderr = cli(['solve', files[0]['obj'], '--smooth', '1',
                           '--signal', tmp_path / 'cube.npy', '--out',
                           tmp_path / 'out', '--quiet'], capsys)
    assert_user_error(code, stderr, 'solve', '(162, 2, 2)',
                      'shape (162,) or (162, C)')


def test_a_weight_far_too_large_names_the_option(files, tmp_path, capsys):
    code, _, stderr = cli(['solve', files[0]['obj'], '--smooth', '1e300',
                           '--out', tmp_path / 'out', '--quiet'], capsys)
    assert_user_error(code, stderr, 'solve', '--smooth 1e+300 is too large',
                      'use --smooth at most')
    assert 'alpha' not in stderr and 'rescale' not in stderr


def test_the_output_folder_never_holds_the_input(files, tmp_path, capsys):
    out = tmp_path / 'out'
    argv = ['solve', files[0]['obj'], '--smooth', '1e-2', '--quiet']
    assert cli(argv + ['--out', out], capsys)[0] == 0
    before = (out / 'result.ply').read_bytes()
    code, _, stderr = cli(['solve', out / 'result.ply', '--smooth', '1e-2',
                           '--out', out, '--overwrite', '--quiet'], capsys)
    assert_user_error(code, stderr, 'solve', '--out', 'holds the input')
    assert (out / 'result.ply').read_bytes() == before


def test_a_failed_run_leaves_the_earlier_results(files, tmp_path, capsys,
                                                 monkeypatch):
    out = tmp_path / 'out'
    argv = ['solve', files[0]['obj'], '--quiet', '--out', out]
    assert cli(argv + ['--smooth', '1e-2'], capsys)[0] == 0
    before = {name: (out / name).read_bytes() for name in os.listdir(out)}
    import tg_intrinsic.io.figures as figures

    def broken(*args, **kwargs):
        raise ValueError('the figure failed')
    monkeypatch.setattr(figures, 'draw_surface', broken)
    code, _, stderr = cli(argv + ['--smooth', '1'], capsys)
    assert_user_error(code, stderr, 'solve', 'the figure failed')
    # the same files, none from the failed run, and no temporary folder
    assert {name: (out / name).read_bytes()
            for name in os.listdir(out)} == before
    assert sorted(os.listdir(tmp_path)) == ['out']


def test_a_rerun_replaces_the_results_whole(files, tmp_path, capsys):
    out = tmp_path / 'out'
    base = ['solve', files[0]['obj'], '--quiet', '--out', out]
    assert cli(base + ['--smooth', '1e-2'], capsys)[0] == 0
    assert cli(base + ['--smooth', '1e-1'], capsys)[0] == 0
    with open(out / 'report.json') as f:
        assert json.load(f)['parameters'] == {'alpha': 0.1}
    assert sorted(os.listdir(tmp_path)) == ['out']


def test_foreign_files_need_overwrite_and_are_kept(files, tmp_path,
                                                   capsys):
    out = tmp_path / 'mine'
    out.mkdir()
    (out / 'notes.txt').write_text('my notes')
    argv = ['solve', files[0]['obj'], '--smooth', '1e-2', '--quiet',
            '--out', out]
    code, _, stderr = cli(argv, capsys)
    assert_user_error(code, stderr, 'solve', 'notes.txt', '--overwrite')
    assert os.listdir(out) == ['notes.txt']
    assert cli(argv + ['--overwrite'], capsys)[0] == 0
    assert (out / 'notes.txt').read_text() == 'my notes'
    assert (out / 'result.ply').exists()
    # the next run (still into a folder of other files) replaces its own
    # files, removes those it no longer writes and keeps the notes
    (out / 'result.png').rename(out / 'old.png')
    with open(out / '.tg-intrinsic.json') as f:
        record = json.load(f)
    record['files'].append('old.png')
    with open(out / '.tg-intrinsic.json', 'w') as f:
        json.dump(record, f)
    assert cli(argv + ['--overwrite'], capsys)[0] == 0
    assert (out / 'notes.txt').read_text() == 'my notes'
    assert sorted(os.listdir(out)) == ['.tg-intrinsic.json', 'notes.txt',
                                       'report.json', 'result.ply',
                                       'result.png']


def test_a_weight_too_small_to_smooth_warns(files, tmp_path, capsys):
    # on a surface 1e8 times larger, --smooth 1e-3 leaves it as it was:
    # said, with the weight that would have an effect
    paths, pos, face, _, _ = files
    huge = str(tmp_path / 'huge.obj')
    trimesh.Trimesh(pos * 1e8, face, process=False).export(huge)
    code, _, stderr = cli(['solve', huge, '--smooth', '1e-3', '--quiet',
                           '--out', tmp_path / 'out'], capsys)
    assert code == 0
    assert 'tg-intrinsic: warning: --smooth 0.001 is so small' in stderr
    bound = float(stderr.split('use --smooth at least ')[1].split()[0])
    code, _, stderr = cli(['solve', huge, '--smooth', str(100 * bound),
                           '--quiet', '--out', tmp_path / 'out'], capsys)
    assert code == 0 and 'warning' not in stderr
    moved, _, _ = read_surface(str(tmp_path / 'out' / 'result.ply'))
    # beyond the bound the surface moves by more than rounding
    assert np.abs(moved - pos * 1e8).max() > 1e-13 * 1e8


def test_pcg_that_does_not_converge_names_the_options(files, tmp_path,
                                                     capsys):
    paths = files[0]
    code, _, stderr = cli(['solve', paths['obj'], '--smooth', '1e-2',
                           '--signal', paths['npy'], '--method', 'pcg',
                           '--max-cycles', '1', '--tol', '1e-12', '--out',
                           tmp_path / 'out', '--quiet'] + HIERARCHY, capsys)
    assert code == 0, stderr
    assert stderr.startswith('tg-intrinsic: warning: the solve did not '
                             'converge: stopped at --max-cycles 1 PCG '
                             'iterations with relative residual ')
    assert stderr.endswith('above --tol 1e-12; raise --max-cycles\n')


# ----------------------------------------------------------------------
# Issue 40: files from other editors and tools, and what is said when
# they cannot be used

def test_an_obj_saved_with_a_byte_order_mark(files, tmp_path, capsys):
    # Notepad saves UTF-8 with a BOM; '\ufeffv 0 0 0' lost the first
    # vertex: "IndexError: index 161 is out of bounds"
    paths, pos, face, _, _ = files
    text = ''.join(f'v {x!r} {y!r} {z!r}\n' for x, y, z in pos.tolist()) \
        + ''.join(f'f {a} {b} {c}\n' for a, b, c in (face + 1).tolist())
    path = tmp_path / 'notepad.obj'
    path.write_text(text, encoding='utf-8-sig')
    code, _, stderr = cli(['solve', path, '--smooth', '1e-2', '--out',
                           tmp_path / 'out', '--quiet'], capsys)
    assert code == 0 and stderr == '', stderr
    got, got_face, _ = read_surface(str(tmp_path / 'out' / 'result.ply'))
    assert len(got) == 162 and np.array_equal(got_face, face)


def test_a_two_object_obj_is_not_said_to_be_welded(files, tmp_path, capsys):
    # two closed meshes in one file, an object and a material each
    _, pos, face, _, _ = files
    lines = []
    for k, shift in enumerate((0.0, 5.0)):
        lines += [f'o part{k}', f'usemtl material{k}']
        lines += [f'v {x + shift!r} {y!r} {z!r}' for x, y, z in pos.tolist()]
        lines += [f'f {a} {b} {c}' for a, b, c in
                  (face + 1 + k * len(pos)).tolist()]
    path = tmp_path / 'two.obj'
    path.write_text('\n'.join(lines) + '\n')
    out = tmp_path / 'out'
    code, _, stderr = cli(['solve', path, '--smooth', '1e-2', '--out', out,
                           '--quiet'], capsys)
    assert code == 0, stderr
    assert 'welded' not in stderr and stderr == '', stderr
    with open(out / 'report.json') as f:
        assert json.load(f)['vertices'] == 2 * len(pos)


def _read_binary_ply(path):
    """An independent reader of a binary little-endian PLY's vertices:
    ``{name: column}`` in the types of the header."""
    types = {'char': 'i1', 'uchar': 'u1', 'short': '<i2', 'ushort': '<u2',
             'int': '<i4', 'uint': '<u4', 'float': '<f4', 'double': '<f8'}
    data = open(path, 'rb').read()
    end = data.index(b'end_header\n') + len(b'end_header\n')
    header = data[:end].decode('ascii').splitlines()
    assert header[1] == 'format binary_little_endian 1.0'
    fields, count, element = [], None, None
    for line in header:
        words = line.split()
        if words[0] == 'element':
            element = words[1]
            if element == 'vertex':
                count = int(words[2])
        elif words[0] == 'property' and element == 'vertex':
            fields.append((words[2], types[words[1]]))
    vertices = np.frombuffer(data[end:], dtype=fields, count=count)
    return {name: vertices[name] for name, _ in fields}


@pytest.mark.parametrize('encoding', ['binary', 'ascii'])
def test_result_ply_keeps_the_input_vertex_properties(tmp_path, capsys,
                                                      encoding):
    # colours, normals and a custom property of the input were lost
    mesh = trimesh.creation.icosphere(2)
    n = len(mesh.vertices)
    rng = np.random.default_rng(3)
    rgb = rng.integers(0, 256, (n, 3)).astype(np.uint8)
    normal = np.asarray(mesh.vertex_normals, dtype=np.float32)
    quality = rng.standard_normal(n).astype(np.float32)
    fields = [('x', '<f4'), ('y', '<f4'), ('z', '<f4'), ('red', 'u1'),
              ('green', 'u1'), ('blue', 'u1'), ('nx', '<f4'), ('ny', '<f4'),
              ('nz', '<f4'), ('quality', '<f4')]
    vertices = np.empty(n, dtype=fields)
    for k, name in enumerate('xyz'):
        vertices[name] = mesh.vertices[:, k]
    for k, name in enumerate(('red', 'green', 'blue')):
        vertices[name] = rgb[:, k]
    for k, name in enumerate(('nx', 'ny', 'nz')):
        vertices[name] = normal[:, k]
    vertices['quality'] = quality
    kinds = {'<f4': 'float', 'u1': 'uchar'}
    header = ['ply', f'format {encoding}'
              f'{"_little_endian" if encoding == "binary" else ""} 1.0',
              f'element vertex {n}'] + \
        [f'property {kinds[t]} {name}' for name, t in fields] + \
        [f'element face {len(mesh.faces)}',
         'property list uchar int vertex_indices', 'end_header']
    path = tmp_path / 'scan.ply'
    with open(path, 'wb') as f:
        f.write(('\n'.join(header) + '\n').encode('ascii'))
        if encoding == 'binary':
            triangles = np.empty(len(mesh.faces),
                                 dtype=[('n', 'u1'), ('v', '<i4', (3,))])
            triangles['n'], triangles['v'] = 3, mesh.faces
            f.write(vertices.tobytes() + triangles.tobytes())
        else:
            for row in vertices.tolist():
                f.write((' '.join(repr(v) for v in row) + '\n').encode())
            for a, b, c in mesh.faces.tolist():
                f.write(f'3 {a} {b} {c}\n'.encode())
    out = tmp_path / 'out'
    code, _, stderr = cli(['solve', path, '--smooth', '1e-2', '--signal',
                           'quality', '--out', out, '--quiet'], capsys)
    assert code == 0, stderr
    written = _read_binary_ply(str(out / 'result.ply'))
    assert list(written) == ['x', 'y', 'z', 'red', 'green', 'blue', 'nx',
                             'ny', 'nz', 'quality', 'signal', 'result']
    for name, kind in fields[3:]:  # equal, and in their own types
        assert written[name].dtype == np.dtype(kind), name
        assert np.array_equal(written[name], vertices[name]), name
    assert np.array_equal(written['signal'], quality)
    # trimesh reads the colours as colours
    loaded = trimesh.load(out / 'result.ply', process=False)
    assert np.array_equal(loaded.visual.vertex_colors[:, :3], rgb)
    with open(out / 'report.json') as f:
        report = json.load(f)
    assert report['input_properties'] == ['red', 'green', 'blue', 'nx', 'ny',
                                          'nz', 'quality']
    # fairing moves the vertices: their old normals are left out; a
    # property named like a new one is replaced by it
    code, _, stderr = cli(['solve', out / 'result.ply', '--smooth', '1e-2',
                           '--out', tmp_path / 'fair', '--quiet'], capsys)
    assert code == 0, stderr
    faired = _read_binary_ply(str(tmp_path / 'fair' / 'result.ply'))
    assert list(faired) == ['x', 'y', 'z', 'red', 'green', 'blue',
                            'quality'] + [f'{key}_{k}' for key in
                                          ('signal', 'result')
                                          for k in range(3)]
    assert np.array_equal(faired['quality'], quality)


def _degenerate_obj(tmp_path, pos, face):
    """The sphere with its first triangle flattened: one corner moved to
    the middle of the opposite edge (zero area, three distinct
    corners)."""
    flat = pos.copy()
    a, b, c = face[0]
    flat[c] = (flat[a] + flat[b]) / 2
    path = tmp_path / 'flat.obj'
    path.write_text(
        ''.join(f'v {x!r} {y!r} {z!r}\n' for x, y, z in flat.tolist())
        + ''.join(f'f {a} {b} {c}\n' for a, b, c in (face + 1).tolist()))
    return path


def test_a_zero_area_triangle_names_the_file_and_the_option(files, tmp_path,
                                                             capsys):
    # was: "'face' has 1 zero-area (degenerate) triangle(s) (first: [0]);
    # remove them, e.g. with trimesh's ...", after the hierarchy was built
    _, pos, face, _, _ = files
    path = _degenerate_obj(tmp_path, pos, face)
    for problem in (['--smooth', '1e-2'], ['--conformal-flow', '1e-3']):
        code, _, stderr = cli(['solve', path, '--out', tmp_path / 'out',
                               '--quiet'] + problem, capsys)
        assert_user_error(code, stderr, 'solve', f"'{path}' has 1 zero-area "
                          f"triangle(s)", "first: triangle 0",
                          f"from line {len(pos) + 1}: 'f {face[0][0] + 1} ",
                          'give --robust-laplacian', 'delete these faces')
    # the option it names works
    out = tmp_path / 'robust'
    code, _, stderr = cli(['solve', path, '--smooth', '1e-2', '--out', out,
                           '--quiet', '--robust-laplacian'], capsys)
    assert code == 0, stderr
    with open(out / 'report.json') as f:
        assert json.load(f)['laplacian'] == 'robust (--robust-laplacian)'
    assert np.isfinite(read_surface(str(out / 'result.ply'))[0]).all()


def test_the_robust_laplacian_option_is_the_library_robust_laplacian(
        files, tmp_path, capsys):
    # a flattened ellipsoid: obtuse triangles, where the robust (intrinsic
    # Delaunay) Laplacian differs from the cotan Laplacian
    _, pos, face, signal, _ = files
    pos = pos * [3, 1, 0.3]
    path = tmp_path / 'ellipsoid.ply'
    write_ply(str(path), pos, face)
    np.save(tmp_path / 'y.npy', signal)
    results = {}
    for option in ([], ['--robust-laplacian']):
        out = tmp_path / f'out{len(option)}'
        code, _, stderr = cli(['solve', path, '--smooth', '1e-2', '--signal',
                               tmp_path / 'y.npy', '--out', out, '--quiet',
                               '--tol', '1e-12'] + option, capsys)
        assert code == 0, stderr
        _, _, props = read_surface(str(out / 'result.ply'))
        results[bool(option)] = np.stack([props['result_0'],
                                          props['result_1']], 1)
        with open(out / 'report.json') as f:
            assert json.load(f)['laplacian'] == (
                'robust (--robust-laplacian)' if option else 'cotan')
    for robust in (False, True):
        direct = smooth(mesh_data(pos, face), 1e-2,
                        y=torch.from_numpy(signal), robust=robust,
                        tol=1e-12).numpy()
        assert np.abs(results[robust] - direct).max() < 1e-9
    assert np.abs(results[True] - results[False]).max() > 1e-3


def test_a_signal_that_is_a_folder_is_said_to_be_one(files, tmp_path,
                                                     capsys):
    # was: "signal file '...' does not exist"
    paths = files[0]
    for name in ('values', 'values.npy'):
        (tmp_path / name).mkdir()
        code, _, stderr = cli(['solve', paths['obj'], '--smooth', '1',
                               '--signal', tmp_path / name, '--out',
                               tmp_path / 'out', '--quiet'], capsys)
        assert_user_error(code, stderr, 'solve', f"'{tmp_path / name}' is a "
                          f"folder; give a .npy/.txt/.csv file with one row "
                          f"per vertex, or FILE.ply:NAME")
        assert 'does not exist' not in stderr


def _unreadable():
    """Whether /proc/self/mem opens but fails to read at offset 0 (EIO),
    as on Linux."""
    try:
        with open('/proc/self/mem', 'rb') as f:
            f.read(1)
    except OSError as error:
        return error.errno == errno.EIO
    return False


@pytest.mark.skipif(not _unreadable(), reason='needs /proc/self/mem that '
                    'fails to read (Linux)')
def test_a_file_that_cannot_be_read_is_one_line_without_errno(
        files, tmp_path, capsys):
    # /proc/self/mem opens but cannot be read (EIO): the bare
    # "OSError: [Errno 5] Input/output error" was the message
    paths = files[0]
    os.symlink('/proc/self/mem', tmp_path / 'mesh.obj')
    os.symlink('/proc/self/mem', tmp_path / 'signal.npy')
    for argv, what in (([tmp_path / 'mesh.obj'], f"'{tmp_path / 'mesh.obj'}'"),
                       ([paths['obj'], '--signal', tmp_path / 'signal.npy'],
                        f"signal file '{tmp_path / 'signal.npy'}'")):
        code, _, stderr = cli(['solve'] + argv + [
            '--smooth', '1', '--out', tmp_path / 'out', '--quiet'], capsys)
        assert_user_error(code, stderr, 'solve',
                          f"{what} cannot be read: input/output error")
        assert 'Errno' not in stderr


@pytest.mark.parametrize('path, message', [
    ('/proc/nope', "'/proc/nope' does not exist"),
    ('/proc/nope.obj', "'/proc/nope.obj' does not exist"),
    ('LINK', "does not exist (it is a link to"),
    ('INSIDE_A_FILE', "is a file, not a folder)"),
])
def test_a_path_that_is_no_file_is_one_line(files, tmp_path, capsys, path,
                                            message):
    if path == 'LINK':
        path = tmp_path / 'link.obj'
        os.symlink(tmp_path / 'gone.obj', path)
    elif path == 'INSIDE_A_FILE':
        path = os.path.join(files[0]['obj'], 'mesh.obj')
    code, _, stderr = cli(['solve', path, '--smooth', '1', '--out',
                           tmp_path / 'out', '--quiet'], capsys)
    assert_user_error(code, stderr, 'solve', message)
