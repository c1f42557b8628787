"""The errors a user sees: UsageError is a ValueError (the command line
ends it with one line and exit code 2), and one_line joins a message."""
import pytest

from tg_intrinsic.cli.common import UsageError as CliUsageError
from tg_intrinsic.errors import UsageError, one_line


def test_usage_error_is_a_value_error_with_one_owner():
    assert issubclass(UsageError, ValueError)
    assert CliUsageError is UsageError   # the command line's is the same
    with pytest.raises(ValueError, match='bad'):
        raise UsageError('bad')


def test_one_line():
    assert one_line('first line\n   second\tline ') == \
        'first line second line'
    assert one_line(ValueError('a\nb')) == 'a b'
