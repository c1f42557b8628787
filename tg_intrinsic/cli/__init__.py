"""The ``tg-intrinsic`` command line (also ``python -m tg_intrinsic``).

Sub-commands: ``demo``, ``train``, ``precompute``, ``solve``, ``svbrdf`` and
``info``; ``tg-intrinsic COMMAND --help`` shows a worked example of each.
This package parses arguments, reads and writes files and draws figures;
the maths lives in the library. A user mistake (a missing file, a bad
value) ends with one line on stderr and exit code 2; ``--debug`` shows the
traceback instead.
"""
import argparse
import importlib
import sys
import warnings
from typing import List, Optional

from .common import ArgumentParser, common_options, one_line

COMMANDS = ('demo', 'train', 'precompute', 'solve', 'svbrdf', 'info')

# Errors that mean "the input or the request is wrong", not "the library
# is broken": reported on one line with exit code 2.
USER_ERRORS = (ValueError, FileNotFoundError, IsADirectoryError,
               NotADirectoryError, PermissionError)


def build_parser() -> ArgumentParser:
    shared = common_options()
    parser = ArgumentParser(
        prog='tg-intrinsic', parents=[shared],
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
            formatter_class=argparse.RawDescriptionHelpFormatter)
        module.add_arguments(command)
        command.set_defaults(run=module.run)
    return parser


def _show_warning(message, category, filename, lineno, file=None,
                  line=None):
    print(f"tg-intrinsic: warning: {one_line(message)}", file=sys.stderr)


def main(argv: Optional[List[str]] = None) -> int:
    """Runs one sub-command; returns the exit code (0, 1 on an unexpected
    failure, 2 on a user mistake, 130 when interrupted)."""
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
            print(f"{prog}: error: {one_line(error)}", file=sys.stderr)
            return 2
        except KeyboardInterrupt:
            if args.debug:
                raise
            print(f"{prog}: interrupted; no file was left half-written "
                  f"and earlier results are as they were (train --resume "
                  f"continues from the last checkpoint)",
                  file=sys.stderr)
            return 130
        except Exception as error:  # noqa: BLE001 - reported, not hidden
            if args.debug:
                raise
            print(f"{prog}: unexpected {type(error).__name__}: "
                  f"{one_line(error)} (rerun with --debug for the traceback "
                  f"and please report it)", file=sys.stderr)
            return 1


def entry_point():
    """The ``tg-intrinsic`` console script."""
    sys.exit(main())
