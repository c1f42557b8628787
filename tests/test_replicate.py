"""The replication scripts (benchmarks/replicate/*.py): every row's smoke
run (tiny data in the real release format, the protocol with small sizes)
writes its JSON and plot, and a bad data folder is one line and exit
code 2."""
import importlib.util
import json
import os

import pytest

from tg_intrinsic.protocols import PROTOCOLS

pytest.importorskip('h5py')
pytest.importorskip('matplotlib')

HERE = os.path.dirname(os.path.abspath(__file__))
REPLICATE = os.path.join(os.path.dirname(HERE), 'benchmarks', 'replicate')
ROWS = ('deltanet-modelnet40', 'deltanet-scanobjectnn', 'deltanet-shrec11',
        'deltanet-shapenet-part', 'deltanet-human-seg', 'hsn-shrec11',
        'hsn-human-seg')


def load(row):
    name = row.replace('-', '_')
    path = os.path.join(REPLICATE, f'{name}.py')
    spec = importlib.util.spec_from_file_location(f'replicate_{name}', path)
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


def test_every_script_is_a_row():
    scripts = {f[:-3] for f in os.listdir(REPLICATE)
               if f.endswith('.py') and not f.startswith('_')}
    assert scripts == {row.replace('-', '_') for row in ROWS}
    for row in ROWS:
        assert row in PROTOCOLS
        assert load(row).ROW.protocol == row


@pytest.mark.parametrize('row', ROWS)
def test_smoke_run(row, tmp_path, capsys):
    result = load(row).main(['--smoke', '--out', str(tmp_path)])
    protocol = PROTOCOLS[row]
    written = json.loads((tmp_path / f'{row}.json').read_text())
    assert written['complete'] and written == json.loads(json.dumps(result))
    assert (tmp_path / f'{row}.png').stat().st_size > 1000
    summary = written['summary']
    assert summary['repeats'] == 2 and len(written['runs']) == 2
    assert summary['epochs'] == 1 and summary['smoke']
    for value in summary['values'] + [summary['mean'], summary['std']]:
        assert 0 <= value <= 100
    # The paper's number is recorded as the protocol states it.
    assert summary['reported'] == protocol.reported
    assert written['protocol'] == json.loads(json.dumps(protocol.to_dict()))
    assert written['machine']['torch']
    runs = written['runs']
    assert [run['settings']['seed'] for run in runs] == [0, 1]
    assert [run['settings']['data_seed'] for run in runs] == [0, 1]
    for run in runs:
        assert 'args' not in run and run['protocol'] == row
        # Sizes are small, everything else is the protocol's.
        settings = run['settings']
        for name in ('optimizer', 'lr', 'schedule', 'weight_decay',
                     'rotate', 'scale', 'anisotropic', 'translate',
                     'label_smoothing', 'task', 'regularizer', 'max_order'):
            value = getattr(protocol, name)
            expected = list(value) if isinstance(value, tuple) else value
            assert settings[name] == (expected if name != 'rotate'
                                      else expected or 'none'), name
        if protocol.train_per_class is not None:
            assert settings['train_per_class'] == 2
            assert run['train_shapes'] == 6     # 2 of 3 per class
    # eval-mode and batch-statistics accuracy side by side; HSN's per-shape
    # normalisation makes them one function
    assert 0 <= summary['eval_accuracy'] <= 100
    assert 0 <= summary['batch_statistics_accuracy'] <= 100
    if protocol.model == 'hsn':
        assert summary['largest_statistics_gap'] == 0
    out = capsys.readouterr().out
    paper = 'not verified' if protocol.reported is None \
        else f'{protocol.reported:.1f} %'
    assert paper in out and f"{summary['mean']:.1f} \u00b1" in out
    for note in protocol.notes:
        assert note in out


def test_bad_path(tmp_path, capsys):
    module = load('deltanet-modelnet40')
    with pytest.raises(SystemExit) as info:
        module.main([str(tmp_path / 'missing'), '--out', str(tmp_path)])
    assert info.value.code == 2
    err = capsys.readouterr().err.strip()
    assert '\n' not in err and 'not a folder' in err
    assert 'ModelNet40/<class>/{train,test}' in err
    # A folder of another data set's layout is refused before it is read.
    (tmp_path / 'other' / 'h5_files').mkdir(parents=True)
    with pytest.raises(SystemExit) as info:
        module.main([str(tmp_path / 'other'), '--out', str(tmp_path)])
    assert info.value.code == 2
    err = capsys.readouterr().err.strip()
    assert '\n' not in err and 'in the ScanObjectNN layout' in err
    # A MeshCNN segmentation folder is not a classification layout.
    (tmp_path / 'seg' / 'train').mkdir(parents=True)
    with pytest.raises(SystemExit) as info:
        load('hsn-human-seg').main([str(tmp_path / 'seg'), '--out',
                                    str(tmp_path)])
    assert info.value.code == 2
    err = capsys.readouterr().err.strip()
    assert '\n' not in err and 'human_seg/{train,test}/*.obj' in err
    # PATH is needed without --smoke.
    with pytest.raises(SystemExit) as info:
        module.main(['--out', str(tmp_path)])
    assert info.value.code == 2


def test_a_gap_between_eval_mode_and_batch_statistics_is_a_warning():
    common = load(ROWS[0])._common
    summary = {'eval_accuracy': 47.5, 'batch_statistics_accuracy': 96.7,
               'largest_statistics_gap': 49.2}
    warning = common.statistics_warning(summary)
    assert warning.startswith('warning: in eval mode the test accuracy')
    assert '49.2 points (more than 2)' in warning and '47.5 vs 96.7' in warning
    summary['largest_statistics_gap'] = 2.0
    assert common.statistics_warning(summary) is None
    assert common.statistics_warning({}) is None
