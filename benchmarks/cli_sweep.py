"""A careful new user's sweep of the command line (issue 30): bad and
unusual inputs over every sub-command, each run in a fresh sandbox of
files that other tools wrote, with four checks per case:

- **exit code**: only 0, 2 (a user mistake, one line) or 130;
- **no data loss**: every file that existed before the run (inputs, a
  user's own files, earlier results) is byte for byte the same after it,
  except the results a successful run replaced in its own output folder;
- **no wrong result**: a run that exits 0 wrote what the case expects
  (checked per case: vertex counts after welding, settings recorded);
- **a message that names the user's own option or file**: the error line
  holds one of the case's options (``--k``) or a file name it gave.

Writes ``benchmarks/results/cli_sweep.json`` (every case with its exit
code, message and verdicts) and prints the counts. Runs in-process
through :func:`tg_intrinsic.cli.main`, a few minutes on 2 cores.

    python benchmarks/cli_sweep.py
"""
import contextlib
import hashlib
import io
import json
import os
import shutil
import sys
import tempfile
import time

import numpy as np
import trimesh

sys.path.insert(0, os.path.join(os.path.dirname(__file__), '..'))
from tg_intrinsic.cli import main  # noqa: E402
from tg_intrinsic.io import write_ply  # noqa: E402
from tg_intrinsic.utils import atomic_write_json, machine_info  # noqa: E402

RESULTS = os.path.join(os.path.dirname(__file__), 'results',
                       'cli_sweep.json')
# the generated training data, shared by the cases (a cache, not a file of
# the user's): '{data}' in a case
DATA = os.path.join(tempfile.gettempdir(), 'tg-intrinsic-sweep-data')
TINY_TRAINING = ['--epochs', '1', '--num-points', '64', '--shapes-per-class',
                 '2', '--batch-size', '4', '--quiet', '--root', DATA]


# ---------------------------------------------------------------- files
def make_files(root: str):
    """The files of the sandbox: meshes as other tools write them, bad
    ones, signals, a user's own folder and a scene."""
    ico = trimesh.creation.icosphere(2)
    ico.export(os.path.join(root, 'ico.obj'))
    ico.export(os.path.join(root, 'ico.stl'))
    ico.export(os.path.join(root, 'ico.off'))
    with open(os.path.join(root, 'ascii.ply'), 'wb') as f:
        f.write(trimesh.exchange.ply.export_ply(
            trimesh.Trimesh(ico.vertices, ico.faces, process=False,
                            vertex_attributes={'heat': ico.vertices[:, 2]}),
            encoding='ascii'))
    soup = trimesh.Trimesh(ico.vertices[ico.faces].reshape(-1, 3),
                           np.arange(3 * len(ico.faces)).reshape(-1, 3),
                           process=False)
    soup.export(os.path.join(root, 'soup.obj'))
    write_ply(os.path.join(root, 'cloud.ply'),
              ico.vertices + 0.0, properties={'q': ico.vertices[:, 0]})
    text = open(os.path.join(root, 'ascii.ply')).read().split('\n')
    first = text.index('end_header') + 1
    text[first] = 'nan ' + text[first].split(' ', 1)[1]
    open(os.path.join(root, 'nan_ascii.ply'), 'w').write('\n'.join(text))
    small = {'one.obj': 'v 0 0 0\n', 'two.obj': 'v 0 0 0\nv 1 0 0\n',
             'garbage.obj': 'this is not a mesh\n', 'empty.off': '',
             'repeat.obj': 'v 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 1 2\n',
             'past.off': 'OFF\n3 1 0\n0 0 0\n1 0 0\n0 1 0\n3 0 1 5\n',
             'notes.txt': 'a user file\n', 'mesh.xyz': '0 0 0\n'}
    for name, body in small.items():
        open(os.path.join(root, name), 'w').write(body)
    trimesh.Trimesh([[0, 0, 0], [1, 0, 0], [0, 1, 0], [0, 0, 1]],
                    [[0, 1, 2], [0, 1, 3], [0, 2, 3]],
                    process=False).export(os.path.join(root, 'three.obj'))
    # quads, negative indices, comments, capitals, spaces, a point cloud
    # with normals, a binary PLY with a NaN
    open(os.path.join(root, 'quads.obj'), 'w').write(
        '# a cube\n' + ''.join(f'v {x} {y} {z}\n' for x in (0, 1)
                               for y in (0, 1) for z in (0, 1))
        + 'f 1 2 4 3\nf 5 7 8 6\nf 1 5 6 2\nf 3 4 8 7\nf 1 3 7 5\n'
        'f 2 6 8 4\n')
    open(os.path.join(root, 'negative.obj'), 'w').write(
        'v 0 0 0\nv 1 0 0\nv 0 1 0\nv 0 0 1\nf -4 -3 -2\nf -4 -3 -1\n'
        'f -4 -2 -1\nf -3 -2 -1\n')
    ico.export(os.path.join(root, 'CAPS.OBJ'))
    ico.export(os.path.join(root, 'with space.obj'))
    write_ply(os.path.join(root, 'normals.ply'), ico.vertices + 0.0,
              properties={'nx': ico.vertices[:, 0], 'ny': ico.vertices[:, 1],
                          'nz': ico.vertices[:, 2]})
    bad_pos = ico.vertices + 0.0
    bad_pos[3, 1] = np.nan
    write_ply(os.path.join(root, 'nan_binary.ply'), bad_pos, ico.faces)
    write_ply(os.path.join(root, 'zero_normals.ply'), ico.vertices + 0.0,
              properties={'nx': 0 * ico.vertices[:, 0],
                          'ny': 0 * ico.vertices[:, 1],
                          'nz': 0 * ico.vertices[:, 2]})
    # an unreferenced vertex, a huge scale, a non-manifold fin, a unicode
    # name, an OFF of quads
    with open(os.path.join(root, 'loose.obj'), 'w') as f:
        f.write(open(os.path.join(root, 'ico.obj')).read() + 'v 9 9 9\n')
    trimesh.Trimesh(ico.vertices * 1e8, ico.faces, process=False).export(
        os.path.join(root, 'huge.obj'))
    fin = np.vstack([ico.vertices, [[0, 0, 2.0]]])
    trimesh.Trimesh(fin, np.vstack([ico.faces, [[ico.faces[0][0],
                                                 ico.faces[0][1], len(fin)
                                                 - 1]]]),
                    process=False).export(os.path.join(root, 'fin.obj'))
    ico.export(os.path.join(root, 'kugel-ä.obj'))
    open(os.path.join(root, 'quads.off'), 'w').write(
        'OFF\n# a cube\n8 6 0\n' + ''.join(
            f'{x} {y} {z}\n' for x in (0, 1) for y in (0, 1) for z in (0, 1))
        + '4 0 1 3 2\n4 4 6 7 5\n4 0 4 5 1\n4 2 3 7 6\n4 0 2 6 4\n'
        '4 1 5 7 3\n')
    n = len(ico.vertices)
    np.savetxt(os.path.join(root, 'sig.txt'), np.ones(n))
    np.savetxt(os.path.join(root, 'sig.csv'), np.ones((n, 3)), delimiter=',')
    open(os.path.join(root, 'words.txt'), 'w').write('a\nb\n')
    os.makedirs(os.path.join(root, 'empty'))
    os.makedirs(os.path.join(root, 'only_text'))
    open(os.path.join(root, 'only_text', 'readme.txt'), 'w').write('x')
    np.save(os.path.join(root, 'sig.npy'), np.random.default_rng(0).normal(
        size=(n, 2)))
    np.save(os.path.join(root, 'short.npy'), np.zeros(n - 1))
    np.save(os.path.join(root, 'cube.npy'), np.zeros((n, 2, 2)))
    np.save(os.path.join(root, 'nan.npy'), np.full(n, np.nan))
    np.save(os.path.join(root, 'stored.npy'), np.zeros(3 * len(ico.faces)))
    os.makedirs(os.path.join(root, 'folder.obj'))
    # a folder of meshes, one of them linked in
    for sub in ('meshes/a', 'elsewhere'):
        os.makedirs(os.path.join(root, sub))
    ico.export(os.path.join(root, 'meshes', 'a', 'x.obj'))
    trimesh.creation.icosphere(1).export(os.path.join(root, 'elsewhere',
                                                      'y.off'))
    os.symlink(os.path.join(root, 'elsewhere'),
               os.path.join(root, 'meshes', 'linked'))
    # a user's own folder, and earlier results
    os.makedirs(os.path.join(root, 'mine'))
    open(os.path.join(root, 'mine', 'thesis.tex'), 'w').write('mine')
    with contextlib.redirect_stderr(io.StringIO()), \
            contextlib.redirect_stdout(io.StringIO()):
        assert main(['solve', os.path.join(root, 'ico.obj'), '--smooth',
                     '1e-3', '--out', os.path.join(root, 'earlier'),
                     '--quiet']) == 0
        assert main(['precompute', 'mls', os.path.join(root, 'meshes'),
                     os.path.join(root, 'cache'), '--k', '3',
                     '--quiet']) == 0
        assert main(['train', 'deltanet', '--out', os.path.join(
            root, 'run')] + TINY_TRAINING) == 0
        assert main(['train', 'deltanet', '--out', os.path.join(
            root, 'truncated')] + TINY_TRAINING) == 0
        assert main(['svbrdf', '--write-example',
                     os.path.join(root, 'scene'), '--example-views', '4',
                     '--example-image-size', '16',
                     '--example-subdivisions', '1', '--quiet']) == 0

        assert main(['svbrdf', os.path.join(root, 'scene'), '--out',
                     os.path.join(root, 'maps'), '--quiet']) == 0
    checkpoint = os.path.join(root, 'truncated', 'checkpoint.pt')
    with open(checkpoint, 'rb') as f:
        half = f.read()[:1000]
    with open(checkpoint, 'wb') as f:
        f.write(half)
    make_round_two_files(root, ico)
    for split in ('train', 'test'):  # a folder of one class
        os.makedirs(os.path.join(root, 'one_class', 'ball', split))
        for k in range(2):
            trimesh.creation.icosphere(1).export(os.path.join(
                root, 'one_class', 'ball', split, f'{k}.obj'))


def make_round_two_files(root: str, ico):
    """Files of the second sweep (issue 40): links to output folders,
    files with a byte-order mark, coloured meshes, two objects in one OBJ,
    a user's files beside precompute's results."""
    os.makedirs(os.path.join(root, 'scratch'))
    os.makedirs(os.path.join(root, 'folder.pt'))
    os.symlink('scratch', os.path.join(root, 'runs'))   # relative: copies
    os.symlink('earlier', os.path.join(root, 'earlier_link'))
    obj = open(os.path.join(root, 'ico.obj')).read()
    vertices_first = ''.join(line + '\n' for line in obj.splitlines()
                             if line.startswith('v ')) + ''.join(
        line + '\n' for line in obj.splitlines() if line.startswith('f '))
    bom = '\ufeff'
    open(os.path.join(root, 'bom.obj'), 'w', encoding='utf-8').write(
        bom + vertices_first)
    open(os.path.join(root, 'bom.off'), 'w', encoding='utf-8').write(
        bom + open(os.path.join(root, 'ico.off')).read())
    open(os.path.join(root, 'bom_ascii.ply'), 'w', encoding='utf-8').write(
        bom + open(os.path.join(root, 'ascii.ply')).read())
    second = trimesh.creation.icosphere(2)
    second.apply_translation([3, 0, 0])
    two = trimesh.Scene({'first': ico, 'second': second})
    two.export(os.path.join(root, 'two_objects.obj'))
    n = len(ico.vertices)
    colours = np.arange(3 * n).reshape(n, 3) % 256
    write_ply(os.path.join(root, 'colours.ply'), ico.vertices + 0.0,
              ico.faces, properties={
                  'red': colours[:, 0].astype(np.uint8),
                  'green': colours[:, 1].astype(np.uint8),
                  'blue': colours[:, 2].astype(np.uint8),
                  'nx': ico.vertex_normals[:, 0],
                  'ny': ico.vertex_normals[:, 1],
                  'nz': ico.vertex_normals[:, 2],
                  'quality': np.linspace(0, 1, n)})
    flat = np.vstack([ico.vertices, ico.vertices[:1]])
    trimesh.Trimesh(flat, np.vstack([ico.faces, [[0, 1, n]]]),
                    process=False).export(
        os.path.join(root, 'degenerate.obj'))
    with contextlib.redirect_stderr(io.StringIO()), \
            contextlib.redirect_stdout(io.StringIO()):
        assert main(['precompute', 'mls', os.path.join(root, 'meshes'),
                     os.path.join(root, 'kept'), '--k', '3',
                     '--quiet']) == 0
    import torch
    torch.save({'labels': 1}, os.path.join(root, 'kept', 'labels.pt'))
    os.makedirs(os.path.join(root, 'kept', 'mine'))
    torch.save({'notes': 1}, os.path.join(root, 'kept', 'mine', 'notes.pt'))


# ---------------------------------------------------------------- checks
def snapshot(root: str) -> dict:
    """Every file under ``root``: relative path -> sha1."""
    found = {}
    for folder, dirs, files in os.walk(root):
        for name in files:
            path = os.path.join(folder, name)
            with open(path, 'rb') as f:
                found[os.path.relpath(path, root)] = hashlib.sha1(
                    f.read()).hexdigest()
    return found


def out_folder(argv):
    for option in ('--out', '--write-example'):
        if option in argv:
            return argv[argv.index(option) + 1]
    if argv[:1] == ['precompute'] and len(argv) > 3:
        return argv[3]
    return None


def named(line: str, argv) -> bool:
    """The error line names one of the user's options or files."""
    words = [a for a in argv if a.startswith('--')] + \
        [os.path.basename(a.rstrip('/')) for a in argv if '/' in a]
    if not any(words):  # nothing given: the message names what is missing
        return '--' in line or 'argument' in line or any(
            w.isupper() and len(w) > 2 for w in line.replace(':', ' ').split())
    return 'argument ' in line or any(w and w in line for w in words)


def vertices_of(path):
    from tg_intrinsic.io import read_surface
    return len(read_surface(path, weld=False)[0])


# ---------------------------------------------------------------- cases
def cases():
    """(argv with {} for the sandbox, expected exit code, check of a
    success or None)."""
    S = ['solve']
    ok_solve = {'report.json', 'result.ply', 'result.png'}

    def solve_ok(count):
        def check(root, out):
            return ok_solve <= set(os.listdir(out)) and \
                vertices_of(os.path.join(out, 'result.ply')) == count
        return check
    yield S + ['{}/ico.obj', '--smooth', '1e-3', '--out', '{}/o'], 0, \
        solve_ok(162)
    for name in ('ico.stl', 'soup.obj', 'ascii.ply', 'ico.off'):
        yield S + [f'{{}}/{name}', '--smooth', '1e-3', '--out', '{}/o'], \
            0, solve_ok(162)
    yield S + ['{}/ascii.ply', '--poisson', '1', '--signal', 'heat',
               '--out', '{}/o'], 0, solve_ok(162)
    yield S + ['{}/soup.obj', '--smooth', '1e-3', '--signal',
               '{}/stored.npy', '--out', '{}/o'], 0, solve_ok(162)
    yield S + ['{}/three.obj', '--smooth', '1e-3', '--out', '{}/o'], 0, \
        solve_ok(4)
    yield S + ['{}/cloud.ply', '--poisson', '1', '--signal', 'q',
               '--out', '{}/o'], 0, solve_ok(162)
    yield S + ['{}/ico.obj', '--smooth', '1e-3', '--out', '{}/earlier'], \
        0, solve_ok(162)
    yield S + ['{}/ico.obj', '--smooth', '1e-3', '--out', '{}/mine',
               '--overwrite'], 0, \
        lambda root, out: os.path.exists(os.path.join(out, 'thesis.tex'))
    for bad in ('nan_ascii.ply', 'one.obj', 'two.obj', 'garbage.obj',
                'empty.off', 'repeat.obj', 'past.off', 'missing.obj',
                'folder.obj', 'notes.txt', 'mesh.xyz'):
        yield S + [f'{{}}/{bad}', '--smooth', '1', '--out', '{}/o'], 2, None
    for signal in ('{}/short.npy', '{}/cube.npy', '{}/nan.npy', 'nothing',
                   '{}/missing.npy', '{}/ascii.ply:nope'):
        yield S + ['{}/ico.obj', '--smooth', '1', '--signal', signal,
                   '--out', '{}/o'], 2, None
    for value in ('1e300', '-1', '0', 'nan', 'inf', 'x'):
        yield S + ['{}/ico.obj', '--smooth', value, '--out', '{}/o'], 2, \
            None
    yield S + ['{}/ico.obj', '--poisson', '1e-300', '--signal',
               '{}/sig.npy', '--out', '{}/o'], 2, None
    yield S + ['{}/ico.obj', '--smooth', '1', '--ratio', '1', '--out',
               '{}/o'], 2, None
    yield S + ['{}/earlier/result.ply', '--smooth', '1', '--out',
               '{}/earlier'], 2, None
    yield S + ['{}/ico.obj', '--smooth', '1', '--out', '{}/mine'], 2, None
    yield S + ['{}/ico.obj', '--smooth', '1', '--out', '{}/notes.txt'], 2, \
        None
    yield S + ['{}/cloud.ply', '--conformal-flow', '1e-3', '--out',
               '{}/o'], 2, None
    yield S + ['{}/ico.obj', '--conformal-flow', '1e-3', '--steps', '2',
               '--out', '{}/o'], 0, solve_ok(162)

    for name in ('quads.obj', 'negative.obj', 'CAPS.OBJ',
                 'with space.obj', 'normals.ply'):
        count = {'quads.obj': 8, 'negative.obj': 4}.get(name, 162)
        yield S + [f'{{}}/{name}', '--smooth', '1e-3', '--out', '{}/o'], \
            0, solve_ok(count)
    for signal in ('{}/sig.txt', '{}/sig.csv', '{}/ascii.ply:heat'):
        yield S + ['{}/ico.obj', '--smooth', '1e-3', '--signal', signal,
                   '--out', '{}/o'], 0, solve_ok(162)
    yield S + ['{}/ico.obj', '--smooth', '1e-3', '--out', '{}/a/b/c'], 0, \
        solve_ok(162)
    yield S + ['{}/ico.obj', '--smooth', '1e-3', '--out', '{}/o/'], 0, \
        solve_ok(162)
    yield S + ['{}/ico.obj', '--smooth', '1e-3', '--bilaplacian', '1e-6',
               '--method', 'pcg', '--out', '{}/o'], 0, solve_ok(162)
    yield S + ['{}/ico.obj', '--smooth', '1e-3', '--cycle', 'W',
               '--out', '{}/earlier'], 0, solve_ok(162)
    for bad in ('nan_binary.ply', 'quads.stl'):
        yield S + [f'{{}}/{bad}', '--smooth', '1', '--out', '{}/o'], 2, None
    yield S + ['{}/ico.obj', '--smooth', '1e-3', '--signal',
               '{}/cloud.ply:q', '--out', '{}/o'], 0, solve_ok(162)
    for signal in ('{}/words.txt', '{}/folder.obj', '{}/notes.txt'):
        yield S + ['{}/ico.obj', '--smooth', '1', '--signal', signal,
                   '--out', '{}/o'], 2, None
    for option, value in (('--steps', '0'), ('--tol', '0'),
                          ('--max-cycles', '0'), ('--cycle', 'X'),
                          ('--lower-bound', '0'), ('--method', 'lu'),
                          ('--ratio', '-2'), ('--tol', 'inf')):
        yield S + ['{}/ico.obj', '--smooth', '1', option, value, '--out',
                   '{}/o'], 2, None
    yield S + ['{}/ico.obj', '--bilaplacian', '1', '--poisson', '1',
               '--signal', '{}/sig.npy', '--out', '{}/o'], 2, None
    yield S + ['{}/ico.obj', '--smooth', '1', '--poisson', '1',
               '--out', '{}/o'], 2, None
    yield S + ['{}/ico.obj', '--smooth', '1', '--out', '{}/o', '--bogus'], \
        2, None
    yield S + ['{}/ico.obj', '--smooth', '1', '--out', '{}'], 2, None
    yield S + ['{}/ico.obj', '--smooth', '1', '--out', '{}/mine/sub'], \
        0, solve_ok(162)

    for name, count in (('loose.obj', None), ('huge.obj', 162),
                        ('fin.obj', 163), ('kugel-ä.obj', 162),
                        ('quads.off', 8)):
        yield S + [f'{{}}/{name}', '--smooth', '1e-3', '--out', '{}/o'], \
            (2 if count is None else 0), \
            (None if count is None else solve_ok(count))
    yield S + ['{}/huge.obj', '--smooth', '1e13', '--out', '{}/o'], 0, \
        solve_ok(162)
    yield S + ['{}/ico.obj', '--smooth', '1', '--signal', '{}/ico.obj',
               '--out', '{}/o'], 2, None

    P = ['precompute']

    def manifest(**expected):
        def check(root, out):
            with open(os.path.join(out, 'precompute.json')) as f:
                settings = json.load(f)['settings']
            return all(settings[k] == v for k, v in expected.items())
        return check
    yield P + ['mls', '{}/meshes', '{}/p', '--k', '4'], 0, manifest(k=4)
    yield P + ['mls', '{}/meshes', '{}/cache', '--k', '3'], 0, \
        manifest(k=3)
    yield P + ['mls', '{}/meshes', '{}/cache', '--k', '5',
               '--overwrite'], 0, manifest(k=5)
    yield P + ['mls', '{}/meshes', '{}/cache', '--k', '500',
               '--overwrite'], 2, None
    yield P + ['mls', '{}/meshes', '{}/cache', '--k', '5'], 2, None
    yield P + ['gravo', '{}/meshes', '{}/mine'], 2, None
    yield P + ['gravo', '{}/ico.stl', '{}/g.pt', '--lower-bound', '10'], \
        0, lambda root, out: os.path.getsize(out) > 0
    yield P + ['hsn', '{}/cloud.ply', '{}/h'], 2, None
    yield P + ['mls', '{}/missing', '{}/p'], 2, None
    yield P + ['mls', '{}/meshes', '{}/p.pt'], 2, None
    yield P + ['mls', '{}/notes.txt', '{}/p'], 2, None
    yield P + ['gravo', '{}/meshes', '{}/p', '--ratio', '1'], 2, None
    yield P + ['logmap', '{}/repeat.obj', '{}/p'], 2, None
    yield P + ['mls', '{}/cloud.ply', '{}/p', '--normal-k', '500'], 2, None
    yield P + ['mls', '{}/normals.ply', '{}/p', '--normal-k', '500'], 0, \
        manifest(normal_k=500)
    yield P + ['mls', '{}/zero_normals.ply', '{}/p'], 2, None
    yield P + ['mls', '{}/empty', '{}/p'], 2, None
    yield P + ['mls', '{}/only_text', '{}/p'], 2, None
    yield P + ['mls', '{}/meshes', '{}/meshes'], 2, None
    yield P + ['mls', '{}/meshes', '{}/meshes/out'], 0, manifest(k=20)
    yield P + ['gravo', '{}/meshes', '{}/p', '--workers', '2',
               '--lower-bound', '10'], 0, manifest(lower_bound=10)
    yield P + ['gravo', '{}/soup.obj', '{}/p', '--dtype', 'float64',
               '--lower-bound', '10'], 0, manifest(dtype='float64')
    yield P + ['gravo', '{}/meshes', '{}/cache'], 2, None
    yield P + ['logmap', '{}/ico.obj', '{}/p', '--radius', '0'], 2, None
    yield P + ['hsn', '{}/ico.obj', '{}/p', '--rings', '0'], 2, None
    yield P + ['hsn', '{}/ico.obj', '{}/p', '--max-order', '-1'], 2, None
    yield P + ['mls', '{}/meshes', '{}/p', '--dtype', 'float16'], 2, None
    yield P + ['mls', '{}/meshes', '{}/notes.txt'], 2, None
    yield P + ['mls', '{}/meshes', '{}/p', '--workers', '0'], 2, None
    yield P + ['bogus', '{}/meshes', '{}/p'], 2, None
    yield P + ['gravo', '{}/ico.obj', '{}/cache', '--overwrite',
               '--lower-bound', '10'], 0, manifest(lower_bound=10)
    yield ['info', '--json'], 0, None

    V = ['svbrdf']
    yield V + ['--write-example', '{}/mine'], 2, None
    yield V + ['--write-example', '{}/scene', '--example-views', '4',
               '--example-image-size', '16', '--example-subdivisions',
               '1'], 0, lambda root, out: os.path.exists(
                   os.path.join(out, 'cameras.json'))
    yield V + ['{}/scene', '--out', '{}/scene'], 2, None
    yield V + ['{}/scene', '--out', '{}/scene/images'], 2, None
    yield V + ['{}/missing', '--out', '{}/v'], 2, None
    yield V + ['{}/scene', '--out', '{}/v', '--device', 'bogus'], 2, None
    yield V + ['{}/scene', '--out', '{}/v', '--l-max', '60'], 2, None
    yield V + ['{}/scene', '--out', '{}/mine'], 2, None
    yield V + ['{}/scene', '--out', '{}/v'], 0, \
        lambda root, out: os.path.exists(os.path.join(out, 'maps.npz'))
    yield V + ['--write-example', '{}/notes.txt'], 2, None
    yield V + ['{}/scene', '--write-example', '{}/w'], 2, None
    yield V + ['--write-example', '{}/w', '--out', '{}/v'], 2, None
    yield V + ['--write-example', '{}/w', '--example-views', '0'], 2, None
    yield V + ['{}/scene', '--example-views', '3', '--out', '{}/v'], 2, None
    yield V + ['{}/meshes', '--out', '{}/v'], 2, None
    yield V + ['{}/ico.obj', '--out', '{}/v'], 2, None
    for option, value in (('--refine', '-1'), ('--tv-weight', '-1'),
                          ('--metallic', '2'), ('--dtype', 'float16'),
                          ('--l-max', '-1'), ('--device', 'cuda:7')):
        yield V + ['{}/scene', '--out', '{}/v', option, value], 2, None
    yield V, 2, None

    yield ['info', '--bogus'], 2, None
    yield ['bogus'], 2, None
    yield [], 2, None
    yield ['demo', '--only', 'everything'], 2, None
    yield ['demo', '--out', '{}/notes.txt', '--quick'], 2, None
    yield ['demo', '--out', '{}/mine', '--quick'], 2, None

    T = ['train']
    tiny = TINY_TRAINING

    def epochs(count):
        def check(root, out):
            with open(os.path.join(out, 'metrics.json')) as f:
                return len(json.load(f)['history']) == count
        return check
    yield T + ['deltanet', '--out', '{}/t'] + tiny, 0, epochs(1)
    yield T + ['deltanet', '--out', '{}/run'] + tiny, 2, None
    yield T + ['deltanet', '--out', '{}/run', '--overwrite'] + tiny, 0, \
        epochs(1)
    yield T + ['deltanet', '--out', '{}/run', '--resume'] + tiny + [
        '--lr', '0.5', '--num-points', '128'], 2, None
    yield T + ['deltanet', '--out', '{}/run', '--resume'] + tiny + [
        '--epochs', '2'], 2, None
    yield T + ['deltanet', '--out', '{}/run', '--resume', '--allow-changes',
               'epochs'] + tiny + ['--epochs', '2'], 0, epochs(2)
    yield T + ['deltanet', '--out', '{}/run', '--resume', '--allow-changes',
               'lr'] + tiny, 2, None
    yield T + ['hsn', '--out', '{}/run', '--resume'] + tiny, 2, None
    yield T + ['deltanet', '--out', '{}/truncated', '--resume'] + tiny, 2, \
        None
    yield T + ['deltanet', '--out', '{}/t', '--resume'] + tiny, 0, \
        epochs(1)
    yield T + ['deltanet', '--out', '{}/t'] + tiny + ['--batch-size', '1'], \
        2, None
    yield T + ['deltanet', '--dataset', '{}/one_class', '--out',
               '{}/t'] + tiny, 2, None
    yield T + ['deltanet', '--out', '{}/t', '--device', 'cuda'] + tiny, 2, \
        None
    yield T + ['deltanet', '--out', '{}/notes.txt'] + tiny, 2, None
    yield T + ['deltanet', '--out', '{}/mine'] + tiny, 2, None
    yield T + ['deltanet', '--device', 'bogus', '--out', '{}/t'] + tiny, \
        2, None
    yield T + ['deltanet', '--dataset', '{}/missing', '--out',
               '{}/t'] + tiny, 2, None
    yield T + ['deltanet', '--lr', '-1', '--out', '{}/t'] + tiny, 2, None
    yield T + ['hsn', '--resume', '--out', '{}/earlier'] + tiny, 2, None
    yield T + ['deltanet', '--out', '{}/t'] + tiny + ['--epochs', '0'], 2, \
        None
    yield T + ['deltanet', '--dataset', '{}/meshes', '--out', '{}/t'] + \
        tiny, 2, None
    yield T + ['deltanet', '--dataset', '{}/empty', '--out', '{}/t'] + \
        tiny, 2, None
    yield T + ['deltanet', '--dataset', '{}/ico.obj', '--out', '{}/t'] + \
        tiny, 2, None
    yield T + ['gcn', '--out', '{}/t'] + tiny, 2, None
    yield T + ['deltanet', '--protocol', 'nope', '--out', '{}/t'] + tiny, \
        2, None
    yield T + ['deltanet', '--out', '{}/meshes'] + tiny, 2, None


VERDICTS = ('allowed_exit_code', 'as_expected', 'data_kept',
            'no_stray_files', 'right_result', 'message_names_input')

# options of train that take no negative value (checked after parsing)
TRAIN_POSITIVE = ('--epochs', '--batch-size', '--num-points', '--lr', '--k',
                  '--rings', '--eval-every', '--workers', '--threads',
                  '--dropout', '--radius', '--weight-decay', '--max-order',
                  '--embedding-size', '--mlp-depth', '--gamma')


def round_two():
    """The cases of the second sweep (issue 40): links, long and odd
    names, byte-order marks, what results keep, a user's files beside
    precompute's, messages."""
    S = ['solve']
    ok = {'report.json', 'result.ply', 'result.png'}

    def solve_ok(count, link=None, keeps=()):
        def check(root, out):
            names = set(os.listdir(out))
            if not ok <= names or vertices_of(
                    os.path.join(out, 'result.ply')) != count:
                return False
            if link and not os.path.islink(os.path.join(root, link)):
                return False
            if keeps:
                from tg_intrinsic.io import read_surface
                properties = read_surface(os.path.join(out, 'result.ply'),
                                          weld=False)[2]
                return set(keeps) <= set(properties)
            return True
        return check
    for link in ('runs', 'earlier_link'):
        yield S + ['{}/ico.obj', '--smooth', '1e-3', '--out',
                   f'{{}}/{link}'], 0, solve_ok(162, link)
    yield ['precompute', 'mls', '{}/meshes', '{}/runs', '--k', '4'], 0, \
        lambda root, out: os.path.islink(os.path.join(root, 'runs')) and \
        os.path.exists(os.path.join(root, 'scratch', 'precompute.json'))
    yield ['svbrdf', '{}/scene', '--out', '{}/runs'], 0, \
        lambda root, out: os.path.islink(os.path.join(root, 'runs')) and \
        os.path.exists(os.path.join(root, 'scratch', 'maps.npz'))
    yield ['train', 'deltanet', '--out', '{}/runs'] + TINY_TRAINING, 0, \
        lambda root, out: os.path.islink(os.path.join(root, 'runs')) and \
        os.path.exists(os.path.join(root, 'scratch', 'checkpoint.pt'))
    # a user's files beside precompute's results survive --overwrite
    yield ['precompute', 'mls', '{}/meshes', '{}/kept', '--k', '8',
           '--overwrite'], 0, lambda root, out: all(os.path.exists(
               os.path.join(out, name)) for name in (
               'labels.pt', os.path.join('mine', 'notes.pt'), 'a/x.pt'))
    yield ['precompute', 'mls', '{}/meshes', '{}/kept', '--k', '3'], 2, \
        None
    # names: too long for the file system, long, odd
    yield S + ['{}/ico.obj', '--smooth', '1', '--out', '{}/' + 'x' * 300], \
        2, None
    yield S + ['{}/ico.obj', '--smooth', '1e-3', '--out', '{}/' + 'y' * 250],\
        0, solve_ok(162)
    yield ['precompute', 'mls', '{}/ico.obj', '{}/' + 'z' * 300 + '.pt'], \
        2, None
    yield S + ['{}/ico.obj', '--smooth', '1e-3', '--out',
               '{}/odd name ü\t#1'], 0, solve_ok(162)
    yield ['svbrdf', '--write-example', '{}/' + 'w' * 300], 2, None
    # a byte-order mark (Notepad's) in every text format
    for name in ('bom.obj', 'bom.off', 'bom_ascii.ply'):
        yield S + [f'{{}}/{name}', '--smooth', '1e-3', '--out', '{}/o'], \
            0, solve_ok(162)
    # what the results keep: two objects, colours, normals, properties
    yield S + ['{}/two_objects.obj', '--smooth', '1e-3', '--out', '{}/o'], \
        0, solve_ok(324)
    yield S + ['{}/colours.ply', '--smooth', '1e-3', '--signal',
               '{}/colours.ply:quality', '--out', '{}/o'], 0, \
        solve_ok(162, keeps=('red', 'green', 'blue', 'nx', 'ny', 'nz',
                             'quality'))
    # fairing moves the vertices: their old normals are left out
    yield S + ['{}/colours.ply', '--smooth', '1e-3', '--out', '{}/o'], 0, \
        solve_ok(162, keeps=('red', 'green', 'blue', 'quality'))
    # messages that name the file or the option
    yield S + ['{}/degenerate.obj', '--smooth', '1', '--out', '{}/o'], 2, \
        None
    yield S + ['/proc/nope', '--smooth', '1', '--out', '{}/o'], 2, None
    yield S + ['{}/ico.obj', '--smooth', '1', '--signal', '{}/empty',
               '--out', '{}/o'], 2, None
    yield ['precompute', 'mls', '{}/ico.obj', '{}/folder.pt', '--k',
           '4'], 2, None
    yield ['precompute', 'mls', '{}/meshes', '{}/p', '--normal-k', '1'], 2, \
        None
    yield ['train', 'deltanet', '--out', '{}/t'] + TINY_TRAINING + [
        '--num-points', '2'], 2, None


def interrupted():
    """Ctrl-C while each command writes its results (the named function
    raises KeyboardInterrupt): exit 130 and the earlier results kept."""
    yield (['solve', '{}/ico.obj', '--smooth', '1', '--out', '{}/earlier'],
           130, None, ('tg_intrinsic.io.figures', 'draw_surface'))
    yield (['precompute', 'mls', '{}/meshes', '{}/cache', '--k', '4',
            '--overwrite'], 130, None,
           ('tg_intrinsic.cli.precompute', 'precompute_file'))
    yield (['svbrdf', '{}/scene', '--out', '{}/maps'], 130, None,
           ('tg_intrinsic.io', 'write_ply'))
    yield (['svbrdf', '--write-example', '{}/scene'], 130, None,
           ('tg_intrinsic.io', 'write_scene'))


def every_numeric_option():
    """Each numeric option of every sub-command (found in the parser) with
    values no such option takes: text, and for the options declared
    positive or non-negative, a negative number."""
    from tg_intrinsic.cli import build_parser
    from tg_intrinsic.cli import common
    checked = {common.positive_float, common.positive_int,
               common.nonnegative_float, common.nonnegative_int}
    base = {'solve': ['solve', '{}/ico.obj', '--smooth', '1', '--out',
                      '{}/o'],
            'svbrdf': ['svbrdf', '{}/scene', '--out', '{}/v'],
            'train': ['train', 'deltanet', '--out', '{}/t'] + TINY_TRAINING,
            'demo': ['demo', '--out', '{}/d', '--quick']}
    parser = build_parser()
    commands = next(a for a in parser._actions
                    if a.dest == 'command').choices
    for name, command in commands.items():
        groups = [(base.get(name), command)]
        if name == 'precompute':
            kinds = next(a for a in command._actions
                         if a.dest == 'kind').choices
            groups = [(['precompute', kind, '{}/meshes', '{}/p'], sub)
                      for kind, sub in kinds.items()]
        for argv, sub in groups:
            if argv is None:
                continue
            for action in sub._actions:
                if action.type in (None, str) or not action.option_strings \
                        or action.nargs not in (None, 1):
                    continue
                option = action.option_strings[-1]
                values = ['x'] + (['-1'] if action.type in checked or (
                    name == 'train' and option in TRAIN_POSITIVE) else [])
                for value in values:
                    yield argv + [option, value], 2, None


CONCURRENT = {
    'solve': (['solve', '{}/ico.obj', '--smooth', '1e-3', '--out',
               '{}/same'], 4),
    'precompute': (['precompute', 'gravo', '{}/meshes', '{}/same',
                    '--lower-bound', '10'], 3),
    'svbrdf': (['svbrdf', '{}/scene', '--out', '{}/same', '--refine', '0'],
               2),
}


def concurrent_runs(base, trials: int = 3):
    """Several processes of one command into one output folder at once:
    one run writes it, the others stop with exit 2 naming it; the folder
    then holds every file its record lists, and no staging is left."""
    import subprocess
    from tg_intrinsic.io.results import RECORD
    results = []
    for command, (template, count) in CONCURRENT.items():
        for trial in range(trials):
            root = tempfile.mkdtemp(prefix='sweep-')
            shutil.rmtree(root)
            shutil.copytree(base, root, symlinks=True)
            argv = [a.replace('{}', root) for a in template]
            before = snapshot(root)
            start = time.perf_counter()
            runs = [subprocess.Popen(
                [sys.executable, '-m', 'tg_intrinsic', '--quiet'] + argv,
                stdout=subprocess.DEVNULL, stderr=subprocess.PIPE,
                text=True) for _ in range(count)]
            said = [run.communicate(timeout=900)[1] for run in runs]
            seconds = time.perf_counter() - start
            out = os.path.join(root, 'same')
            record = os.path.join(out, RECORD if command != 'precompute'
                                  else 'precompute.json')
            try:
                with open(record) as f:
                    listed = json.load(f)['files']
                whole = all(os.path.exists(os.path.join(out, name))
                            for name in listed)
            except (OSError, ValueError, KeyError):
                whole = False
            after = snapshot(root)
            changed = [name for name, digest in before.items()
                       if after.get(name) != digest]
            stray = [name for name in os.listdir(root)
                     if name.startswith('.')]
            winners = sum(run.returncode == 0 for run in runs)
            for run, stderr in zip(runs, said):
                lines = stderr.strip().splitlines()
                message = lines[-1] if lines else ''
                results.append({
                    'argv': [a.replace(root, '{}') for a in argv],
                    'exit_code': run.returncode, 'expected': 'one 0, rest 2',
                    'message': message.replace(root, '{}'),
                    'seconds': round(seconds, 2),
                    'allowed_exit_code': run.returncode in (0, 2, 130),
                    'as_expected': winners >= 1 and (
                        run.returncode == 0 or 'is being written by another '
                        'run' in message),
                    'data_kept': not changed, 'changed': changed,
                    'no_stray_files': not stray, 'stray': stray[:5],
                    'right_result': whole,
                    'message_names_input': run.returncode != 2 or
                    named(message, argv),
                    'interrupted': False, 'concurrent': count})
            shutil.rmtree(root, ignore_errors=True)
    return results


def run_case(base, template, expected, check, interrupt=None):
    """Runs one case in a copy of the sandbox ``base`` (``interrupt``:
    ``(module, name)`` of a function that then raises KeyboardInterrupt)."""
    import importlib
    from unittest import mock
    root = tempfile.mkdtemp(prefix='sweep-')
    shutil.rmtree(root)
    shutil.copytree(base, root, symlinks=True)
    # links point into the copy
    link = os.path.join(root, 'meshes', 'linked')
    os.remove(link)
    os.symlink(os.path.join(root, 'elsewhere'), link)
    argv = [a.replace('{}', root) for a in template]
    before = snapshot(root)
    stderr = io.StringIO()
    start = time.perf_counter()

    def ctrl_c(*args, **kwargs):
        raise KeyboardInterrupt
    patch = contextlib.nullcontext() if interrupt is None else \
        mock.patch.object(importlib.import_module(interrupt[0]),
                          interrupt[1], ctrl_c)
    with contextlib.redirect_stderr(stderr), \
            contextlib.redirect_stdout(io.StringIO()), patch:
        try:
            code = main(argv)
        except BaseException as error:  # noqa: BLE001 - recorded
            code = f'raised {type(error).__name__}'
    seconds = time.perf_counter() - start
    after = snapshot(root)
    out = out_folder(argv)
    # a linked output folder is written through: its target is the region
    out_rel = None if out is None else os.path.relpath(
        os.path.realpath(out), os.path.realpath(root))
    lines = [ln for ln in stderr.getvalue().splitlines()
             if ': error:' in ln or 'unexpected' in ln or
             'interrupted' in ln]
    message = lines[-1] if lines else ''
    # a failed run changes nothing; a successful one only its --out
    changed = [name for name, digest in before.items()
               if after.get(name) != digest and not (
                   code == 0 and out_rel is not None and
                   (name == out_rel or name.startswith(out_rel + os.sep))
                   and not name.startswith(os.path.join(out_rel, 'thesis')))]
    # new files: a success's results; precompute, which resumes file by
    # file, also records its settings and failures in a failed run's
    # output folder (or, for --overwrite, the staging folder beside it)
    precompute = argv[:1] == ['precompute']
    regions = [] if out_rel is None else [out_rel] if code == 0 or \
        not precompute else \
        [out_rel, os.path.join(os.path.dirname(out_rel),
                               f'.{os.path.basename(out_rel)}.overwrite')]
    if code != 0 and not precompute:
        regions = []
    # (folder data sets cache what they read under train's --root, not
    # beside the data)
    stray = [name for name in after if name not in before and
             not any(name == r or name.startswith(r + os.sep)
                     for r in regions)]
    result = {
        'argv': [a.replace(root, '{}') for a in argv],
        'exit_code': code, 'expected': expected,
        'message': message.replace(root, '{}'),
        'seconds': round(seconds, 2),
        'allowed_exit_code': code in (0, 2, 130),
        'as_expected': code == expected,
        'data_kept': not changed, 'changed': changed,
        'no_stray_files': not stray, 'stray': stray[:5],
        'right_result': code != 0 or check is None or bool(check(root, out)),
        'message_names_input': code != 2 or named(message, argv),
        'interrupted': interrupt is not None,
    }
    shutil.rmtree(root, ignore_errors=True)
    return result


def plot(results, counts):
    """cli_sweep.png: the cases of every sub-command by exit code, and
    the verdicts over all of them."""
    import matplotlib
    matplotlib.use('Agg')
    import matplotlib.pyplot as plt
    from tg_intrinsic.io.figures import save_figure
    commands = sorted({(r['argv'] or ['(none)'])[0] for r in results})
    fig, ax = plt.subplots(figsize=(7, 3.6))
    bottom = np.zeros(len(commands))
    for code, colour in ((0, '#4c9a5f'), (2, '#4f7cba'), (130, '#d08c3f')):
        height = np.array([sum(r['exit_code'] == code for r in results
                               if (r['argv'] or ['(none)'])[0] == c)
                           for c in commands])
        ax.bar(commands, height, bottom=bottom, color=colour,
               label=f'exit {code}' + {0: ' (a result)',
                                       2: ' (a user mistake, one line)',
                                       130: ' (Ctrl-C while writing)'}[code])
        bottom += height
    ax.set_ylabel('cases')
    ax.set_title(f"{counts['cases']} command lines: {counts['data_loss']} "
                 f"lost files, {counts['wrong_results']} wrong results, "
                 f"{counts['other_exit_codes']} other exit codes",
                 fontsize=10)
    ax.legend(frameon=False)
    save_figure(fig, RESULTS.replace('.json', '.png'))


def main_sweep():
    base = tempfile.mkdtemp(prefix='sweep-base-')
    make_files(base)
    results = []
    for case in list(cases()) + list(round_two()) + list(interrupted()) + \
            list(every_numeric_option()):
        result = run_case(base, *case)
        results.append(result)
        verdict = all(result[k] for k in VERDICTS)
        print(f"{'ok ' if verdict else 'BAD'} {result['exit_code']!s:>3} "
              f"{' '.join(result['argv'])[:90]}", flush=True)
        if not verdict:
            print(f"      {result}", flush=True)
    for result in concurrent_runs(base):
        results.append(result)
        print(f"{'ok ' if all(result[k] for k in VERDICTS) else 'BAD'} "
              f"{result['exit_code']!s:>3} x{result['concurrent']} "
              f"{' '.join(result['argv'])[:85]}", flush=True)
    shutil.rmtree(base, ignore_errors=True)
    counts = {
        'cases': len(results),
        'exit_0': sum(r['exit_code'] == 0 for r in results),
        'exit_2': sum(r['exit_code'] == 2 for r in results),
        'exit_130': sum(r['exit_code'] == 130 for r in results),
        'other_exit_codes': sum(not r['allowed_exit_code']
                                for r in results),
        'unexpected_exit_codes': sum(not r['as_expected'] for r in results),
        'data_loss': sum(not r['data_kept'] for r in results),
        'stray_files': sum(not r['no_stray_files'] for r in results),
        'wrong_results': sum(not r['right_result'] for r in results),
        'messages_not_naming_the_input': sum(
            not r['message_names_input'] for r in results),
    }
    print(json.dumps(counts, indent=1))
    atomic_write_json(RESULTS, {'counts': counts, 'cases': results,
                                'machine': machine_info()})
    plot(results, counts)
    bad = sum(v for k, v in counts.items()
              if k not in ('cases', 'exit_0', 'exit_2', 'exit_130'))
    return 1 if bad else 0


if __name__ == '__main__':
    sys.exit(main_sweep())
