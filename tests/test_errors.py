"""The errors a user sees: UsageError is a ValueError (the command line
ends it with one line and exit code 2), and one_line joins a message."""
import pytest

from tg_intrinsic.cli.common import UsageError as CliUsageError
from tg_intrinsic.errors import UsageError, interruption_behind, one_line


def test_usage_error_is_a_value_error_with_one_owner():
    assert issubclass(UsageError, ValueError)
    assert CliUsageError is UsageError   # the command line's is the same
    with pytest.raises(ValueError, match='bad'):
        raise UsageError('bad')


def test_one_line():
    assert one_line('first line\n   second\tline ') == \
        'first line second line'
    assert one_line(ValueError('a\nb')) == 'a b'


def wrapped_interrupt():
    """What CPython raises when a signal's KeyboardInterrupt is pending as a
    compiled function returns: a SystemError caused by it."""
    try:
        try:
            raise KeyboardInterrupt
        except KeyboardInterrupt as stop:
            raise SystemError('returned a result with an exception set') \
                from stop
    except SystemError as error:
        return error


def test_interruption_behind():
    error = wrapped_interrupt()
    assert isinstance(interruption_behind(error), KeyboardInterrupt)
    assert interruption_behind(KeyboardInterrupt()) is not None
    assert interruption_behind(ValueError('a bad file')) is None
    chained = ValueError('outer')
    chained.__context__ = RuntimeError('inner')
    assert interruption_behind(chained) is None


def test_an_interrupt_inside_a_compiled_function_is_a_stop(capsys,
                                                            monkeypatch):
    """The command line and precompute's per-file work treat the wrapped
    interrupt as Ctrl-C (exit 130, nothing reported as a failure)."""
    from tg_intrinsic import cli
    from tg_intrinsic.cli import info, precompute

    def stopped(args):
        raise wrapped_interrupt()
    monkeypatch.setattr(info, 'run', stopped)
    assert cli.main(['info']) == 130
    assert 'interrupted' in capsys.readouterr().err

    def compiled(*args):
        raise wrapped_interrupt()
    monkeypatch.setattr(precompute, 'precompute_file', compiled)
    with pytest.raises(KeyboardInterrupt):
        precompute._work(('mls', {}, 'a.obj', 'a.pt'))
