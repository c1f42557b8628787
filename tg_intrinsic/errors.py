"""The errors a user sees, below every module that raises them: the
library raises :class:`UsageError` for a mistake in what the user asked
for, and the command line prints it on one line (:func:`one_line`) with
exit code 2."""

__all__ = ['UsageError', 'one_line', 'interruption_behind']


class UsageError(ValueError):
    """A mistake in what the user asked for (a missing file, a bad value):
    the command line prints the message on one line and exits with 2."""


def one_line(message: str) -> str:
    """A (possibly multi-line) error message as one line."""
    return ' '.join(str(message).split())


def interruption_behind(error: BaseException):
    """The ``KeyboardInterrupt`` (Ctrl-C, or SIGTERM/SIGHUP as the command
    line raises them) that ``error`` stands for, or :obj:`None`. A signal
    that arrives while a compiled (numba) function runs surfaces as a
    ``SystemError`` ("returned a result with an exception set") whose cause
    is the interrupt: it is a stop, not a failure of the file or the
    step."""
    seen = set()
    while error is not None and id(error) not in seen:
        if isinstance(error, KeyboardInterrupt):
            return error
        seen.add(id(error))
        error = error.__cause__ or error.__context__
    return None
