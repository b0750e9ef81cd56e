"""Throttled warnings: how the nodes report bad input without flooding the log.

A node that skips a message warns at most once per ``WARN_THROTTLE_S`` from each place; `SourceWarnings`
throttles per input (one child logger per source: rclpy throttles per logger and call site), so a flood
on one topic never hides a warning about another.
"""

from __future__ import annotations

from rclpy.impl.rcutils_logger import RcutilsLogger

# Minimum time between two warnings from the same place (s)
WARN_THROTTLE_S = 2.0


class SourceWarnings:
    """``warn(source, text)``: a warning on ``<logger>.<source>``, throttled per source."""

    def __init__(self, logger: RcutilsLogger) -> None:
        self._logger = logger
        self._children: dict[str, RcutilsLogger] = {}

    def warn(self, source: str, text: str) -> None:
        child = self._children.get(source)
        if child is None:
            child = self._children[source] = self._logger.get_child(source)
        child.warning(text, throttle_duration_sec=WARN_THROTTLE_S)
