"""Throttled warnings: how the nodes report bad input without flooding the log.

A node that skips a message warns at most once per ``WARN_THROTTLE_S`` per input: `SourceWarnings`
throttles each source on its own (steady clock), so a flood on one topic never hides a warning about
another. The warnings go to the node's own logger: rclpy's child loggers are linked to /rosout by name, and
the older of two nodes of one name in a process (tests, a restarted node) unlinks the newer's when it is
collected.
"""

from __future__ import annotations

import time

from rclpy.impl.rcutils_logger import RcutilsLogger

# Minimum time between two warnings from the same source (s)
WARN_THROTTLE_S = 2.0


class SourceWarnings:
    """``warn(source, text)``: a warning on the node's logger, at most once per ``WARN_THROTTLE_S`` per
    ``source``."""

    def __init__(self, logger: RcutilsLogger) -> None:
        self._logger = logger
        self._last_s: dict[str, float] = {}

    def warn(self, source: str, text: str) -> None:
        now_s = time.monotonic()
        last_s = self._last_s.get(source)
        if last_s is not None and now_s - last_s < WARN_THROTTLE_S:
            return
        self._last_s[source] = now_s
        self._logger.warning(text)
