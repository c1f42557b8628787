"""The command line as a whole (tg_intrinsic.cli's entry point): help,
dispatch, how a failure ends (exit codes 2, 1, 130, one line), warnings
on one line, and --debug."""
import errno
import os
import signal
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
    # the help, and one line on stderr that says what is missing
    assert result.stderr.strip() == ('tg-intrinsic: error: give a COMMAND: '
                                     + ', '.join(COMMANDS))
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


@pytest.mark.parametrize('error,code,words', [
    (FileNotFoundError("'x.obj' does not exist"), 2,
     ["tg-intrinsic info: error: 'x.obj' does not exist"]),
    (ValueError('first line\n  second line'), 2,
     ['tg-intrinsic info: error: first line second line']),
    (KeyboardInterrupt(), 130,
     ['tg-intrinsic info: interrupted; no file was left half-written']),
    (OSError(errno.ENOSPC, 'No space left on device', '/runs/x.ply'), 2,
     ["tg-intrinsic info: error: '/runs/x.ply': no space left on device"]),
    (OSError(errno.ENAMETOOLONG, 'File name too long', 'a' * 300), 2,
     ["tg-intrinsic info: error: 'aaa", "': file name too long"]),
    (RuntimeError('boom'), 1,
     ['tg-intrinsic info: unexpected RuntimeError: boom', '--debug',
      'please report it']),
])
def test_how_a_failure_ends(capsys, monkeypatch, error, code, words):
    from tg_intrinsic.cli import info

    def fail(args):
        raise error

    monkeypatch.setattr(info, 'run', fail)
    got, out, err = run_cli(capsys, 'info')
    assert got == code and out == ''
    assert len(err.strip().splitlines()) == 1 and 'Traceback' not in err
    for word in words:
        assert word in err
    with pytest.raises(type(error)):
        main(['info', '--debug'])


def test_warnings_are_one_line_unless_debugging(capsys, monkeypatch):
    import warnings
    from tg_intrinsic.cli import info

    def warn(args):
        warnings.warn('the solver did not\n converge', RuntimeWarning)
        return 0

    monkeypatch.setattr(info, 'run', warn)
    code, _, err = run_cli(capsys, 'info')
    assert code == 0
    assert err == 'tg-intrinsic: warning: the solver did not converge\n'
    with pytest.warns(RuntimeWarning, match='did not'):
        assert main(['info', '--debug']) == 0
    assert warnings.showwarning.__module__ != 'tg_intrinsic.cli'  # restored


@pytest.mark.parametrize('signum', [signal.SIGTERM, signal.SIGHUP])
def test_a_stop_signal_ends_like_ctrl_c(tmp_path, capsys, monkeypatch,
                                        signum):
    """``kill`` (or a closed terminal) in the middle of writing results:
    exit 128 + the signal, the staging folder removed, nothing in place."""
    from tg_intrinsic.cli import info
    from tg_intrinsic.io.results import result_folder

    def killed_while_writing(args):
        with result_folder(str(tmp_path / 'out'), 'info') as staging:
            open(os.path.join(staging, 'a.txt'), 'w').close()
            os.kill(os.getpid(), signum)

    monkeypatch.setattr(info, 'run', killed_while_writing)
    before = signal.getsignal(signum)
    code, _, err = run_cli(capsys, 'info')
    assert code == 128 + signum
    assert f'stopped by {signal.Signals(signum).name}' in err
    assert os.listdir(tmp_path) == []
    assert signal.getsignal(signum) == before   # the handler put back
