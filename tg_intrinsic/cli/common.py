"""What every sub-command shares: argument types that reject bad values in
one line, messages of errors and progress bars (the user-error type lives
in :mod:`tg_intrinsic.errors`, output folders in
:mod:`tg_intrinsic.io.results`)."""
import argparse
import inspect
import math
import sys
import textwrap
import time
from contextlib import contextmanager
from typing import Iterable, Optional

from tqdm.auto import tqdm

from tg_intrinsic.errors import UsageError, one_line  # noqa: F401 (re-exported)
from tg_intrinsic.utils import os_error_reason


class ArgumentParser(argparse.ArgumentParser):
    """argparse that reports a bad argument on one line (no usage block)
    and exits with code 2, like every other user mistake."""

    def error(self, message):
        self.exit(2, f"{self.prog}: error: {message} (see {self.prog} "
                     f"--help)\n")


class HelpFormatter(argparse.RawDescriptionHelpFormatter):
    """argparse's help with words kept whole: option help breaks lines only
    at spaces (argparse's own breaks hyphenated words and long file names,
    so a name copied from ``--help`` would be wrong); descriptions and
    examples keep their own lines."""

    def _split_lines(self, text, width):
        text = ' '.join(text.split())
        return textwrap.wrap(text, width, break_on_hyphens=False,
                             break_long_words=False)


def user_message(error: BaseException) -> str:
    """What went wrong, on one line; an operating-system error as the
    file and the reason, not as ``[Errno N] ...``."""
    if isinstance(error, OSError) and error.strerror and \
            str(error).startswith('[Errno'):
        where = f"'{error.filename}'" if error.filename is not None \
            else 'a file'
        if error.filename2 is not None:
            where += f" -> '{error.filename2}'"
        return one_line(f"{where}: {os_error_reason(error)}")
    return one_line(error)


def _number(kind, text, minimum, strict):
    try:
        value = kind(text)
    except ValueError:
        raise argparse.ArgumentTypeError(
            f"expected {'an integer' if kind is int else 'a number'}, got "
            f"{text!r}") from None
    if kind is float and not math.isfinite(value):
        raise argparse.ArgumentTypeError(f"must be finite, got {text!r}")
    if value < minimum or (strict and value == minimum):
        bound = 'greater than' if strict else 'at least'
        raise argparse.ArgumentTypeError(f"must be {bound} {minimum}, got "
                                         f"{text!r}")
    return value


def positive_float(text: str) -> float:
    """argparse type: a finite number > 0."""
    return _number(float, text, 0.0, strict=True)


def nonnegative_float(text: str) -> float:
    """argparse type: a finite number >= 0."""
    return _number(float, text, 0.0, strict=False)


def positive_int(text: str) -> int:
    """argparse type: an integer >= 1."""
    return _number(int, text, 1, strict=False)


def int_at_least(minimum: int):
    """argparse type: an integer >= ``minimum``."""
    def parse(text: str) -> int:
        return _number(int, text, minimum, strict=False)
    parse.__name__ = f'integer >= {minimum}'
    return parse


def nonnegative_int(text: str) -> int:
    """argparse type: an integer >= 0."""
    return _number(int, text, 0, strict=False)


def default_of(function, name: str):
    """The default of argument ``name`` of a library ``function`` (or
    class): the library owns the value, the command line shows it."""
    return inspect.signature(function).parameters[name].default


def progress(iterable: Iterable, desc: str, quiet: bool = False,
             total: Optional[int] = None, unit: str = 'it'):
    """A tqdm bar on stderr, off with ``--quiet``."""
    return tqdm(iterable, desc=desc, disable=quiet, total=total, unit=unit,
                leave=False, dynamic_ncols=True)


def common_options() -> argparse.ArgumentParser:
    """Options every sub-command accepts (before or after its name)."""
    parent = argparse.ArgumentParser(add_help=False)
    parent.add_argument('--debug', action='store_true',
                        default=argparse.SUPPRESS,
                        help='show the Python traceback of an error')
    parent.add_argument('--quiet', action='store_true',
                        default=argparse.SUPPRESS,
                        help='no progress bars or progress lines')
    return parent


@contextmanager
def stage(name: str, quiet: bool, seconds: dict, key: str):
    """Times a stage into ``seconds[key]`` and reports it on stderr
    (progress, not the result): ``name ...`` when it starts, its time
    or ``failed`` when it ends, so a progress bar may run in between."""
    if not quiet:
        print(f"{name} ...", file=sys.stderr, flush=True)
    start = time.perf_counter()
    try:
        yield
    except BaseException:
        if not quiet:
            print(f"{name}: failed", file=sys.stderr, flush=True)
        raise
    seconds[key] = round(time.perf_counter() - start, 3)
    if not quiet:
        print(f"{name}: {seconds[key]:.2f} s", file=sys.stderr, flush=True)
