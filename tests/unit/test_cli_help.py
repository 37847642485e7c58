"""Every command's --help prints (a bare '%' in a help text breaks argparse's formatting)."""

import argparse

from autopilot.cli import build_parser


def _parsers(parser: argparse.ArgumentParser):
    yield parser
    for action in parser._actions:
        if isinstance(action, argparse._SubParsersAction):
            for sub in action.choices.values():
                yield from _parsers(sub)


def test_every_commands_help_formats():
    parsers = list(_parsers(build_parser()))
    assert len(parsers) > 20  # run, sim, bench and its benches, …
    for parser in parsers:
        assert parser.format_help().startswith("usage:"), parser.prog
