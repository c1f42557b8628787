"""tg-intrinsic info: the versions, the device and the optional extras,
as a table and as JSON."""
import json

from tests.cli import run_cli


def test_info(capsys):
    code, out, _ = run_cli(capsys, 'info')
    assert code == 0
    for name in ('torch', 'torch_geometric', 'tg_intrinsic', 'device',
                 'potpourri3d', 'OpenEXR', 'mitsuba', 'torch_scatter'):
        assert name in out
    code, out, _ = run_cli(capsys, 'info', '--json')
    info = json.loads(out)
    assert code == 0 and set(info['extras']) == {
        'potpourri3d', 'OpenEXR', 'mitsuba', 'torch_scatter'}
