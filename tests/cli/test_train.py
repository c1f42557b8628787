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
