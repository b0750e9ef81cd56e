"""nuturtle_eval.command_help: an option's help says its default once, and only a default it has."""

import argparse

import pytest

from nuturtle_eval.command_help import DefaultsHelpFormatter


def _help_of(**argument) -> str:
    """The help entry of one option ``--x`` built with ``argument`` (after ``-h``'s), on one line."""
    parser = argparse.ArgumentParser(prog="p", formatter_class=DefaultsHelpFormatter)
    parser.add_argument("--x", **argument)
    return " ".join(parser.format_help().partition("show this help message and exit")[2].split())


@pytest.mark.parametrize(
    ("argument", "shown"),
    [
        ({"default": "out/latest", "help": "folder"}, "--x X folder (default: out/latest)"),
        ({"type": float, "default": 20.0, "help": "bound"}, "--x X bound (default: 20.0)"),
        ({"type": int, "default": 0, "help": "seed"}, "--x X seed (default: 0)"),
        ({"default": "50%", "help": "share"}, "--x X share (default: 50%)"),
        ({"default": None, "help": "file"}, "--x X file"),
        (
            {"default": None, "help": "file (default: the committed one)"},
            "--x X file (default: the committed one)",
        ),
        (
            {"default": "known", "help": "known (the default) or unknown"},
            "--x X known (the default) or unknown",
        ),
        ({"default": argparse.SUPPRESS, "help": "domain"}, "--x X domain"),
        (
            {"type": float, "nargs": 3, "metavar": "V", "default": (0.05, 0.05, 0.05), "help": "stds"},
            "--x V V V stds (default: 0.05 0.05 0.05)",
        ),
    ],
)
def test_an_option_shows_its_default_once_and_none_it_does_not_have(argument, shown):
    assert _help_of(**argument) == shown


def test_a_flag_shows_no_default_and_an_option_without_help_none_either():
    parser = argparse.ArgumentParser(prog="p", formatter_class=DefaultsHelpFormatter)
    parser.add_argument("--check", action="store_true", help="exit 1 on a failed target")
    parser.add_argument("--no-plots", dest="plots", action="store_false", help="metrics only")
    parser.add_argument("--y", default="a")
    text = " ".join(parser.format_help().split())
    assert "--check exit 1 on a failed target --no-plots metrics only --y Y" in text
    assert "default" not in text
