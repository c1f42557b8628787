"""What every sub-command shares: the one-line argument errors, the
number types, progress bars and timed stages."""
import argparse

import pytest

from tg_intrinsic.cli import main
from tg_intrinsic.cli.common import (ArgumentParser, common_options,
                                     default_of, nonnegative_float,
                                     nonnegative_int, one_line,
                                     positive_float, positive_int, progress,
                                     stage)

from tests.cli import assert_user_error, run_cli


def test_a_bad_argument_is_one_line_and_exit_code_2(capsys):
    parser = ArgumentParser(prog='tg-intrinsic thing')
    parser.add_argument('--count', type=positive_int)
    with pytest.raises(SystemExit) as done:
        parser.parse_args(['--count', '0'])
    assert done.value.code == 2
    out, err = capsys.readouterr()
    assert out == '' and 'usage' not in err
    assert err == ("tg-intrinsic thing: error: argument --count: must be at "
                   "least 1, got '0' (see tg-intrinsic thing --help)\n")


@pytest.mark.parametrize('kind,text,value', [
    (positive_float, '2.5', 2.5), (positive_float, '1e-300', 1e-300),
    (nonnegative_float, '0', 0.0), (nonnegative_float, '-0.0', 0.0),
    (positive_int, '1', 1), (positive_int, '12', 12),
    (nonnegative_int, '0', 0)])
def test_numbers_that_are_accepted(kind, text, value):
    result = kind(text)
    assert result == value and type(result) is type(value)


@pytest.mark.parametrize('kind,text,message', [
    (positive_float, '0', "must be greater than 0.0, got '0'"),
    (positive_float, '-1', "must be greater than 0.0, got '-1'"),
    (positive_float, 'nan', "must be finite, got 'nan'"),
    (positive_float, 'inf', "must be finite, got 'inf'"),
    (positive_float, 'lots', "expected a number, got 'lots'"),
    (nonnegative_float, '-1e-9', "must be at least 0.0, got '-1e-9'"),
    (nonnegative_float, '-inf', "must be finite, got '-inf'"),
    (positive_int, '0', "must be at least 1, got '0'"),
    (positive_int, '1.5', "expected an integer, got '1.5'"),
    (positive_int, '', "expected an integer, got ''"),
    (nonnegative_int, '-1', "must be at least 0, got '-1'")])
def test_numbers_that_are_rejected_say_why(kind, text, message):
    with pytest.raises(argparse.ArgumentTypeError) as info:
        kind(text)
    assert str(info.value) == message


@pytest.mark.parametrize('argv,needles', [
    (['--smooth', 'nan'], ['argument --smooth', "must be finite, got 'nan'"]),
    (['--smooth', '0'], ['--smooth', "must be greater than 0.0, got '0'"]),
    (['--smooth', '1', '--max-cycles', '2.5'],
     ['--max-cycles', "expected an integer, got '2.5'"]),
    (['--poisson', '1', '--lower-bound', '0'],
     ['--lower-bound', "must be at least 1, got '0'"]),
])
def test_a_sub_command_reports_a_bad_number_on_one_line(capsys, argv,
                                                       needles):
    # rejected while parsing, before the (missing) mesh is read
    code, _, err = run_cli(capsys, 'solve', 'missing.obj', *argv)
    assert_user_error(code, err, 'solve', *needles)
    assert err.rstrip().endswith('(see tg-intrinsic solve --help)')


def test_help_shows_the_librarys_defaults(capsys):
    from tg_intrinsic.solvers import smooth
    code, text, _ = run_cli(capsys, 'solve', '--help')
    assert code == 0
    assert f"(default: {default_of(smooth, 'tol')}" in ' '.join(text.split())
    assert f"(default: {default_of(smooth, 'max_iter')})" in \
        ' '.join(text.split())


def test_one_line():
    assert one_line('a\n  b\tc\n\n d ') == 'a b c d'
    assert one_line(ValueError('first line\nsecond')) == \
        'first line second'
    assert one_line('') == ''


def test_default_of_reads_the_librarys_default():
    def solve(x, tol=1e-8, *, steps=10):
        return x

    class Fit:
        def __init__(self, rank=3):
            self.rank = rank

    assert default_of(solve, 'tol') == 1e-8
    assert default_of(solve, 'steps') == 10
    assert default_of(Fit, 'rank') == 3
    with pytest.raises(KeyError):
        default_of(solve, 'missing')


def test_progress_is_silent_with_quiet(capsys):
    assert list(progress(range(5), 'work', quiet=True)) == [0, 1, 2, 3, 4]
    bar = progress(iter('abc'), 'work', quiet=False, total=3, unit='x')
    assert bar.total == 3 and bar.unit == 'x' and not bar.disable
    assert list(bar) == ['a', 'b', 'c']
    assert progress([], 'work', quiet=True).disable


def test_common_options_before_or_after_the_command(capsys):
    shared = common_options()
    parser = ArgumentParser(prog='p', parents=[shared])
    sub = parser.add_subparsers(dest='command')
    sub.add_parser('go', parents=[shared])
    args = parser.parse_args(['--debug', 'go', '--quiet'])
    assert args.debug and args.quiet
    args = parser.parse_args(['go'])
    # absent, not False: a flag given before the command survives the
    # sub-command's parser
    assert not hasattr(args, 'debug') and not hasattr(args, 'quiet')
    # and through the real command line
    code, out, _ = run_cli(capsys, 'info', '--quiet', '--json')
    assert code == 0 and out.lstrip().startswith('{')


def test_stage_reports_its_progress(capsys):
    seconds = {}
    with stage('reading', quiet=False, seconds=seconds, key='read'):
        pass
    err = capsys.readouterr().err.splitlines()
    assert err[0] == 'reading ...'
    assert err[1] == f"reading: {seconds['read']:.2f} s"
    assert seconds['read'] >= 0
    with stage('quiet', quiet=True, seconds=seconds, key='q'):
        pass
    assert capsys.readouterr().err == '' and 'q' in seconds
    with pytest.raises(ZeroDivisionError):
        with stage('solving', quiet=False, seconds=seconds, key='solve'):
            1 / 0
    assert capsys.readouterr().err.splitlines() == ['solving ...',
                                                    'solving: failed']
    assert 'solve' not in seconds  # no time for a stage that failed


def test_a_usage_error_from_a_command_is_one_line(tmp_path, capsys):
    (tmp_path / 'taken').write_text('not a folder')
    code, _, err = run_cli(capsys, 'demo', '--quick', '--out',
                           tmp_path / 'taken')
    assert_user_error(code, err, 'demo', str(tmp_path / 'taken'),
                      'is a file; give a folder')
    assert (tmp_path / 'taken').read_text() == 'not a folder'
    with pytest.raises(ValueError, match='is a file'):
        main(['demo', '--quick', '--out', str(tmp_path / 'taken'),
              '--debug'])
