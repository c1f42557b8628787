"""train's options: unsupported combinations and missing roots fail
before any data is read."""
import pytest

from tg_intrinsic.training.options import main, parse_args


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


def test_mesh_folder_needs_a_root(tmp_path):
    with pytest.raises(ValueError, match='--mesh-root'):
        main(['--dataset', 'mesh_folder', '--out', str(tmp_path),
              '--epochs', '1', '--quiet'])
    with pytest.raises(SystemExit):
        parse_args(['--epochs', '0'])
