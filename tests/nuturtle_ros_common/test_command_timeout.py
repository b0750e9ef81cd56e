"""CommandWatchdog: a command holds for cmd_timeout, then expires once (hand-computed times)."""

import math

import pytest

from nuturtle_ros_common.command_timeout import CommandTimeoutConfig, CommandWatchdog

MS = 1_000_000


def test_expires_once_after_the_timeout():
    watchdog = CommandWatchdog(CommandTimeoutConfig(cmd_timeout=0.5))
    assert not watchdog.expired(0)  # no command yet
    watchdog.command(100 * MS)
    assert not watchdog.expired(600 * MS)  # exactly 0.5 s: still holds
    assert watchdog.expired(600 * MS + 1)
    assert not watchdog.expired(700 * MS)  # once
    watchdog.command(800 * MS)
    assert not watchdog.expired(1200 * MS)
    assert watchdog.expired(1400 * MS)


def test_a_newer_command_restarts_the_timeout():
    watchdog = CommandWatchdog(CommandTimeoutConfig(cmd_timeout=0.5))
    for t in range(0, 5000, 400):
        watchdog.command(t * MS)
        assert not watchdog.expired(t * MS + 450 * MS)


def test_zero_never_expires():
    watchdog = CommandWatchdog(CommandTimeoutConfig(cmd_timeout=0.0))
    watchdog.command(0)
    assert not watchdog.expired(10**15)


@pytest.mark.parametrize("value", [-0.1, math.nan, math.inf])
def test_invalid_timeouts_raise(value):
    with pytest.raises(ValueError, match="cmd_timeout"):
        CommandTimeoutConfig(cmd_timeout=value)
