"""``tg-intrinsic svbrdf`` on one capture in every format: ``--write-example
--format F [--ldr]``, then the recovery from what was written, whose maps
must be the native scene folder's (LDR: within the quantisation), and the
mistakes a user makes with a capture, each one line and exit code 2."""
import json
import os

import numpy as np
import pytest

from tests.cli import assert_user_error, run_cli

TINY = ['--example-views', '6', '--example-image-size', '24',
        '--example-subdivisions', '1']
FAST = ['--refine', '0', '--quiet']
FORMATS = ['colmap', 'colmap-bin', 'nerf', 'nerfstudio', 'orb']
READ_AS = {'colmap-bin': 'colmap'}


def example(capsys, folder, *options):
    code, out, err = run_cli(capsys, 'svbrdf', '--write-example', folder,
                             *TINY, *options)
    assert code == 0, err
    # the command to run next, as the example prints it
    command = out.strip().splitlines()[-1].split('next: ')[1].split()
    return command[2:command.index('--out')]


def recover(capsys, capture, out):
    code, _, err = run_cli(capsys, 'svbrdf', *capture, '--out', out, *FAST)
    assert code == 0, err
    report = json.loads(open(os.path.join(out, 'report.json')).read())
    return dict(np.load(os.path.join(out, 'maps.npz'))), report


@pytest.fixture(scope='module')
def native_maps(tmp_path_factory):
    from tg_intrinsic.cli import main
    folder = tmp_path_factory.mktemp('native')
    assert main(['svbrdf', '--write-example', str(folder / 'scene'), '--quiet']
                + TINY) == 0
    assert main(['svbrdf', str(folder / 'scene'), '--out',
                 str(folder / 'out')] + FAST) == 0
    return dict(np.load(folder / 'out' / 'maps.npz'))


@pytest.mark.parametrize('form', FORMATS)
def test_every_format_recovers_the_native_maps(capsys, tmp_path, form,
                                               native_maps):
    capture = example(capsys, tmp_path / 'capture', '--format', form)
    maps, report = recover(capsys, capture, tmp_path / 'out')
    assert report['capture']['format'] == READ_AS.get(form, form)
    assert report['ground_truth'] is not None  # found beside the capture
    for name, value in native_maps.items():
        # the inputs agree to float32 round-off (rotations through a
        # quaternion, focal lengths through an angle); the per-point fits
        # carry it on, a few ill-conditioned points more than the rest
        difference = np.abs(maps[name] - value)
        assert difference.mean() < 1e-4 and difference.max() < 1e-2, name


def test_ldr_photographs_recover_close_to_the_hdr_maps(capsys, tmp_path,
                                                       native_maps):
    capture = example(capsys, tmp_path / 'capture', '--format',
                      'nerfstudio', '--ldr')
    assert '--exposure' in capture
    maps, report = recover(capsys, capture, tmp_path / 'out')
    assert report['capture']['ldr']
    left_out = report['capture']['pixels_left_out']
    assert left_out['masked'] == 0 and left_out['clipped'] > 0
    # 8-bit quantisation and the clipped highlights left out
    assert np.abs(maps['roughness'] - native_maps['roughness']).mean() < 0.05
    assert np.abs(maps['base_color'] - native_maps['base_color']).mean() \
        < 0.08


def test_capture_mistakes_are_one_line(capsys, tmp_path):
    capture = example(capsys, tmp_path / 'ldr', '--format', 'colmap',
                      '--ldr')
    folder = capture[0]
    code, _, err = run_cli(capsys, 'svbrdf', folder, '--out', tmp_path / 'o')
    assert_user_error(code, err, 'svbrdf', 'needs --exposure S')
    assert not os.path.exists(tmp_path / 'o')
    os.remove(os.path.join(folder, 'images', '002.png'))
    code, _, err = run_cli(capsys, 'svbrdf', folder, '--exposure', '0.1',
                           '--out', tmp_path / 'o')
    assert_user_error(code, err, 'svbrdf', "'002.png'", 'does not hold')
    code, _, err = run_cli(capsys, 'svbrdf', tmp_path, '--out',
                           tmp_path / 'o')
    assert_user_error(code, err, 'svbrdf', 'no capture this library reads')
    code, _, err = run_cli(capsys, 'svbrdf', '--write-example',
                           tmp_path / 'x', '--ldr')
    assert_user_error(code, err, 'svbrdf', '--ldr', '--format')
    code, _, err = run_cli(capsys, 'svbrdf', folder, '--exposure', '-1')
    assert_user_error(code, err, 'svbrdf', '--exposure')
    code, _, err = run_cli(capsys, 'svbrdf', folder, '--envmap-rotation',
                           'nan')
    assert_user_error(code, err, 'svbrdf', '--envmap-rotation')
    assert not os.path.exists(tmp_path / 'o')


def test_show_cameras_writes_the_figure_and_stops(capsys, tmp_path):
    capture = example(capsys, tmp_path / 'capture', '--format', 'colmap')
    code, out, err = run_cli(capsys, 'svbrdf', *capture, '--show-cameras',
                             '--out', tmp_path / 'out')
    assert code == 0, err
    assert sorted(name for name in os.listdir(tmp_path / 'out')
                  if not name.startswith('.')) == ['cameras.png',
                                                   'report.json']
    assert 'cameras.png' in out
    report = json.loads((tmp_path / 'out' / 'report.json').read_text())
    assert report['capture']['format'] == 'colmap'


def test_photographs_are_streamed_not_held(capsys, tmp_path, monkeypatch):
    """The recovery reads a capture's photographs a block of views at a
    time: never more than a block at once, each view once from the stack
    (the projection; the reader's checking pass reads and drops each
    before), and the maps equal those of the photographs projected at
    once."""
    from tg_intrinsic.geometry.appearance import photograph_stack
    from tg_intrinsic.transforms import project_views
    capture = example(capsys, tmp_path / 'capture', '--format', 'colmap',
                      '--ldr')
    whole, _ = recover(capsys, capture, tmp_path / 'whole')
    reads, blocks = [], []
    view = photograph_stack.PhotographStack._view
    stack_getitem = photograph_stack.PhotographStack.__getitem__

    def counted(self, index):
        reads.append(index)
        return view(self, index)

    def block(self, index):
        if isinstance(index, slice):
            blocks.append(len(range(*index.indices(len(self)))))
        return stack_getitem(self, index)
    monkeypatch.setattr(photograph_stack.PhotographStack, '_view', counted)
    monkeypatch.setattr(photograph_stack.PhotographStack, '__getitem__',
                        block)
    # two photographs of 24 x 24 at a time
    monkeypatch.setattr(project_views, 'VIEW_PIXELS', 2 * 24 * 24)
    streamed, _ = recover(capsys, capture, tmp_path / 'streamed')
    assert blocks == [2, 2, 2]
    assert sorted(reads) == list(range(6))
    for name, value in whole.items():
        np.testing.assert_array_equal(streamed[name], value, err_msg=name)


def test_photographs_under_their_own_maps(capsys, tmp_path):
    """transforms.json frames naming their own maps (hdri_path): here two
    files of the same sky, so the recovery under each photograph's own map
    must land where the recovery under the one map does."""
    import shutil
    capture = example(capsys, tmp_path / 'capture', '--format',
                      'nerfstudio')
    refined = ['--refine', '2', '--quiet']

    def recover_refined(out):
        code, _, err = run_cli(capsys, 'svbrdf', *capture, '--out', out,
                               *refined)
        assert code == 0, err
        return (dict(np.load(os.path.join(out, 'maps.npz'))),
                json.loads(open(os.path.join(out, 'report.json')).read()))
    one, report = recover_refined(tmp_path / 'one')
    assert report['lightings'] == 1
    folder = capture[0]
    path = os.path.join(folder, 'transforms.json')
    spec = json.loads(open(path).read())
    sky = [name for name in os.listdir(folder) if name.startswith('envmap')]
    shutil.copy(os.path.join(folder, sky[0]),
                os.path.join(folder, 'second' + sky[0]))
    for index, frame in enumerate(spec['frames']):
        frame['hdri_path'] = ('second' if index % 2 else '') + sky[0]
    open(path, 'w').write(json.dumps(spec))
    own, report = recover_refined(tmp_path / 'own')
    assert report['lightings'] == 2
    assert len(report['capture']['lightings']) == 2
    assert report['pipeline']['refine'] is not None
    assert np.abs(own['roughness'] - one['roughness']).mean() < 0.05
    # the harmonic fit alone cannot model several lightings: said in words
    code, _, err = run_cli(capsys, 'svbrdf', *capture, '--out',
                           tmp_path / 'fit', '--refine', '0')
    assert code == 2 and 'only the refinement models' in err
    assert not os.path.exists(tmp_path / 'fit')
