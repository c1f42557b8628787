"""The errors a user sees, below every module that raises them: the
library raises :class:`UsageError` for a mistake in what the user asked
for, and the command line prints it on one line (:func:`one_line`) with
exit code 2."""

__all__ = ['UsageError', 'one_line']


class UsageError(ValueError):
    """A mistake in what the user asked for (a missing file, a bad value):
    the command line prints the message on one line and exits with 2."""


def one_line(message: str) -> str:
    """A (possibly multi-line) error message as one line."""
    return ' '.join(str(message).split())
