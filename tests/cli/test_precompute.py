"""tg-intrinsic precompute: every kind against its transform called
directly, folders mirrored, resuming, the settings manifest, failures that
leave the other files done, and --workers 1 vs 2 giving the same files."""
import json
import os
import signal
import subprocess
import sys
import time

import numpy as np
import pytest
import torch
import trimesh

from tg_intrinsic.data import IntrinsicData
from tg_intrinsic.io import read_surface, write_ply
from tg_intrinsic.train import hsn_pipeline
from tg_intrinsic.transforms import (EstimateNormals, GravoHierarchy, LogMap,
                                     MLSOperators)

from tests.cli import run_cli

BAD = {'garbage.off': 'this is not a mesh\n',
       'nan.off': 'OFF\n3 1 0\n0 0 0\nnan 0 0\n0 1 0\n3 0 1 2\n',
       'past.off': 'OFF\n3 1 0\n0 0 0\n1 0 0\n0 1 0\n3 0 1 5\n'}


def cli(argv, capsys):
    """Runs the command line: (exit code, stdout, stderr)."""
    return run_cli(capsys, *argv)


def load(path):
    return torch.load(path, weights_only=False)


def make_folder(root):
    """a.obj (42 vertices), sub/b.off (162), c.ply (a 200-point cloud with
    normals) and a text file that is not a mesh."""
    (root / 'sub').mkdir(parents=True)
    trimesh.creation.icosphere(1).export(str(root / 'a.obj'))
    trimesh.creation.icosphere(2).export(str(root / 'sub' / 'b.off'))
    rng = np.random.default_rng(0)
    cloud = rng.normal(size=(200, 3))
    cloud /= np.linalg.norm(cloud, axis=1, keepdims=True)
    write_ply(str(root / 'c.ply'), cloud,
              properties={'nx': cloud[:, 0], 'ny': cloud[:, 1],
                          'nz': cloud[:, 2]})
    (root / 'notes.txt').write_text('not a mesh')
    return root


def surface(path, dtype=torch.float32):
    pos, face, _ = read_surface(str(path))
    data = IntrinsicData(pos=torch.from_numpy(pos).to(dtype))
    if face is not None:
        data.face = torch.from_numpy(face).t().contiguous()
    return data


def same(a, b):
    assert sorted(a.keys()) == sorted(b.keys())
    for key in a.keys():
        assert torch.equal(a[key], b[key]), key


def test_mls_folder_is_mirrored(tmp_path, capsys):
    src = make_folder(tmp_path / 'in')
    out = tmp_path / 'out'
    code, stdout, stderr = cli(['precompute', 'mls', str(src), str(out),
                                '--k', '8'], capsys)
    assert code == 0, stderr
    assert 'precomputed mls for 3 file(s)' in stdout
    assert sorted(os.path.relpath(os.path.join(r, f), out)
                  for r, _, fs in os.walk(out) for f in fs) == \
        ['a.pt', 'c.pt', 'precompute.json', os.path.join('sub', 'b.pt')]
    with open(out / 'precompute.json') as f:
        manifest = json.load(f)
    assert manifest['kind'] == 'mls'
    assert manifest['settings'] == {'dtype': 'float32', 'k': 8,
                                    'regularizer': 1e-3, 'normal_k': 10}
    # the mesh: normals from the mesh, operators as MLSOperators makes them
    a = load(out / 'a.pt')
    assert isinstance(a, IntrinsicData) and a.pos.dtype == torch.float32
    assert a.grad_weight.shape == (42 * 8, 2) and a.face.shape == (3, 80)
    same(a, MLSOperators(k=8)(EstimateNormals()(surface(src / 'a.obj'))))
    # the point cloud: the PLY's normals
    c = load(out / 'c.pt')
    pos, _, props = read_surface(str(src / 'c.ply'))
    normal = np.stack([props['nx'], props['ny'], props['nz']], 1)
    assert torch.allclose(c.normal, torch.from_numpy(normal).float())
    assert 'face' not in c and c.div_weight.shape == (200 * 8, 2)


def test_logmap_hsn_gravo_match_their_transforms(tmp_path, capsys):
    src = make_folder(tmp_path / 'in')
    mesh = src / 'sub' / 'b.off'
    code, _, stderr = cli(['--quiet', 'precompute', 'logmap', str(mesh),
                           str(tmp_path / 'b_logmap.pt'), '--radius', '0.5'],
                          capsys)
    assert code == 0, stderr
    same(load(tmp_path / 'b_logmap.pt'), LogMap(0.5)(surface(mesh)))
    # hsn: the pipeline training uses
    code, _, stderr = cli(['--quiet', 'precompute', 'hsn', str(mesh),
                           str(tmp_path / 'hsn'), '--rings', '4',
                           '--dtype', 'float64'], capsys)
    assert code == 0, stderr
    hsn = load(tmp_path / 'hsn' / 'b.pt')
    assert hsn.pos.dtype == torch.float64 and hsn.harmonic.shape[1:] == (4, 2)
    assert 'harmonic_1' in hsn and 'transport_1' in hsn
    same(hsn, hsn_pipeline(rings=4)(surface(mesh, torch.float64)))
    # gravo: on a point cloud, on its k-nn graph
    cloud = src / 'c.ply'
    code, _, stderr = cli(['--quiet', 'precompute', 'gravo', str(cloud),
                           str(tmp_path / 'gravo'), '--ratio', '4',
                           '--lower-bound', '10'], capsys)
    assert code == 0, stderr
    gravo = load(tmp_path / 'gravo' / 'c.pt')
    assert 'prolong_index_1' in gravo  # 200 -> 31 points
    expected = GravoHierarchy(ratio=4, lower_bound=10)(surface(cloud))
    expected.normal = gravo.normal  # the PLY's normals ride along
    same(gravo, expected)


@pytest.mark.parametrize('kind', ['logmap', 'hsn'])
def test_point_clouds_are_rejected_where_discs_need_a_mesh(tmp_path, capsys,
                                                           kind):
    src = make_folder(tmp_path / 'in')
    code, stdout, stderr = cli(['--quiet', 'precompute', kind,
                                str(src / 'c.ply'), str(tmp_path / 'o')],
                               capsys)
    assert code == 2 and stdout == '' and 'Traceback' not in stderr
    lines = stderr.strip().splitlines()
    assert len(lines) == 1, stderr
    assert lines[0].startswith('tg-intrinsic precompute: error: 1 of 1')
    assert 'c.ply' in lines[0] and 'point cloud' in lines[0] and \
        'needs a triangle mesh' in lines[0]


def test_resume_skips_finished_files(tmp_path, capsys):
    src = make_folder(tmp_path / 'in')
    out = tmp_path / 'out'
    argv = ['precompute', 'gravo', str(src), str(out), '--lower-bound', '10',
            '--ratio', '4']
    assert cli(argv, capsys)[0] == 0
    files = [out / 'a.pt', out / 'sub' / 'b.pt', out / 'c.pt']
    before = {f: os.stat(f).st_mtime_ns for f in files}
    first = load(out / 'sub' / 'b.pt')
    os.remove(out / 'sub' / 'b.pt')
    # what a run killed (kill -9) while saving leaves
    (out / '.tmp-0123456789abcdefa.pt').write_bytes(b'half')
    (out / 'sub' / '.tmp-0123456789abcdefb.pt').write_bytes(b'half')
    code, stdout, stderr = cli(argv, capsys)
    assert code == 0, stderr
    assert 'for 1 file(s) (skipped 2 already done)' in stdout
    assert 'removed 2 temporary file(s) of an interrupted write' in stdout
    assert not list(out.rglob('.tmp-*'))
    for f in files:
        if f.name == 'b.pt':
            same(load(f), first)  # recomputed, the same
        else:
            assert os.stat(f).st_mtime_ns == before[f]  # untouched
    code, stdout, _ = cli(argv, capsys)
    assert code == 0 and 'nothing to do' in stdout
    # an input changed after its result was written is recomputed
    os.utime(src / 'a.obj', ns=(before[files[0]] + 10**9,) * 2)
    code, stdout, _ = cli(argv, capsys)
    assert code == 0 and 'for 1 file(s) (skipped 2' in stdout


def test_other_settings_need_overwrite(tmp_path, capsys):
    src = make_folder(tmp_path / 'in')
    out = tmp_path / 'out'
    argv = ['--quiet', 'precompute', 'gravo', str(src / 'a.obj'), str(out),
            '--lower-bound', '10']
    assert cli(argv, capsys)[0] == 0
    code, stdout, stderr = cli(argv + ['--ratio', '4'], capsys)
    assert code == 2 and 'Traceback' not in stderr
    lines = stderr.strip().splitlines()
    assert len(lines) == 1, stderr
    assert 'other settings' in lines[0] and 'ratio 8.0 -> 4.0' in lines[0]
    assert '--overwrite' in lines[0]
    code, _, stderr = cli(argv[:2] + ['mls'] + argv[3:5], capsys)
    assert code == 2 and 'kind gravo -> mls' in stderr
    before = os.stat(out / 'a.pt').st_mtime_ns
    code, _, stderr = cli(argv + ['--ratio', '4', '--overwrite'], capsys)
    assert code == 0, stderr
    with open(out / 'precompute.json') as f:
        assert json.load(f)['settings']['ratio'] == 4.0
    assert os.stat(out / 'a.pt').st_mtime_ns != before


def test_bad_files_fail_alone(tmp_path, capsys):
    src = make_folder(tmp_path / 'in')
    for name, text in BAD.items():
        (src / 'sub' / name).write_text(text)
    out = tmp_path / 'out'
    code, stdout, stderr = cli(['--quiet', 'precompute', 'gravo', str(src),
                                str(out), '--lower-bound', '10'], capsys)
    assert code == 2 and stdout == '' and 'Traceback' not in stderr
    lines = stderr.strip().splitlines()
    assert len(lines) == 1, stderr
    line = lines[0]
    assert line.startswith('tg-intrinsic precompute: error: 3 of 6 file(s) '
                           'failed:')
    for name, reason in (('garbage.off', 'could not read'),
                         ('nan.off', 'NaN'),
                         ('past.off', 'face indices outside')):
        assert os.path.join('sub', name) + ': ' in line and reason in line
    assert 'failures.json' in line
    with open(out / 'failures.json') as f:
        failures = json.load(f)
    assert [f['file'] for f in failures] == [
        os.path.join('sub', name) for name in sorted(BAD)]
    for name in ('a.pt', 'c.pt', os.path.join('sub', 'b.pt')):
        assert os.path.exists(out / name)  # the good ones are done
    # once the bad files are gone the rerun succeeds and the list goes
    for name in BAD:
        os.remove(src / 'sub' / name)
    assert cli(['--quiet', 'precompute', 'gravo', str(src), str(out),
                '--lower-bound', '10'], capsys)[0] == 0
    assert not os.path.exists(out / 'failures.json')


@pytest.mark.parametrize('case, message', [
    ('empty', 'holds no .obj/.off/.ply/.stl files'),
    ('no_meshes', 'holds no .obj/.off/.ply/.stl files'),
    ('missing', 'does not exist'),
    ('not_a_mesh', 'is not a mesh or point cloud file'),
    ('output_is_file', 'is a file; give a folder'),
])
def test_bad_input_is_one_line_and_exit_code_2(tmp_path, capsys, case,
                                               message):
    src = tmp_path / 'in'
    src.mkdir()
    if case == 'no_meshes':
        (src / 'notes.txt').write_text('nothing here')
        (src / '.hidden.obj').write_text('')
    target = {'missing': src / 'nope', 'not_a_mesh': src / 'notes.txt'}.get(
        case, src)
    if case == 'not_a_mesh':
        target.write_text('text')
    output = tmp_path / 'out'
    if case == 'output_is_file':
        make_folder(src / 'meshes')
        output.write_text('a file')
    code, stdout, stderr = cli(['--quiet', 'precompute', 'mls', str(target),
                                str(output)], capsys)
    assert code == 2 and stdout == '' and 'Traceback' not in stderr
    lines = stderr.strip().splitlines()
    assert len(lines) == 1, stderr
    assert lines[0].startswith('tg-intrinsic precompute: error:')
    assert message in lines[0]


def test_bad_options(tmp_path, capsys):
    src = make_folder(tmp_path / 'in')
    for argv, message in (
            (['mls', '--k', '0'], 'argument --k: must be at least 3'),
            (['logmap', '--radius', '-1'], 'must be greater than 0'),
            (['gravo', '--ratio', '0.5'], '--ratio must be greater than 1'),
            (['hsn', '--method', 'exact'], 'invalid choice')):
        code, _, stderr = cli(['--quiet', 'precompute', argv[0], str(src),
                               str(tmp_path / 'o')] + argv[1:], capsys)
        assert code == 2 and 'Traceback' not in stderr
        assert len(stderr.strip().splitlines()) == 1 and message in stderr


def test_workers_give_identical_files(tmp_path, capsys):
    """--workers 1 in this process, --workers 2 (a process pool) in a
    subprocess: the same bytes."""
    src = make_folder(tmp_path / 'in')
    one, two = tmp_path / 'one', tmp_path / 'two'
    code, _, stderr = cli(['--quiet', 'precompute', 'mls', str(src),
                           str(one), '--k', '8'], capsys)
    assert code == 0, stderr
    done = subprocess.run(
        [sys.executable, '-m', 'tg_intrinsic', 'precompute', 'mls', str(src),
         str(two), '--k', '8', '--workers', '2'], capture_output=True,
        text=True, timeout=300)
    assert done.returncode == 0, done.stderr
    assert 'Traceback' not in done.stderr
    assert 'precomputed mls for 3 file(s)' in done.stdout
    for name in ('a.pt', 'c.pt', os.path.join('sub', 'b.pt')):
        same(load(one / name), load(two / name))
        assert (one / name).read_bytes() == (two / name).read_bytes()


def test_a_failed_overwrite_leaves_the_earlier_results(tmp_path, capsys):
    src = make_folder(tmp_path / 'in')
    out = tmp_path / 'out'
    argv = ['--quiet', 'precompute', 'mls', str(src), str(out)]
    assert cli(argv + ['--k', '3'], capsys)[0] == 0
    before = {f: (out / f).read_bytes()
              for f in ('a.pt', 'sub/b.pt', 'c.pt', 'precompute.json')}
    # every file fails (a.obj has 42 points): the folder is as it was
    code, _, stderr = cli(argv + ['--k', '100', '--overwrite'], capsys)
    assert code == 2
    assert 'fewer than --k 100; lower --k to at most 42' in stderr
    assert 'still holds the earlier results' in stderr
    assert {f: (out / f).read_bytes() for f in before} == before
    # ... so a plain rerun with the new settings is told about the old ones
    code, _, stderr = cli(argv + ['--k', '100'], capsys)
    assert code == 2 and 'k 3 -> 100' in stderr
    # a run that succeeds replaces them all, and leaves no staging folder
    code, _, stderr = cli(argv + ['--k', '5', '--overwrite'], capsys)
    assert code == 0, stderr
    with open(out / 'precompute.json') as f:
        assert json.load(f)['settings']['k'] == 5
    assert load(out / 'a.pt').edge_index.size(1) == 42 * 5
    assert sorted(os.listdir(tmp_path)) == ['in', 'out']


def test_linked_folders_are_followed_once(tmp_path, capsys):
    src = make_folder(tmp_path / 'in')
    elsewhere = make_folder(tmp_path / 'elsewhere')
    os.symlink(elsewhere / 'sub', src / 'linked')
    os.symlink(src, src / 'sub' / 'loop')  # must not loop
    out = tmp_path / 'out'
    code, _, stderr = cli(['--quiet', 'precompute', 'gravo', src, out,
                           '--lower-bound', '10'], capsys)
    assert code == 0, stderr
    assert (out / 'linked' / 'b.pt').exists()


def test_files_precompute_did_not_write_need_overwrite(tmp_path, capsys):
    src = make_folder(tmp_path / 'in')
    out = tmp_path / 'out'
    out.mkdir()
    (out / 'notes.md').write_text('mine')
    argv = ['--quiet', 'precompute', 'gravo', str(src), str(out),
            '--lower-bound', '10']
    code, _, stderr = cli(argv, capsys)
    assert code == 2 and 'notes.md' in stderr and '--overwrite' in stderr
    assert cli(argv + ['--overwrite'], capsys)[0] == 0
    assert (out / 'notes.md').read_text() == 'mine'
    # one output file that exists is replaced only with --overwrite
    single = ['--quiet', 'precompute', 'gravo', str(src / 'a.obj'),
              str(tmp_path / 'a.pt'), '--lower-bound', '10']
    assert cli(single, capsys)[0] == 0
    code, _, stderr = cli(single, capsys)
    assert code == 2 and 'exists' in stderr and '--overwrite' in stderr
    assert cli(single + ['--overwrite'], capsys)[0] == 0


def test_an_stl_is_welded_for_every_kind(tmp_path, capsys):
    # precompute hsn refused an STL ("weld them first"); now every command
    # reads it by the same policy
    trimesh.creation.icosphere(1).export(str(tmp_path / 'ball.stl'))
    for kind in ('hsn', 'mls', 'gravo'):
        out = tmp_path / f'{kind}.pt'
        code, _, stderr = cli(['--quiet', 'precompute', kind,
                               tmp_path / 'ball.stl', out], capsys)
        assert code == 0, stderr
        assert 'welded 198 vertices' in stderr
        assert load(out).num_nodes == 42


def test_overwrite_keeps_the_users_files_beside_the_results(tmp_path,
                                                             capsys):
    src = make_folder(tmp_path / 'in')
    out = tmp_path / 'out'
    argv = ['--quiet', 'precompute', 'mls', str(src), str(out)]
    assert cli(argv + ['--k', '3'], capsys)[0] == 0
    torch.save({'mine': 1}, out / 'labels.pt')
    (out / 'mine').mkdir()
    torch.save({'mine': 2}, out / 'mine' / 'notes.pt')
    code, _, stderr = cli(argv + ['--k', '8'], capsys)
    assert code == 2 and 'k 3 -> 8' in stderr
    # they are the user's, not results of unknown settings
    code, _, stderr = cli(argv + ['--k', '3'], capsys)
    assert code == 2 and 'files precompute did not write (labels.pt, ' \
        'mine/notes.pt)' in stderr, stderr
    (src / 'c.ply').unlink()   # its old result is precompute's: removed
    code, _, stderr = cli(argv + ['--k', '8', '--overwrite'], capsys)
    assert code == 0, stderr
    assert load(out / 'labels.pt') == {'mine': 1}
    assert load(out / 'mine' / 'notes.pt') == {'mine': 2}
    assert not (out / 'c.pt').exists()
    assert load(out / 'a.pt').edge_index.size(1) == 42 * 8
    with open(out / 'precompute.json') as f:
        assert json.load(f)['files'] == ['a.pt', 'sub/b.pt']


def test_a_linked_output_is_written_through(tmp_path, capsys):
    src = make_folder(tmp_path / 'in')
    target = tmp_path / 'scratch'
    target.mkdir()
    link = tmp_path / 'out'
    link.symlink_to(target)
    argv = ['--quiet', 'precompute', 'gravo', str(src), str(link),
            '--lower-bound', '10']
    assert cli(argv, capsys)[0] == 0
    assert cli(argv + ['--ratio', '3', '--overwrite'], capsys)[0] == 0
    assert link.is_symlink() and (target / 'sub' / 'b.pt').exists()
    assert sorted(os.listdir(tmp_path)) == ['in', 'out', 'scratch']


def test_messages_name_the_option_and_the_problem(tmp_path, capsys):
    src = make_folder(tmp_path / 'in')
    (tmp_path / 'x.pt').mkdir()
    for argv, needles in [
            (['mls', src / 'a.obj', tmp_path / 'x.pt'],
             ["OUTPUT '", "x.pt' is a folder, not a .pt file"]),
            (['mls', src / 'a.obj', tmp_path / 'x.pt', '--overwrite'],
             ["x.pt' is a folder, not a .pt file"]),
            (['mls', src, tmp_path / 'o', '--normal-k', '1'],
             ['argument --normal-k: must be at least 2']),
            (['mls', src, tmp_path / 'o', '--k', '2'],
             ['argument --k: must be at least 3'])]:
        code, _, stderr = cli(['--quiet', 'precompute'] + argv, capsys)
        assert code == 2 and 'Traceback' not in stderr, stderr
        assert len(stderr.strip().splitlines()) == 1, stderr
        for needle in needles:
            assert needle in stderr, stderr


def test_ctrl_c_stops_precompute_while_it_saves(tmp_path):
    """Ctrl-C (SIGINT) in the middle of an --overwrite run: exit 130 and
    a stop, not a failed file reported as torch's RuntimeError and a run
    that goes on; the earlier results stay."""
    src = tmp_path / 'in'
    src.mkdir()
    for index in range(30):
        trimesh.creation.icosphere(2).export(str(src / f'{index:02d}.obj'))
    out = tmp_path / 'out'
    argv = [sys.executable, '-m', 'tg_intrinsic', '--quiet', 'precompute',
            'gravo', str(src), str(out), '--lower-bound', '10']
    subprocess.run(argv, check=True, capture_output=True)
    before = (out / '00.pt').read_bytes()
    run = subprocess.Popen(argv + ['--ratio', '3', '--overwrite'],
                           stderr=subprocess.PIPE, text=True)
    staging = tmp_path / '.out.overwrite'
    while run.poll() is None and len(list(staging.glob('*.pt'))) < 3:
        time.sleep(0.01)
    run.send_signal(signal.SIGINT)
    _, stderr = run.communicate(timeout=120)
    assert run.returncode == 130, stderr
    assert 'interrupted' in stderr and 'failed' not in stderr, stderr
    assert (out / '00.pt').read_bytes() == before
    assert not list(staging.glob('.tmp-*'))   # no half-written file
