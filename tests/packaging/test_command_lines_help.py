"""The ``--help`` of every command line (the demo, the replay, the dataset command and its subcommands), as
their real parsers print it: each option's default said once where it has one, never ``(default: None)``
nor a flag's ``(default: False)``."""

from __future__ import annotations

import argparse
import re

import pytest

from nuturtle_demo.cli import build_parser as demo_parser
from nuturtle_eval.command_help import shows_default
from nuturtle_eval.datasets.__main__ import build_parser as dataset_parser
from nuturtle_tools.replay import build_parser as replay_parser

# the start of an entry of the help's argument lists: two spaces, then the option or the positional
ENTRY = re.compile(r"^  (?=\S)", re.MULTILINE)


def _parsers() -> list[argparse.ArgumentParser]:
    """Every front-end's parser, the dataset command's subcommands included."""
    parsers = [demo_parser(), replay_parser(), dataset_parser()]
    for action in parsers[-1]._actions:
        if isinstance(action.choices, dict):
            parsers += action.choices.values()
    return parsers


def _entries(parser: argparse.ArgumentParser) -> dict[str, str]:
    """The help's entry of each argument, on one line, by its first option string (or positional name)."""
    text = parser.format_help()
    entries = {}
    for entry in ENTRY.split(text[text.index("\n\n") :])[1:]:
        words = entry.split()
        entries[words[0].rstrip(",")] = " ".join(words)
    return entries


@pytest.mark.parametrize("parser", _parsers(), ids=lambda parser: parser.prog)
def test_every_option_says_its_real_default_once(parser):
    entries = _entries(parser)
    for action in parser._actions:
        if action.help is None and not shows_default(action):
            continue
        entry = entries[(action.option_strings or [action.dest])[0]]
        assert "(default: None)" not in entry and "(default: False)" not in entry, entry
        # said once: by the formatter where the option has a value by default, else by the help's own words
        assert entry.count("default") == 1 if shows_default(action) else entry.count("default") <= 1, entry


def test_the_defaults_read_as_typed():
    demo = _entries(demo_parser())
    assert demo["--out"].endswith("(default: out/latest)")
    assert demo["--initial-pose-std"].endswith("(default: 0.05 0.05 0.05)")
    assert "default" not in demo["--map-file"] and "default" not in demo["--check"]
    replay = _entries(replay_parser())
    assert replay["--params"].endswith("(default: the demo's config.yaml next to a demo recording, if there)")
    assert replay["--wait-for-subscribers"].endswith("(default: 5.0)")
