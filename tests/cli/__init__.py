"""Shared helpers of the command-line tests."""
from tg_intrinsic.cli import main


def run_cli(capsys, *argv):
    """Runs ``tg-intrinsic ARGV`` in process: ``(exit code, stdout,
    stderr)``."""
    code = main([str(a) for a in argv])
    out, err = capsys.readouterr()
    return code, out, err


def assert_user_error(code, err, command, *needles):
    """A user mistake: exit code 2 and one line on stderr, from the
    command, holding every needle, without a traceback."""
    assert code == 2, (code, err)
    assert 'Traceback' not in err, err
    lines = err.strip().splitlines()
    assert len(lines) == 1, err
    assert lines[0].startswith(f'tg-intrinsic {command}: error: '), err
    for needle in needles:
        assert needle in lines[0], lines[0]
