"""A command watchdog: a velocity command holds for ``cmd_timeout`` seconds, then the wheels stop.

A robot must not keep driving on the last command of a teleop that crashed or a `ros2 topic pub` that
ended. The watchdog keeps the time of the newest command (integer ns, on the node's clock: simulation
time where it runs on /clock) and reports, once, when the command has expired::

    expired(t)  <=>  t - t_command > cmd_timeout   (cmd_timeout = 0: never)
"""

from __future__ import annotations

from dataclasses import dataclass

from turtlelib.util.timebase import NS_PER_S
from turtlelib.util.validation import non_negative, store


@dataclass(frozen=True)
class CommandTimeoutConfig:
    """``cmd_timeout`` (s, >= 0): how long a velocity command holds without a newer one (0: for ever)."""

    cmd_timeout: float = 0.5

    def __post_init__(self) -> None:
        store(self, ("cmd_timeout",), non_negative)


class CommandWatchdog:
    """The newest command's time and whether it has expired (module docstring)."""

    def __init__(self, config: CommandTimeoutConfig) -> None:
        self._timeout_ns = round(config.cmd_timeout * NS_PER_S)
        self._t_command_ns: int | None = None

    def command(self, t_ns: int) -> None:
        """A command arrived at ``t_ns``."""
        self._t_command_ns = t_ns

    def expired(self, t_ns: int) -> bool:
        """True once, at the first check more than ``cmd_timeout`` after the newest command."""
        if self._timeout_ns == 0 or self._t_command_ns is None:
            return False
        if t_ns - self._t_command_ns > self._timeout_ns:
            self._t_command_ns = None
            return True
        return False
