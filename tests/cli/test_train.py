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
    import tg_intrinsic.train
    calls = []
    monkeypatch.setattr(tg_intrinsic.train, 'train', calls.append)
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
