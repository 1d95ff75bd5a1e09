"""The command line's --help: every command listed in plain text at the top, every argument
with a help text and its default, and commands that differ with help of their own."""
import argparse
import re

import pytest

from nonfragile_tracker.cli import build_parser


def _parsers(parser, path=()):
    yield path, parser
    for action in parser._actions:
        if isinstance(action, argparse._SubParsersAction):
            for name, sub in action.choices.items():
                yield from _parsers(sub, path + (name,))


PARSERS = dict(_parsers(build_parser()))


def _flat(text):
    return re.sub(r'\s+', ' ', text)


def test_the_top_level_help_is_plain_and_lists_every_command():
    top = PARSERS[()]
    text = top.format_help()
    commands = [p[0] for p in PARSERS if len(p) == 1]
    assert len(commands) == 15 and 'bringup' in commands and 'sweep' in commands and 'trajectory' in commands
    for name in commands:
        assert re.search(rf'^\s+{re.escape(name)}\b', text, re.MULTILINE), name
    assert '``' not in text and '::' not in text             # no RST markup
    assert 'differential-drive' in _flat(text) and 'exit codes' in text


@pytest.mark.parametrize('path', [p for p in PARSERS if p], ids=' '.join)
def test_every_argument_has_help_and_shows_its_default(path):
    parser = PARSERS[path]
    text = _flat(parser.format_help())
    for action in parser._actions:
        if isinstance(action, (argparse._HelpAction, argparse._SubParsersAction)):
            continue
        assert action.help, (path, action.dest)
        d = action.default
        if action.option_strings and d is not None and not isinstance(d, bool) and d != []:
            shown = {str(d), ' '.join(f'{x:g}' for x in d) if isinstance(d, list) else
                     (f'{d:g}' if isinstance(d, float) else str(d))}
            assert any(s in text for s in shown), (path, action.option_strings, d)


def test_margins_has_its_own_options_and_help():
    analyse, margins = PARSERS[('analyse',)], PARSERS[('margins',)]
    options = {o for a in margins._actions for o in a.option_strings}
    assert '--no-margins' not in options and '--tracking' not in options
    assert {'--gains', '--paper', '--json'} <= options
    assert margins.description != analyse.description
    assert '--jobs' not in PARSERS[('sweep',)].format_help()      # sweep has --workers
