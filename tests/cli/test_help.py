"""``--help`` of every command: every option says what it does, lines
break only between words (a file or protocol name copied from the help is
whole), and train's options that a protocol fills show each protocol's
value."""
import argparse

import pytest

from tg_intrinsic.cli import COMMANDS, build_parser
from tg_intrinsic.protocols import PROTOCOLS
from tg_intrinsic.training.options import protocol_defaults


def parsers():
    """Every (sub-)command's parser by its name, nested ones included."""
    found = {}

    def visit(parser):
        found[parser.prog] = parser
        for action in parser._actions:
            if isinstance(action, argparse._SubParsersAction):
                for child in action.choices.values():
                    visit(child)
    visit(build_parser())
    return found


PARSERS = parsers()


def test_every_command_is_visited():
    assert {f'tg-intrinsic {name}' for name in COMMANDS} <= set(PARSERS)
    assert 'tg-intrinsic precompute mls' in PARSERS


@pytest.mark.parametrize('prog', sorted(PARSERS))
def test_every_option_says_what_it_does(prog):
    actions = []
    for action in PARSERS[prog]._actions:
        if isinstance(action, argparse._SubParsersAction):
            actions += action._choices_actions  # one line per command
        elif action.help != argparse.SUPPRESS:
            actions.append(action)
    for action in actions:
        assert action.help and len(action.help.split()) >= 2, \
            f"{prog} {'/'.join(action.option_strings) or action.dest}"


@pytest.mark.parametrize('prog', sorted(PARSERS))
def test_help_breaks_lines_between_words_only(prog, monkeypatch):
    monkeypatch.setenv('COLUMNS', '80')
    parser = PARSERS[prog]
    shown = parser.format_help().split()
    formatter = parser._get_formatter()
    for action in parser._actions:
        if not action.help or action.help == argparse.SUPPRESS:
            continue
        text = formatter._expand_help(action)
        for word in text.split():
            assert word in shown, f'{prog}: {word!r} is broken in --help'


def test_protocol_values_are_shown_per_protocol(monkeypatch):
    monkeypatch.setenv('COLUMNS', '80')
    text = ' '.join(PARSERS['tg-intrinsic train'].format_help().split())
    assert ('--lr LR the learning rate at the start; default from '
            '--protocol: 0.1 (deltanet-modelnet40, deltanet-scanobjectnn, '
            'deltanet-shrec11, deltanet-shapenet-part), 0.005 '
            '(deltanet-human-seg), 0.01 (hsn-shrec11, hsn-human-seg)') \
        in text
    # a model's own option lists that model's protocols only
    assert protocol_defaults('k', 'deltanet') == (
        'default from --protocol: 20 (deltanet-modelnet40, '
        'deltanet-scanobjectnn, deltanet-shrec11, deltanet-human-seg), 30 '
        '(deltanet-shapenet-part)')
    assert protocol_defaults('gamma') == \
        'default from --protocol: 0.1 in every one'
    # every protocol appears under every option it fills
    for field in ('epochs', 'batch_size', 'rotate', 'scale'):
        assert all(name in protocol_defaults(field) for name in PROTOCOLS)
