"""The ``tg-intrinsic`` command line (also ``python -m tg_intrinsic``).

Sub-commands: ``demo``, ``train``, ``precompute``, ``solve``, ``svbrdf`` and
``info``; ``tg-intrinsic COMMAND --help`` shows a worked example of each.
This package parses arguments, reads and writes files and draws figures;
the maths lives in the library. A user mistake (a missing file, a bad
value) ends with one line on stderr and exit code 2; ``--debug`` shows the
traceback instead.
"""
import importlib
import signal
import sys
import threading
import warnings
from typing import List, Optional

from tg_intrinsic.errors import interruption_behind

from .common import (ArgumentParser, HelpFormatter, common_options, one_line,
                     user_message)

COMMANDS = ('demo', 'train', 'precompute', 'solve', 'svbrdf', 'info')

# Errors that mean "the input or the request is wrong", not "the library
# is broken": reported on one line with exit code 2. Every OSError is one
# (a file missing or unreadable, a name too long, a full or read-only
# disk): the machine's state, which the user can change.
USER_ERRORS = (ValueError, OSError)


class Terminated(KeyboardInterrupt):
    """A stop asked by a signal other than Ctrl-C (``kill``, a closed
    terminal): handled like Ctrl-C, so every result folder is cleaned."""

    def __init__(self, signum: int):
        super().__init__(signal.Signals(signum).name)
        self.signum = signum


def _terminate(signum, frame):
    raise Terminated(signum)


def _stop_signals():
    """Makes SIGTERM and SIGHUP raise :class:`Terminated` (main thread
    only); returns the handlers to put back."""
    if threading.current_thread() is not threading.main_thread():
        return {}
    return {signum: signal.signal(signum, _terminate)
            for signum in (getattr(signal, 'SIGTERM', None),
                           getattr(signal, 'SIGHUP', None))
            if signum is not None}


def build_parser() -> ArgumentParser:
    shared = common_options()
    parser = ArgumentParser(
        prog='tg-intrinsic', parents=[shared], formatter_class=HelpFormatter,
        description='Learning and computing on curved surfaces: DeltaConv, '
        'Harmonic Surface Networks, Gravo MG and frequency-domain SVBRDF '
        'recovery.',
        epilog='Run "tg-intrinsic COMMAND --help" for the options and a '
        'worked example of each command.')
    from tg_intrinsic import __version__
    parser.add_argument('--version', action='version',
                        version=f'tg-intrinsic {__version__}')
    sub = parser.add_subparsers(dest='command', metavar='COMMAND',
                                parser_class=ArgumentParser)
    for name in COMMANDS:
        module = importlib.import_module(f'tg_intrinsic.cli.{name}')
        command = sub.add_parser(
            name, parents=[shared], help=module.HELP,
            description=module.__doc__.strip().split('\n\n')[0],
            epilog=module.EXAMPLE,
            formatter_class=HelpFormatter)
        module.add_arguments(command)
        command.set_defaults(run=module.run)
    return parser


def _show_warning(message, category, filename, lineno, file=None,
                  line=None):
    print(f"tg-intrinsic: warning: {one_line(message)}", file=sys.stderr)


def main(argv: Optional[List[str]] = None) -> int:
    """Runs one sub-command; returns the exit code (0, 1 on an unexpected
    failure, 2 on a user mistake, 130 when interrupted, 128 + the signal's
    number when stopped by SIGTERM or SIGHUP)."""
    parser = build_parser()
    try:
        args = parser.parse_args(argv)
    except SystemExit as done:  # --help (0) or a rejected argument (2)
        return done.code if isinstance(done.code, int) else 2
    args.debug = getattr(args, 'debug', False)
    args.quiet = getattr(args, 'quiet', False)
    if args.command is None:
        parser.print_help()
        print(f"tg-intrinsic: error: give a COMMAND: {', '.join(COMMANDS)}",
              file=sys.stderr)
        return 2
    prog = f'tg-intrinsic {args.command}'
    handlers = _stop_signals()
    try:
        return _run(args, prog)
    finally:
        for signum, handler in handlers.items():
            signal.signal(signum, handler)


def _run_stopped(prog: str, stop: KeyboardInterrupt) -> int:
    """Says that the run was stopped (Ctrl-C, SIGTERM, SIGHUP) and what
    was kept; the exit code, 128 + the signal's number."""
    signum = getattr(stop, 'signum', signal.SIGINT)
    what = 'interrupted' if signum == signal.SIGINT else f'stopped by {stop}'
    print(f"{prog}: {what}; no file was left half-written and earlier "
          f"results are as they were (train --resume continues from the "
          f"last checkpoint)", file=sys.stderr)
    return 128 + signum


def _run(args, prog: str) -> int:
    with warnings.catch_warnings():
        if not args.debug:
            warnings.showwarning = _show_warning
        try:
            return args.run(args) or 0
        except SystemExit as done:  # a late parser.error(): already said
            return done.code if isinstance(done.code, int) else 2
        except USER_ERRORS as error:
            if args.debug:
                raise
            print(f"{prog}: error: {user_message(error)}", file=sys.stderr)
            return 2
        except KeyboardInterrupt as stop:
            if args.debug:
                raise
            return _run_stopped(prog, stop)
        except Exception as error:  # noqa: BLE001 - reported, not hidden
            if args.debug:
                raise
            stop = interruption_behind(error)
            if stop is not None:  # a signal inside a compiled function
                return _run_stopped(prog, stop)
            print(f"{prog}: unexpected {type(error).__name__}: "
                  f"{one_line(error)} (rerun with --debug for the traceback "
                  f"and please report it)", file=sys.stderr)
            return 1


def entry_point():
    """The ``tg-intrinsic`` console script."""
    sys.exit(main())
