import json
import os

import pytest
import torch

from tg_intrinsic.train import main, parse_args


def run(tmp_path, *extra):
    return main(['--dataset', 'synthetic_modelnet', '--root',
                 str(tmp_path / 'data'), '--out', str(tmp_path / 'run'),
                 '--num-points', '96', '--shapes-per-class', '4',
                 '--batch-size', '8', '--conv-channels', '8', '8',
                 '--k', '8', '--eval-every', '1', '--quiet', *extra])


def test_training_writes_outputs_and_resumes(tmp_path):
    metrics = run(tmp_path, '--epochs', '2')
    out = tmp_path / 'run'
    for name in ('checkpoint.pt', 'metrics.json', 'learning_curve.png'):
        assert (out / name).exists(), name
    assert len(metrics['history']) == 2
    assert 0.0 <= metrics['final_test_accuracy'] <= 1.0
    state = torch.load(out / 'checkpoint.pt', weights_only=False)
    assert state['epoch'] == 2
    # Resuming continues from the checkpoint instead of starting over.
    metrics = run(tmp_path, '--epochs', '3', '--resume')
    assert [h['epoch'] for h in metrics['history']] == [1, 2, 3]
    assert json.loads((out / 'metrics.json').read_text())[
        'final_test_accuracy'] == metrics['final_test_accuracy']
    assert not [f for f in os.listdir(out) if f.startswith('.tmp')]


def test_mesh_folder_needs_a_root(tmp_path):
    with pytest.raises(ValueError, match='--mesh-root'):
        main(['--dataset', 'mesh_folder', '--out', str(tmp_path),
              '--epochs', '1', '--quiet'])
    with pytest.raises(SystemExit):
        parse_args(['--epochs', '0'])


def test_training_on_a_mesh_folder(tmp_path):
    import trimesh
    shapes = {'ball': lambda s: trimesh.creation.icosphere(2, radius=s),
              'box': lambda s: trimesh.creation.box((s, 2 * s, 0.5 * s))}
    for name, make in shapes.items():
        for split in ('train', 'test'):
            folder = tmp_path / 'meshes' / name / split
            folder.mkdir(parents=True)
            for i in range(3):
                make(1.0 + 0.1 * i).export(folder / f'{name}_{i}.off')
    metrics = main(['--dataset', 'mesh_folder', '--mesh-root',
                    str(tmp_path / 'meshes'), '--out', str(tmp_path / 'run'),
                    '--num-points', '96', '--batch-size', '4',
                    '--conv-channels', '8', '8', '--k', '8', '--epochs', '1',
                    '--quiet'])
    assert metrics['dataset'] == 'mesh_folder'
    assert len(metrics['history']) == 1


def test_rotation_augmentation_and_sgd(tmp_path):
    metrics = run(tmp_path, '--epochs', '1', '--rotate', '--optimizer', 'sgd',
                  '--lr', '0.05')
    assert metrics['args']['rotate'] and metrics['args']['optimizer'] == 'sgd'
    assert len(metrics['history']) == 1
    state = torch.load(tmp_path / 'run' / 'checkpoint.pt', weights_only=False)
    assert 'momentum' in state['optimizer']['param_groups'][0]


@pytest.fixture(scope='module')
def shrec_root(tmp_path_factory):
    return tmp_path_factory.mktemp('shrec')  # generated once for both tasks


@pytest.mark.parametrize('task', ['classification', 'segmentation'])
def test_hsn_training_on_synthetic_shrec(tmp_path, shrec_root, task):
    metrics = main(['--model', 'hsn', '--task', task, '--dataset',
                    'synthetic_shrec', '--root', str(shrec_root),
                    '--out', str(tmp_path / 'run'), '--shapes-per-class',
                    '2', '--num-vertices', '120', '160', '--hsn-channels',
                    '4', '8', '--rings', '3', '--radius', '0.3', '--epochs',
                    '1', '--batch-size', '4', '--rotate', '--quiet',
                    '--resample-vertices', '100'])
    assert len(metrics['history']) == 1
    assert 0.0 <= metrics['final_test_accuracy'] <= 1.0
    assert (tmp_path / 'run' / 'checkpoint.pt').exists()


def test_hsn_training_on_a_mesh_folder(tmp_path):
    import trimesh
    for name, scale in (('ball', (1, 1, 1)), ('cigar', (3, 1, 1))):
        for split in ('train', 'test'):
            folder = tmp_path / 'meshes' / name / split
            folder.mkdir(parents=True)
            for i in range(2):
                mesh = trimesh.creation.icosphere(2)
                mesh.apply_scale(scale)
                mesh.export(folder / f'{name}_{i}.off')
    metrics = main(['--model', 'hsn', '--dataset', 'mesh_folder',
                    '--mesh-root', str(tmp_path / 'meshes'), '--out',
                    str(tmp_path / 'run'), '--hsn-channels', '4', '8',
                    '--rings', '3', '--radius', '0.25', '--epochs', '1',
                    '--batch-size', '2', '--quiet'])
    assert metrics['dataset'] == 'mesh_folder'


def test_unsupported_combinations_fail_before_reading_data(tmp_path, capsys):
    with pytest.raises(SystemExit) as exit_info:
        parse_args(['--model', 'hsn', '--dataset', 'synthetic_modelnet',
                    '--root', str(tmp_path / 'data')])
    assert exit_info.value.code == 2
    message = capsys.readouterr().err
    assert 'hsn classification cannot train on synthetic_modelnet' in message
    assert 'hsn classification: synthetic_shrec, mesh_folder' in message
    with pytest.raises(SystemExit):
        parse_args(['--model', 'deltanet', '--task', 'segmentation',
                    '--dataset', 'synthetic_modelnet'])
    with pytest.raises(SystemExit):
        parse_args(['--model', 'deltanet', '--protocol', 'hsn-shrec11'])
    assert not (tmp_path / 'data').exists()


def test_protocol_defaults_and_overrides():
    from tg_intrinsic.protocols import PROTOCOLS
    args = parse_args(['--model', 'hsn'])
    hsn = PROTOCOLS['hsn-shrec11']
    assert args.protocol == 'hsn-shrec11'
    assert (args.lr, args.optimizer, args.batch_size, args.schedule) == \
        (hsn.lr, hsn.optimizer, hsn.batch_size, hsn.schedule)
    assert args.milestones == list(hsn.milestones) and args.rotate == 'xyz'
    args = parse_args(['--model', 'hsn', '--lr', '0.5', '--rotate'])
    assert args.lr == 0.5 and args.rotate == 'so3'
    args = parse_args(['--protocol', 'deltanet-shrec11',
                       '--no-anisotropic'])
    shrec = PROTOCOLS['deltanet-shrec11']
    assert (args.num_points, args.conv_channels, args.train_per_class) == \
        (shrec.num_points, list(shrec.conv_channels), 10)
    assert args.anisotropic is False
    args = parse_args(['--model', 'hsn', '--task', 'segmentation'])
    assert args.protocol == 'hsn-human-seg'
    assert args.resample_vertices == 1024


def test_select_per_class_is_seeded_and_balanced():
    from tg_intrinsic.train import select_per_class
    labels = [0] * 16 + [1] * 16 + [2] * 3
    first = select_per_class(labels, 10, seed=4)
    assert first == select_per_class(labels, 10, seed=4)
    assert first != select_per_class(labels, 10, seed=5)
    counts = torch.bincount(torch.tensor(labels)[first])
    assert counts.tolist() == [10, 10, 3]


def test_test_points_are_the_same_on_every_preparation(tmp_path):
    # A checkpoint must score the same every time: the sampling of a
    # shape depends on the data seed and the shape only.
    from tg_intrinsic.train import build_point_sets
    argv = ['--dataset', 'synthetic_shrec', '--root', str(tmp_path),
            '--num-points', '64', '--shapes-per-class', '2',
            '--num-vertices', '120', '160', '--k', '8']
    first = build_point_sets(parse_args(argv))[1]
    for folder in tmp_path.glob('deltanet_cache'):
        for f in folder.iterdir():
            f.unlink()
    again = build_point_sets(parse_args(argv))[1]
    other = build_point_sets(parse_args(argv + ['--data-seed', '1']))[1]
    for a, b in zip(first, again):
        torch.testing.assert_close(a.pos, b.pos)
        torch.testing.assert_close(a.grad_weight, b.grad_weight)
    assert not torch.allclose(first[0].pos, other[0].pos)


def test_deltanet_segmentation_on_synthetic_shrec(tmp_path, shrec_root):
    metrics = main(['--model', 'deltanet', '--task', 'segmentation',
                    '--dataset', 'synthetic_shrec', '--root',
                    str(shrec_root), '--out', str(tmp_path / 'run'),
                    '--shapes-per-class', '2', '--num-vertices', '120', '160',
                    '--num-points', '64', '--conv-channels', '8', '8',
                    '--k', '8', '--embedding-size', '32', '--epochs', '1',
                    '--batch-size', '4', '--quiet'])
    assert metrics['protocol'] == 'deltanet-shapenet-part'
    assert 0.0 <= metrics['final_test_accuracy'] <= 1.0
