"""tg-intrinsic train: the data set argument, one-line user mistakes, and
the files a run writes."""
import csv
import json

import pytest

from tg_intrinsic.cli import main

from tests.cli import assert_user_error, run_cli


@pytest.mark.parametrize('argv,needles', [
    (['train', 'deltanet', '--epochs', '-3'], ['--epochs', 'at least 1']),
    (['train', 'deltanet', '--lr', '0'], ['--lr', 'positive']),
    (['train', 'deltanet', '--dataset', 'no/such/folder'],
     ['no/such/folder', 'existing folder']),
    (['train', 'resnet'], ["invalid choice: 'resnet'"]),
    (['train', 'deltanet', '--epochs', 'many'], ['--epochs', 'many']),
    (['train', 'deltanet', '--device', 'cpu', '--precision', '16-mixed'],
     ['16-mixed needs a CUDA device', 'use bf16-mixed']),
    (['train', 'deltanet', '--precision', 'half'], ['half', 'bf16-mixed']),
])
def test_train_user_mistakes_end_in_one_line(capsys, argv, needles):
    code, _, err = run_cli(capsys, *argv)
    assert_user_error(code, err, 'train', *needles)


def test_train_writes_metrics_csv_and_curves(tmp_path, capsys):
    code = main(['train', 'deltanet', '--dataset', 'synthetic-modelnet',
                 '--root', str(tmp_path / 'data'), '--out',
                 str(tmp_path / 'run'), '--num-points', '64',
                 '--shapes-per-class', '2', '--batch-size', '8',
                 '--conv-channels', '8', '--k', '6', '--epochs', '2',
                 '--eval-every', '2', '--quiet'])
    assert code == 0
    rows = list(csv.DictReader(open(tmp_path / 'run' / 'metrics.csv')))
    assert [int(r['epoch']) for r in rows] == [1, 2]
    assert rows[0]['test_accuracy'] == '' and 0 <= float(
        rows[1]['test_accuracy']) <= 1
    assert (tmp_path / 'run' / 'learning_curve.png').stat().st_size > 0


def test_a_mesh_folder_as_dataset(tmp_path, capsys):
    import trimesh
    for name, scale in (('ball', (1, 1, 1)), ('cigar', (3, 1, 1))):
        for split in ('train', 'test'):
            folder = tmp_path / 'meshes' / name / split
            folder.mkdir(parents=True)
            mesh = trimesh.creation.icosphere(1)
            mesh.apply_scale(scale)
            mesh.export(folder / f'{name}.off')
    code = main(['train', 'deltanet', '--dataset', str(tmp_path / 'meshes'),
                 '--out', str(tmp_path / 'run'), '--num-points', '64',
                 '--batch-size', '2', '--conv-channels', '8', '--k', '6',
                 '--epochs', '1', '--quiet'])
    assert code == 0
    metrics = json.loads((tmp_path / 'run' / 'metrics.json').read_text())
    assert metrics['dataset'] == 'mesh_folder'


@pytest.fixture
def trained(monkeypatch):
    """The arguments ``tg-intrinsic train`` hands to the library's train()
    (which is not run)."""
    import tg_intrinsic.training.loop
    calls = []
    monkeypatch.setattr(tg_intrinsic.training.loop, 'train', calls.append)
    return calls


@pytest.mark.parametrize('given,dataset', [
    ('synthetic-modelnet', 'synthetic_modelnet'),
    ('synthetic_modelnet', 'synthetic_modelnet'),  # the library's spelling
    ('synthetic-shrec', 'synthetic_shrec'),
])
def test_the_synthetic_data_sets(capsys, trained, given, dataset):
    code, _, err = run_cli(capsys, 'train', 'deltanet', '--dataset', given)
    assert code == 0, err
    (args, ) = trained
    assert args.dataset == dataset and args.mesh_root is None
    assert args.model == 'deltanet' and args.protocol == 'deltanet-modelnet40'
    assert not hasattr(args, 'check') and not hasattr(args, 'run')


def test_a_folder_is_a_mesh_folder_and_the_default_follows_the_model(
        tmp_path, capsys, trained):
    code, _, _ = run_cli(capsys, 'train', 'hsn', '--dataset', tmp_path)
    assert code == 0
    assert trained[-1].dataset == 'mesh_folder'
    assert trained[-1].mesh_root == str(tmp_path)
    assert trained[-1].protocol == 'hsn-shrec11'
    code, _, _ = run_cli(capsys, 'train', 'hsn')
    assert code == 0
    assert (trained[-1].dataset, trained[-1].mesh_root) == \
        ('synthetic_shrec', None)
    code, _, _ = run_cli(capsys, 'train', 'deltanet', '--task',
                         'segmentation', '--dataset', 'synthetic-shrec')
    assert code == 0
    assert (trained[-1].dataset, trained[-1].protocol) == \
        ('synthetic_shrec', 'deltanet-shapenet-part')
    # the documented default for deltanet is synthetic-modelnet, which has
    # no part labels: said on one line, nothing trained
    count = len(trained)
    code, _, err = run_cli(capsys, 'train', 'deltanet', '--task',
                           'segmentation')
    assert_user_error(code, err, 'train', 'deltanet segmentation cannot '
                      'train on synthetic_modelnet', 'synthetic_shrec')
    assert len(trained) == count


@pytest.mark.parametrize('argv,needles', [
    (['deltanet', '--dataset', 'FILE'], ['FILE', 'neither',
                                         'existing folder']),
    (['deltanet', '--protocol', 'hsn-shrec11'],
     ["protocol 'hsn-shrec11' trains hsn, not deltanet"]),
    (['hsn', '--dataset', 'synthetic-modelnet'],
     ['hsn classification cannot train on synthetic_modelnet']),
    (['deltanet', '--scale', '2', '1'], ['--scale needs 0 < LOW <= HIGH']),
    (['deltanet', '--max-angle', '270'], ['--max-angle', 'at most 180']),
])
def test_more_user_mistakes_end_in_one_line_before_any_work(
        tmp_path, capsys, trained, argv, needles):
    a_file = tmp_path / 'meshes.zip'
    a_file.write_bytes(b'PK')
    argv = [str(a_file) if a == 'FILE' else a for a in argv]
    needles = [str(a_file) if n == 'FILE' else n for n in needles]
    code, _, err = run_cli(capsys, 'train', *argv)
    assert_user_error(code, err, 'train', *needles)
    assert trained == []  # nothing was trained


def test_synthetic_parts_trains_deltanet_segmentation(capsys, trained):
    code, _, err = run_cli(capsys, 'train', 'deltanet', '--task',
                           'segmentation', '--dataset', 'synthetic-parts')
    assert code == 0, err
    assert (trained[-1].dataset, trained[-1].protocol) == \
        ('synthetic_parts', 'deltanet-shapenet-part')
    code, _, err = run_cli(capsys, 'train', 'deltanet', '--dataset',
                           'synthetic-parts')
    assert_user_error(code, err, 'train', 'deltanet classification cannot '
                      'train on synthetic_parts')


# --- resuming, the output folder and mistakes found before any work ---

import shutil  # noqa: E402

import torch  # noqa: E402

import tg_intrinsic.training.loop as training_loop  # noqa: E402
import tg_intrinsic.training.prepare as training_prepare  # noqa: E402
from tg_intrinsic.cli.common import UsageError  # noqa: E402
from tg_intrinsic.io.results import recorded_files  # noqa: E402

# DeltaNet on 12 + 12 generated shapes, one batch an epoch (seconds)
TINY = ['--dataset', 'synthetic-modelnet', '--num-points', '64',
        '--shapes-per-class', '2', '--batch-size', '8', '--conv-channels',
        '8', '--k', '6', '--embedding-size', '16', '--lr', '0.1',
        '--epochs', '1']


@pytest.fixture(scope='module')
def finished(tmp_path_factory):
    """(data root, out) of a finished one-epoch run."""
    folder = tmp_path_factory.mktemp('finished')
    root, out = folder / 'data', folder / 'run'
    assert main(['train', 'deltanet', *TINY, '--quiet', '--root', str(root),
                 '--out', str(out)]) == 0
    return root, out


@pytest.fixture
def earlier(finished, tmp_path):
    """A copy of the finished run's folder, and the arguments that made
    it (but --out)."""
    root, out = finished
    shutil.copytree(out, tmp_path / 'run')
    return tmp_path / 'run', ['train', 'deltanet', *TINY, '--quiet',
                              '--root', str(root)]


STOPPED = 'stopped where the data are prepared'


@pytest.fixture
def no_data(monkeypatch):
    """Data preparation ends the run with STOPPED: a check that passes
    reaches it, one that fails comes before it."""
    def stop(args):
        raise UsageError(STOPPED)
    monkeypatch.setattr(training_prepare, 'source_splits', stop)


def test_a_run_records_its_files(finished):
    _, out = finished
    assert {'checkpoint.pt', 'metrics.json', 'metrics.csv',
            'learning_curve.png'} <= recorded_files(str(out), 'train')


def test_resume_names_every_changed_setting(capsys, earlier, no_data):
    out, argv = earlier
    code, _, err = run_cli(capsys, *argv, '--out', out, '--resume', '--lr',
                           '0.5', '--num-points', '128')
    assert_user_error(code, err, 'train', 'checkpoint.pt',
                      'trained with other settings', '--lr 0.1 -> 0.5',
                      '--num-points 64 -> 128', 'cannot change when resuming')
    # --allow-changes lets only what the checkpoint does not hold change
    code, _, err = run_cli(capsys, *argv, '--out', out, '--resume', '--lr',
                           '0.5', '--allow-changes', 'lr')
    assert_user_error(code, err, 'train', '--allow-changes lr', 'epochs')


def test_resume_runs_longer_with_allow_changes(capsys, earlier):
    out, argv = earlier
    longer = [a if a != '1' or b != '--epochs' else '2'
              for b, a in zip([None] + argv, argv)]
    assert longer != argv
    code, _, err = run_cli(capsys, *longer, '--out', out, '--resume')
    assert_user_error(code, err, 'train', '--epochs 1 -> 2',
                      'add --allow-changes epochs')
    # settings that do not change the result never need the flag
    code, out_text, err = run_cli(capsys, *longer, '--out', out, '--resume',
                                  '--allow-changes', 'epochs', '--device',
                                  'cpu', '--workers', '2', '--on-disk')
    assert code == 0, err
    assert 'resuming with changed settings: --epochs 1 -> 2' in out_text
    state = torch.load(out / 'checkpoint.pt', weights_only=False)
    assert state['epoch'] == 2 and state['args']['epochs'] == 2


def test_resume_ignores_settings_an_older_checkpoint_did_not_save(
        capsys, earlier, no_data):
    out, argv = earlier
    state = torch.load(out / 'checkpoint.pt', weights_only=False)
    del state['args']['lr']
    torch.save(state, out / 'checkpoint.pt')
    code, _, err = run_cli(capsys, *argv, '--out', out, '--resume', '--lr',
                           '0.5')
    assert_user_error(code, err, 'train', STOPPED)


@pytest.mark.parametrize('content,needle', [
    (b'', 'is not a readable checkpoint (truncated?)'),
    ('half', 'is not a readable checkpoint (truncated?)'),
    ({'weights': 1}, 'is not a checkpoint of tg-intrinsic train'),
])
def test_resume_refuses_what_is_not_a_checkpoint(capsys, earlier, no_data,
                                                 content, needle):
    out, argv = earlier
    path = out / 'checkpoint.pt'
    if content == 'half':
        data = path.read_bytes()
        path.write_bytes(data[:len(data) // 2])
    elif isinstance(content, dict):
        torch.save(content, path)
    else:
        path.write_bytes(content)
    code, _, err = run_cli(capsys, *argv, '--out', out, '--resume')
    assert_user_error(code, err, 'train', str(path), needle, '--overwrite')


def test_resume_refuses_a_checkpoint_of_another_model(capsys, earlier,
                                                      no_data):
    out, _ = earlier
    code, _, err = run_cli(capsys, 'train', 'hsn', '--out', out, '--resume',
                           '--quiet')
    assert_user_error(code, err, 'train', 'holds a deltanet classification '
                      'model, not hsn classification')


def test_resume_without_a_checkpoint_starts_a_new_run(capsys, tmp_path,
                                                      no_data):
    out = tmp_path / 'new'
    code, stdout, err = run_cli(capsys, 'train', 'deltanet', *TINY,
                                '--quiet', '--out', out, '--resume')
    assert_user_error(code, err, 'train', STOPPED)
    assert f'no checkpoint in {out}: starting a new run at epoch 1' in stdout


def test_a_new_run_does_not_replace_an_earlier_one(capsys, earlier,
                                                   no_data):
    out, argv = earlier
    (out / 'notes.txt').write_text('mine')
    code, _, err = run_cli(capsys, *argv, '--out', out)
    assert_user_error(code, err, 'train', 'holds an earlier run (checkpoint '
                      'at epoch 1); --resume continues it, --overwrite '
                      'starts over')
    assert (out / 'checkpoint.pt').exists()
    # --overwrite deletes the earlier run's files before the data are read
    code, _, err = run_cli(capsys, *argv, '--out', out, '--overwrite')
    assert_user_error(code, err, 'train', STOPPED)
    left = sorted(p.name for p in out.iterdir())
    assert left == ['.tg-intrinsic.json', 'notes.txt']


def test_the_output_folder_rules(capsys, tmp_path, no_data):
    argv = ['train', 'deltanet', *TINY, '--quiet']
    a_file = tmp_path / 'file'
    a_file.write_text('x')
    code, _, err = run_cli(capsys, *argv, '--out', a_file)
    assert_user_error(code, err, 'train', '--out', 'is a file')
    foreign = tmp_path / 'foreign'
    foreign.mkdir()
    (foreign / 'thesis.tex').write_text('x')
    code, _, err = run_cli(capsys, *argv, '--out', foreign)
    assert_user_error(code, err, 'train', 'thesis.tex', '--overwrite')
    meshes = tmp_path / 'meshes'
    meshes.mkdir()
    for out in (meshes / 'run', tmp_path):
        code, _, err = run_cli(capsys, 'train', 'deltanet', '--dataset',
                               meshes, '--out', out)
        assert_user_error(code, err, 'train', '--out', str(meshes))
    # a run that fails before writing anything leaves no folder behind
    code, _, err = run_cli(capsys, *argv, '--out', tmp_path / 'new')
    assert_user_error(code, err, 'train', STOPPED)
    assert not (tmp_path / 'new').exists()


def test_device_that_this_machine_lacks(capsys):
    if torch.cuda.is_available():
        pytest.skip('this machine has CUDA')
    code, _, err = run_cli(capsys, 'train', 'deltanet', '--device', 'cuda')
    assert_user_error(code, err, 'train', "--device 'cuda'", 'no CUDA',
                      'cpu')


@pytest.mark.parametrize('argv,needles', [
    (['--device', 'bogus'], ["--device 'bogus' is not a device", 'cuda:N']),
    (['--batch-size', '1'], ['--batch-size 1', 'at least 2 shapes']),
    (['--allow-changes', 'epochs'], ['--allow-changes', 'add --resume']),
])
def test_mistakes_found_before_any_work(capsys, trained, argv, needles):
    code, _, err = run_cli(capsys, 'train', 'deltanet', *argv)
    assert_user_error(code, err, 'train', *needles)
    assert trained == []


def _mesh_folder(root, layout):
    import trimesh
    for name, split in layout:
        folder = root / name / split
        folder.mkdir(parents=True, exist_ok=True)
        trimesh.creation.icosphere(1).export(folder / f'{name}.off')
    return root


def test_one_class_is_not_a_classification(capsys, tmp_path):
    meshes = _mesh_folder(tmp_path / 'meshes', [('ball', 'train'),
                                                ('ball', 'test')])
    code, _, err = run_cli(capsys, 'train', 'deltanet', '--dataset', meshes,
                           '--out', tmp_path / 'run', '--quiet')
    assert_user_error(code, err, 'train', str(meshes), '1 class (ball)',
                      'at least 2')


def test_a_training_set_of_one_shape_for_batch_norm(capsys, tmp_path):
    meshes = _mesh_folder(tmp_path / 'meshes', [
        ('ball', 'train'), ('ball', 'test'), ('cigar', 'test')])
    code, _, err = run_cli(capsys, 'train', 'deltanet', '--dataset', meshes,
                           '--out', tmp_path / 'run', '--num-points', '64',
                           '--k', '6', '--conv-channels', '8',
                           '--batch-size', '8', '--root', tmp_path / 'data',
                           '--quiet')
    assert_user_error(code, err, 'train', 'training set has 1 shape',
                      'at least 2 shapes')


def test_quiet_generates_the_data_without_a_progress_bar(
        capsys, tmp_path, monkeypatch):
    def stop(*args, **kwargs):
        raise UsageError(STOPPED)
    monkeypatch.setattr(training_prepare, '_prepare_all', stop)
    code, _, err = run_cli(capsys, 'train', 'deltanet', *TINY, '--quiet',
                           '--root', tmp_path / 'data', '--out',
                           tmp_path / 'run')
    assert (tmp_path / 'data' / 'SyntheticModelNet').is_dir()  # generated
    assert_user_error(code, err, 'train', STOPPED)  # and nothing else said


class _Failing(torch.nn.Module):
    def __init__(self):
        super().__init__()
        self.lin = torch.nn.Linear(1, 1)

    def forward(self, batch):
        raise ValueError('this batch cannot be trained on')


def test_the_error_is_not_printed_inside_the_progress_bar(
        capsys, finished, tmp_path, monkeypatch):
    from tqdm import tqdm

    class KeptBar(tqdm):
        """A bar whose iteration outlives the error (as a debugger, a
        traceback or another interpreter may keep it): closed only if
        train closes it, not when the iteration is collected."""
        kept = []

        def __iter__(self):
            iteration = super().__iter__()
            self.kept.append(iteration)
            return iteration

    monkeypatch.setattr(training_loop, 'tqdm', KeptBar)
    monkeypatch.setattr(training_loop, 'build_model',
                        lambda *args, **kwargs: _Failing())
    code, _, err = run_cli(capsys, 'train', 'deltanet', *TINY, '--root',
                           finished[0], '--out', tmp_path / 'run')
    KeptBar.kept.clear()
    assert code == 2
    assert 'epoch 1/1' in err  # the bar was drawn ...
    # ... and cleared: the error starts a line of its own
    last = err.rstrip('\n').split('\n')[-1].split('\r')[-1]
    assert last.startswith('tg-intrinsic train: error: this batch cannot '
                           'be trained on'), repr(err[-300:])


def test_resume_on_data_of_another_number_of_classes(capsys, tmp_path,
                                                     monkeypatch):
    layout = [(name, split) for name in ('ball', 'cigar')
              for split in ('train', 'train2', 'test')]
    meshes = _mesh_folder(tmp_path / 'meshes', layout)
    for name in ('ball', 'cigar'):  # two training shapes per class
        (meshes / name / 'train2' / f'{name}.off').rename(
            meshes / name / 'train' / f'{name}2.off')
    argv = ['train', 'deltanet', '--dataset', meshes, '--out',
            tmp_path / 'run', '--num-points', '64', '--k', '6',
            '--conv-channels', '8', '--embedding-size', '16',
            '--batch-size', '4', '--root', tmp_path / 'data', '--quiet']
    code, _, err = run_cli(capsys, *argv, '--epochs', '1')
    assert code == 0, err
    _mesh_folder(meshes, [('box', 'train'), ('box', 'test')])

    def stop(*args, **kwargs):
        raise UsageError(STOPPED)
    monkeypatch.setattr(training_prepare, '_prepare_all', stop)
    code, _, err = run_cli(capsys, *argv, '--epochs', '1', '--resume')
    assert_user_error(code, err, 'train', 'trained on 2 classes, but the '
                      'data set has 3')
