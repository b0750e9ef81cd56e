"""The ``--help`` of the commands (the demo, the replay, the dataset runs): each option's default said once.
No ROS.

argparse's ``ArgumentDefaultsHelpFormatter`` appends ``(default: %(default)s)`` to every option, so an option
whose default the caller decides (``None``: "the params file's, else the node's") reads ``(default: None)``
after the help's own words, and a flag reads ``(default: False)``. :class:`DefaultsHelpFormatter` appends the
default only where it is a value the option takes when absent and the help does not already say it.
"""

from __future__ import annotations

import argparse
from typing import Any

# the word by which an option's help says its default itself
DEFAULT_WORD = "default"


class DefaultsHelpFormatter(argparse.HelpFormatter):
    """argparse's help with `` (default: VALUE)`` after an option's help when it has a default value (not
    None or suppressed), takes a value (not a flag such as ``--check``) and its help does not contain the
    word "default"; a sequence default is shown as typed (``0.05 0.05 0.05``)."""

    def _get_help_string(self, action: argparse.Action) -> str | None:
        text = action.help
        if text is None or DEFAULT_WORD in text or not shows_default(action):
            return text
        return f"{text} (default: {default_text(action.default)})"


def shows_default(action: argparse.Action) -> bool:
    """Whether ``action`` has a default worth printing: a value taken when the option is absent (not None,
    not suppressed) by an option that takes a value (``nargs`` 0: a flag, whose default is its absence)."""
    return action.default is not None and action.default is not argparse.SUPPRESS and action.nargs != 0


def default_text(value: Any) -> str:
    """``value`` as it would be typed on the command line (a list or tuple: its items, space-separated),
    with ``%`` escaped for argparse's help expansion."""
    shown = " ".join(map(str, value)) if isinstance(value, (list, tuple)) else str(value)
    return shown.replace("%", "%%")
