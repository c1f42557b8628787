"""``tg-intrinsic svbrdf``: the example scene, the recovery and its
outputs, and one-line errors with exit code 2 on bad input. The scene is
tiny (162 points, 8 views of 32 x 32) and the fits are a few steps: these
check the plumbing, not the accuracy (tests/test_svbrdf_end_to_end.py)."""
import json
import os
import shutil
import subprocess
import sys

import numpy as np
import pytest
import torch

from tg_intrinsic.cli import main
from tg_intrinsic.io import read_scene, read_surface
from tg_intrinsic.io.results import RECORD

TINY = ['--example-views', '8', '--example-image-size', '32',
        '--example-subdivisions', '2']
MAPS = ('base_color', 'metallic', 'roughness', 'entropy', 'roughness_std')


def run(argv):
    """The exit code of ``main``."""
    return main(argv)


@pytest.fixture(scope='module')
def scene(tmp_path_factory):
    folder = tmp_path_factory.mktemp('svbrdf') / 'scene'
    assert run(['svbrdf', '--write-example', str(folder), '--quiet']
               + TINY) == 0
    return folder


def one_line_error(capsys, *words):
    err = capsys.readouterr().err.strip()
    assert err.startswith('tg-intrinsic svbrdf: error: '), err
    assert '\n' not in err and 'Traceback' not in err, err
    for word in words:
        assert word in err, err
    return err


def test_example_is_a_scene_folder(scene):
    names = sorted(os.listdir(scene))
    assert {'cameras.json', 'geometry.ply', 'ground_truth.npz', 'images',
            'README.txt'} <= set(names)
    assert any(n.startswith('envmap.') for n in names)
    assert len(os.listdir(scene / 'images')) == 8
    data = read_scene(scene)
    assert data.pos.shape == (162, 3) and data.images.shape == (8, 32, 32, 3)
    truth = np.load(scene / 'ground_truth.npz')
    assert truth['roughness'].shape == (162, )
    assert np.allclose(truth['pos'], data.pos.numpy())
    assert 'cameras.json' in (scene / 'README.txt').read_text()


def test_recovery_writes_maps_plys_figures_and_report(scene, tmp_path,
                                                      capsys):
    out = tmp_path / 'out'
    assert run(['svbrdf', str(scene), '--out', str(out), '--steps', '3',
                '--quiet']) == 0
    assert capsys.readouterr().out == ''  # --quiet: no summary
    names = set(os.listdir(out)) - {RECORD}
    assert names == {'maps.npz', 'report.json', 'cameras.png'} | {
        f'{m}.{e}' for m in MAPS for e in ('ply', 'png')}
    maps = np.load(out / 'maps.npz')
    assert maps['base_color'].shape == (162, 3)
    for name in MAPS[1:]:
        assert maps[name].shape == (162, )
    pos, face, properties = read_surface(out / 'roughness.ply')
    assert pos.shape == (162, 3) and face.shape == (320, 3)
    assert np.allclose(properties['roughness'], maps['roughness'])
    assert {'red', 'green', 'blue', 'nx', 'ny', 'nz'} <= set(properties)
    _, _, properties = read_surface(out / 'base_color.ply')
    assert np.allclose(np.stack([properties[f'base_color_{k}']
                                 for k in range(3)], 1), maps['base_color'])
    import matplotlib.pyplot as plt
    image = plt.imread(out / 'entropy.png')
    assert image.shape[0] > 200 and image.shape[1] > 400
    report = json.loads((out / 'report.json').read_text())
    assert report['points'] == 162 and report['views'] == 8
    assert report['triangles'] == 320
    seen = report['observations_per_point']
    assert 0 <= seen['min'] <= seen['mean'] <= seen['max'] <= 8
    # --steps asks for the SH fit before the default refinement
    assert set(report['seconds']) >= {'read', 'project', 'fit', 'refine',
                                      'write', 'total'}
    # this process's peak: torch alone holds a few hundred MB
    assert 0.1 < report['peak_memory_gib'] < 24
    assert report['pipeline']['steps'] == [
        'project', 'fit_spherical_harmonics', 'spectral_uncertainty', 'fit',
        'refine']
    assert report['pipeline']['refine']['visibility'] == 'geometry'
    assert report['options']['steps'] == 3
    assert report['options']['l_max'] == 5
    assert np.isfinite(report['loss']['refine']).all()
    assert 0 <= report['mean_entropy'] <= 1
    assert 0 < report['mean_roughness_std'] <= 1
    truth = report['ground_truth']
    for key in ('roughness_mae', 'base_color_rmse', 'metallic_mae'):
        assert 0 <= truth[key] < 1, key
    for name in ('entropy', 'roughness_std'):
        rho = truth[f'{name}_roughness_error_spearman']
        assert rho is None or -1 <= rho <= 1
    assert [n for n in os.listdir(out) if n.startswith('.')] == [RECORD]
    assert not [n for n in os.listdir(tmp_path) if n.startswith('.')]


def test_subprocess_with_options(scene, tmp_path):
    out = tmp_path / 'out'
    result = subprocess.run(
        [sys.executable, '-m', 'tg_intrinsic', 'svbrdf', str(scene),
         '--out', str(out), '--steps', '2', '--specular-model',
         'split_sum', '--metallic', '1', '--tv-weight', '0.01'],
        capture_output=True, text=True, timeout=300)
    assert result.returncode == 0, result.stderr
    assert 'roughness MAE' in result.stdout
    assert f'wrote {out}' in result.stdout
    report = json.loads((out / 'report.json').read_text())
    assert report['options']['l_max'] == 8  # split_sum's default
    assert report['options']['metallic'] == 1.0
    assert report['options']['solver'] == 'lm'
    assert np.allclose(np.load(out / 'maps.npz')['metallic'], 1.0)


def test_levenberg_marquardt_solver(scene, tmp_path):
    from tg_intrinsic.nn.frequency_svbrdf import DEFAULT_STEPS
    out = tmp_path / 'lm'
    assert run(['svbrdf', str(scene), '--out', str(out), '--solver', 'lm',
                '--quiet']) == 0
    report = json.loads((out / 'report.json').read_text())
    assert report['options']['solver'] == 'lm'
    assert report['options']['steps'] == DEFAULT_STEPS['lm']
    assert report['loss']['fit'][1] < report['loss']['fit'][0]


def test_refinement_against_the_full_integral(scene, tmp_path):
    plain, refined = tmp_path / 'plain', tmp_path / 'refined'
    assert run(['svbrdf', str(scene), '--out', str(plain), '--solver', 'lm',
                '--metallic', '1', '--refine', '0', '--quiet']) == 0
    assert run(['svbrdf', str(scene), '--out', str(refined), '--solver',
                'lm', '--metallic', '1', '--refine', '5', '--quiet']) == 0
    before = json.loads((plain / 'report.json').read_text())
    after = json.loads((refined / 'report.json').read_text())
    assert after['options']['refine'] == 5 and 'refine' in after['seconds']
    assert 'refine' not in before['seconds'] and 'refine' not in \
        before['loss']
    assert before['pipeline']['not_refined_because'] == 'not asked for'
    assert after['loss']['refine'][1] < after['loss']['refine'][0]
    # the example is rendered with the full integral: refining gets closer
    assert after['ground_truth']['roughness_mae'] \
        < before['ground_truth']['roughness_mae']


def test_bad_input_is_one_line_with_exit_code_2(scene, tmp_path, capsys):
    assert run(['svbrdf', str(tmp_path / 'nowhere'), '--out',
                str(tmp_path / 'o')]) == 2
    one_line_error(capsys, 'nowhere', 'does not exist')
    (tmp_path / 'empty').mkdir()
    assert run(['svbrdf', str(tmp_path / 'empty'), '--out',
                str(tmp_path / 'o')]) == 2
    one_line_error(capsys, 'no capture this library reads', 'no cameras.json')
    # one camera fewer than photographs
    copy = tmp_path / 'copy'
    shutil.copytree(scene, copy)
    spec = json.loads((copy / 'cameras.json').read_text())
    spec['cameras'] = spec['cameras'][:-1]
    (copy / 'cameras.json').write_text(json.dumps(spec))
    assert run(['svbrdf', str(copy), '--out', str(tmp_path / 'o')]) == 2
    one_line_error(capsys, 'lists 7 camera(s)', 'holds 8 image(s)',
                   'has no camera')
    last = sorted(os.listdir(copy / 'images'))[-1]
    os.remove(copy / 'images' / last)  # the counts agree again
    np.savez(copy / 'ground_truth.npz', roughness=np.zeros(5),
             base_color=np.zeros((5, 3)))
    assert run(['svbrdf', str(copy), '--out', str(tmp_path / 'o')]) == 2
    one_line_error(capsys, 'ground_truth.npz',
                   "'base_color' has shape [5, 3]", '162 points')
    assert run(['svbrdf', str(scene), '--steps', '-3']) == 2
    one_line_error(capsys, '--steps', 'must be at least 0')
    assert run(['svbrdf', str(scene), '--solver', 'newton']) == 2
    one_line_error(capsys, '--solver', 'newton')
    assert run(['svbrdf', str(scene), '--metallic', '2']) == 2
    one_line_error(capsys, '--metallic', 'must lie in [0, 1]')
    assert run(['svbrdf']) == 2
    one_line_error(capsys, 'give a CAPTURE')
    assert run(['svbrdf', str(scene), '--write-example', str(tmp_path)]) \
        == 2
    one_line_error(capsys, 'not both')
    assert run(['svbrdf', str(scene), '--example-views', '3']) == 2
    one_line_error(capsys, 'only go with --write-example')
    if not torch.cuda.is_available():
        assert run(['svbrdf', str(scene), '--device', 'cuda']) == 2
        one_line_error(capsys, 'no CUDA device')
    assert run(['svbrdf', str(scene), '--device', 'tpu9']) == 2
    one_line_error(capsys, '--device')
    assert not (tmp_path / 'o').exists()  # nothing written on bad input


# ------------------------------------------- result folders (io.results)
def listing(folder):
    """Every file under ``folder`` with its bytes."""
    found = {}
    for root, _, files in os.walk(folder):
        for name in files:
            path = os.path.join(root, name)
            with open(path, 'rb') as f:
                found[os.path.relpath(path, folder)] = f.read()
    return found


SMALL = ['--example-views', '4', '--example-image-size', '24',
         '--example-subdivisions', '1']


def test_write_example_keeps_a_users_files(tmp_path, capsys):
    capture = tmp_path / 'capture'
    (capture / 'images').mkdir(parents=True)
    (capture / 'cameras.json').write_text('{"cameras": "mine"}')
    (capture / 'images' / '000.exr').write_bytes(b'my photograph')
    before = listing(capture)
    assert run(['svbrdf', '--write-example', str(capture), '--quiet']
               + SMALL) == 2
    one_line_error(capsys, f"--write-example '{capture}' holds files that "
                   f"tg-intrinsic svbrdf-example did not write",
                   'cameras.json', '--overwrite')
    assert listing(capture) == before
    assert not [n for n in os.listdir(tmp_path) if n.startswith('.')]
    # --overwrite: the example's files replace those of the same name,
    # the others are kept
    (capture / 'notes.txt').write_text('keep me')
    assert run(['svbrdf', '--write-example', str(capture), '--overwrite',
                '--quiet'] + SMALL) == 0
    assert (capture / 'notes.txt').read_text() == 'keep me'
    assert read_scene(capture).images.shape[0] == 4


def test_write_example_replaces_an_earlier_example_whole(tmp_path):
    folder = tmp_path / 'example'
    assert run(['svbrdf', '--write-example', str(folder), '--quiet']
               + SMALL) == 0
    assert len(os.listdir(folder / 'images')) == 4
    assert run(['svbrdf', '--write-example', str(folder), '--quiet',
                '--example-views', '2', '--example-image-size', '24',
                '--example-subdivisions', '1']) == 0
    assert sorted(os.listdir(folder / 'images')) == ['000.exr', '001.exr'] \
        or sorted(os.listdir(folder / 'images')) == ['000.hdr', '001.hdr']
    assert read_scene(folder).images.shape[0] == 2
    assert not [n for n in os.listdir(tmp_path) if n.startswith('.')]


def test_recovery_never_writes_into_the_scene(scene, tmp_path, capsys):
    copy = tmp_path / 'scene'
    shutil.copytree(scene, copy)
    before = listing(copy)
    assert run(['svbrdf', str(copy), '--out', str(copy), '--steps', '1',
                '--quiet']) == 2
    one_line_error(capsys, f"--out '{copy}' holds the input")
    assert run(['svbrdf', str(copy), '--out', str(copy / 'images'),
                '--steps', '1', '--quiet']) == 2
    one_line_error(capsys, f"--out '{copy / 'images'}' holds the input",
                   '000.')
    assert run(['svbrdf', str(copy), '--out', str(copy / 'cameras.json'),
                '--steps', '1', '--quiet']) == 2
    one_line_error(capsys, 'cameras.json', 'is a file')
    assert run(['svbrdf', str(copy), '--out',
                str(copy / 'cameras.json' / 'out'), '--quiet']) == 2
    one_line_error(capsys, 'cannot be created', 'is a file, not a folder')
    assert listing(copy) == before


def test_recovery_outputs_appear_together(scene, tmp_path, capsys,
                                          monkeypatch):
    out = tmp_path / 'out'
    out.mkdir()
    (out / 'mine.txt').write_text('not svbrdf\'s')
    assert run(['svbrdf', str(scene), '--out', str(out), '--steps', '1',
                '--quiet']) == 2
    one_line_error(capsys, f"--out '{out}' holds files that tg-intrinsic "
                   f"svbrdf did not write (mine.txt)", '--overwrite')
    assert os.listdir(out) == ['mine.txt']
    assert run(['svbrdf', str(scene), '--out', str(out), '--steps', '1',
                '--overwrite', '--quiet']) == 0
    assert (out / 'mine.txt').read_text() == 'not svbrdf\'s'
    first = listing(out)
    assert 'maps.npz' in first and 'report.json' in first
    # a run that stops while writing (after maps.npz and a PLY) leaves the
    # results of the run before it as they were
    from tg_intrinsic.io import figures

    def interrupted(*args, **kwargs):
        raise KeyboardInterrupt
    monkeypatch.setattr(figures, 'draw_surface', interrupted)
    assert run(['svbrdf', str(scene), '--out', str(out), '--steps', '2',
                '--overwrite', '--quiet']) == 130
    assert listing(out) == first
    assert not [n for n in os.listdir(tmp_path) if n.startswith('.')]
    # a rerun replaces them (and only them)
    monkeypatch.undo()
    assert run(['svbrdf', str(scene), '--out', str(out), '--steps', '2',
                '--overwrite', '--quiet']) == 0
    report = json.loads((out / 'report.json').read_text())
    assert report['options']['steps'] == 2
    assert (out / 'mine.txt').exists()


# ------------------------------------------------ messages that name the
# user's own option or file
def test_recovery_options_with_write_example_are_refused(tmp_path, capsys):
    folder = tmp_path / 'example'
    assert run(['svbrdf', '--write-example', str(folder), '--out',
                str(tmp_path / 'out')] + SMALL) == 2
    one_line_error(capsys, '--out is not used with --write-example DIR',
                   "'tg-intrinsic svbrdf DIR --out OUT'")
    assert run(['svbrdf', '--write-example', str(folder), '--steps', '3',
                '--refine', '2'] + SMALL) == 2
    one_line_error(capsys, '--steps, --refine are not used with '
                   '--write-example DIR')
    assert not folder.exists() and not (tmp_path / 'out').exists()
    assert run(['svbrdf', '--write-example', ''] + SMALL) == 2
    one_line_error(capsys, '--write-example is empty; give a folder')
    assert run(['svbrdf', str(folder), '--out', '']) == 2
    one_line_error(capsys, '--out is empty; give a folder')


def test_l_max_beyond_the_light_samples(scene, capsys):
    assert run(['svbrdf', str(scene), '--l-max', '60']) == 2
    err = one_line_error(capsys, 'argument --l-max: must be at most 15, got '
                         "'60'", '1024 directions', '(L + 1)^2')
    assert 'num_light_samples' not in err


def test_folder_where_a_scene_file_belongs(scene, tmp_path, capsys):
    copy = tmp_path / 'scene'
    shutil.copytree(scene, copy)
    photo = sorted(os.listdir(copy / 'images'))[2]
    os.remove(copy / 'images' / photo)
    (copy / 'images' / photo).mkdir()
    assert run(['svbrdf', str(copy), '--out', str(tmp_path / 'o')]) == 2
    one_line_error(capsys, f"'{copy / 'images' / photo}' is a folder, not a "
                   f"file", f"'images/{photo}'")
    os.remove(copy / 'cameras.json')
    (copy / 'cameras.json').mkdir()
    assert run(['svbrdf', str(copy), '--out', str(tmp_path / 'o')]) == 2
    one_line_error(capsys, f"'{copy / 'cameras.json'}' is a folder, not a "
                   f"file")
    assert not (tmp_path / 'o').exists()


@pytest.mark.parametrize('content, reason', [
    (b'\x93\x1fH\x00' + bytes(range(256)) * 2,
     'it is not a NumPy .npz file'),
    (b'base_color = 0.5\n', 'it is not a NumPy .npz file'),
    (b'', 'the file is empty'),
    (np.zeros(3), 'one .npy array, not a .npz archive'),
    ({'base_color': np.zeros((162, 3)),
      'roughness': np.array(['rough'] * 162)},
     "its 'roughness' holds <U5, not numbers"),
    ({'roughness': np.array([{'a': 1}] * 162, dtype=object)},
     "its 'roughness' cannot be read: it holds Python objects"),
])
def test_unreadable_ground_truth(scene, tmp_path, capsys, content, reason):
    copy = tmp_path / 'scene'
    shutil.copytree(scene, copy)
    path = copy / 'ground_truth.npz'
    if isinstance(content, bytes):
        path.write_bytes(content)
    elif isinstance(content, dict):
        np.savez(path, **content)
    else:
        with open(path, 'wb') as f:
            np.save(f, content)
    assert run(['svbrdf', str(copy), '--out', str(tmp_path / 'o'),
                '--steps', '1']) == 2
    err = one_line_error(capsys, f"'{path}' is not a readable .npz of the "
                         f"ground truth ({reason}", 'delete or repair it')
    assert 'pickle' not in err
    assert not (tmp_path / 'o').exists()


def test_ground_truth_folder(scene, tmp_path, capsys):
    copy = tmp_path / 'scene'
    shutil.copytree(scene, copy)
    os.remove(copy / 'ground_truth.npz')
    (copy / 'ground_truth.npz').mkdir()
    assert run(['svbrdf', str(copy), '--out', str(tmp_path / 'o'),
                '--steps', '1']) == 2
    one_line_error(capsys, f"'{copy / 'ground_truth.npz'}' is a folder, not "
                   f"a file")
    assert not (tmp_path / 'o').exists()


def test_nothing_to_fit(scene, tmp_path, capsys):
    copy = tmp_path / 'scene'
    shutil.copytree(scene, copy)
    spec = json.loads((copy / 'cameras.json').read_text())
    np.save(copy / 'black.npy', np.zeros((8, 16, 3), np.float32))
    (copy / 'cameras.json').write_text(json.dumps(dict(spec,
                                                       envmap='black.npy')))
    assert run(['svbrdf', str(copy), '--out', str(tmp_path / 'o')]) == 2
    one_line_error(capsys, f"'{copy / 'black.npy'}' is black")
    # every pixel missing: said so, not "no camera sees any point"
    for camera in spec['cameras']:
        os.remove(copy / camera['image'])
        camera['image'] = os.path.splitext(camera['image'])[0] + '.npy'
        np.save(copy / camera['image'],
                np.full((32, 32, 3), np.nan, np.float32))
    (copy / 'cameras.json').write_text(json.dumps(spec))
    assert run(['svbrdf', str(copy), '--out', str(tmp_path / 'o')]) == 2
    one_line_error(capsys, f"no photograph listed in "
                   f"'{copy / 'cameras.json'}' has a pixel above 0")
    assert not (tmp_path / 'o').exists()


@pytest.fixture(scope='module')
def point_scene(scene, tmp_path_factory):
    """The example with its mesh replaced by the bare points (with
    normals): a point cloud, whose occlusion is unknown."""
    from tg_intrinsic.io import write_ply
    folder = tmp_path_factory.mktemp('points') / 'scene'
    shutil.copytree(scene, folder)
    pos, _, properties = read_surface(folder / 'geometry.ply')
    write_ply(str(folder / 'geometry.ply'), pos, None,
              {k: properties[k] for k in ('nx', 'ny', 'nz')})
    return folder


def test_a_point_cloud_is_refined_only_when_told_it_is_convex(
        point_scene, tmp_path, capsys):
    out = tmp_path / 'out'
    assert run(['svbrdf', str(point_scene), '--out', str(out)]) == 0
    assert 'not refined: a point cloud without a mesh' in \
        capsys.readouterr().out
    report = json.loads((out / 'report.json').read_text())
    assert report['triangles'] is None
    assert report['pipeline']['steps'][-1] == 'fit'
    assert report['options']['refine'] == 0
    assert run(['svbrdf', str(point_scene), '--out', str(out), '--refine',
                '2', '--quiet']) == 2
    one_line_error(capsys, 'the refinement cannot run: a point cloud '
                   'without a mesh', 'horizon visibility')
    assert run(['svbrdf', str(point_scene), '--out', str(out), '--refine',
                '2', '--visibility', 'horizon', '--quiet']) == 0
    report = json.loads((out / 'report.json').read_text())
    refine = report['pipeline']['refine']
    assert refine['steps'] == 2 and refine['visibility'] == 'horizon'
    assert set(refine['seconds']) == {'visibility', 'tables', 'solve'}
    assert report['options']['visibility'] == 'horizon'


def test_textures_and_a_gltf_binary(scene, point_scene, tmp_path, capsys):
    import pygltflib
    out = tmp_path / 'out'
    assert run(['svbrdf', str(scene), '--out', str(out), '--texture', '64',
                '--refine', '0', '--steps', '2']) == 0
    assert '64 x 64 textures on an atlas' in capsys.readouterr().out
    for name in MAPS:
        assert (out / f'{name}_texture.png').is_file()
    gltf = pygltflib.GLTF2().load(str(out / 'svbrdf.glb'))
    assert gltf.materials[0].pbrMetallicRoughness.metallicRoughnessTexture \
        is not None
    report = json.loads((out / 'report.json').read_text())
    assert report['texture']['uv'] == 'xatlas'
    assert report['texture']['size'] == 64
    assert 'svbrdf.glb' in report['files']
    # a point cloud has no surface to put textures on: said before the work
    assert run(['svbrdf', str(point_scene), '--out', str(tmp_path / 'p'),
                '--texture', '64']) == 2
    one_line_error(capsys, '--texture needs a mesh')
    assert not (tmp_path / 'p').exists()
    assert run(['svbrdf', str(scene), '--out', str(tmp_path / 'q'),
                '--texture', '4']) == 2
    one_line_error(capsys, '--texture', 'must lie in [8, 8192]')


def test_textures_without_uvs_or_xatlas_say_how(scene, tmp_path, capsys,
                                                hide_module):
    hide_module('xatlas')
    assert run(['svbrdf', str(scene), '--out', str(tmp_path / 'out'),
                '--texture', '64']) == 2
    one_line_error(capsys, 'pip install xatlas', 'OBJ vt')
    assert not (tmp_path / 'out').exists()
