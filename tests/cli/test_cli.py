"""The command line as a whole (tg_intrinsic.cli's entry point): help,
dispatch, one-line user errors and --debug."""
import subprocess
import sys

import pytest

from tg_intrinsic.cli import COMMANDS, main

from tests.cli import run_cli


@pytest.mark.parametrize('command', COMMANDS)
def test_every_command_has_help_with_a_worked_example(capsys, command):
    code, text, _ = run_cli(capsys, command, '--help')
    assert code == 0
    assert 'example' in text and f'tg-intrinsic {command}' in text


def test_python_dash_m_and_no_command():
    result = subprocess.run([sys.executable, '-m', 'tg_intrinsic'],
                            capture_output=True, text=True)
    assert result.returncode == 2
    assert all(command in result.stdout for command in COMMANDS)
    result = subprocess.run([sys.executable, '-m', 'tg_intrinsic', 'nope'],
                            capture_output=True, text=True)
    assert result.returncode == 2
    assert len(result.stderr.strip().split('\n')) == 1
    assert "invalid choice: 'nope'" in result.stderr


def test_debug_shows_the_traceback(capsys):
    with pytest.raises(ValueError, match='neither'):
        main(['--debug', 'train', 'deltanet', '--dataset', 'missing'])
    with pytest.raises(ValueError, match='neither'):
        main(['train', 'deltanet', '--dataset', 'missing', '--debug'])
