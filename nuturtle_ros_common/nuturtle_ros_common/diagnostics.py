"""`/diagnostics` (diagnostic_msgs/DiagnosticArray) of the nodes: input rates, timing, counts, and levels
that mean something.

* :class:`InputMonitor` watches one input topic: the arrival times (node clock, integer ns) of its last
  ``WINDOW`` messages give its rate; the level is ERROR when nothing arrived for ``stale_s`` (or never
  since start-up, once that long has passed), WARN when it arrives but below ``min_rate_hz``, else OK.
* :class:`DurationMonitor` keeps the last ``WINDOW`` durations of a step (ms): median and maximum.
* :func:`status` builds one ``DiagnosticStatus`` with its key-value pairs, and
  :class:`DiagnosticsPublisher` publishes a node's statuses at 1 Hz.

Viewers (`rqt_runtime_monitor`, Foxglove's diagnostics panel, `ros2 topic echo /diagnostics`) show each
status by its name ``<node>: <part>``. `/diagnostics` is one topic for every robot (as diagnostic_updater's
and the aggregator's), so a node in a namespace names its statuses ``<namespace>/<node>: <part>``
(``tb3_0/slam: scan registration``) and its ``hardware_id`` ``<namespace>/<node>``.
"""

from __future__ import annotations

import statistics
from collections import deque
from collections.abc import Callable, Mapping

from diagnostic_msgs.msg import DiagnosticArray, DiagnosticStatus, KeyValue
from rclpy.node import Node

from turtlelib.util.timebase import NS_PER_S

OK = DiagnosticStatus.OK
WARN = DiagnosticStatus.WARN
ERROR = DiagnosticStatus.ERROR
WINDOW = 50


def status(
    name: str, hardware_id: str, level: bytes, message: str, values: Mapping[str, object]
) -> DiagnosticStatus:
    """A ``DiagnosticStatus`` named ``name`` with ``values`` as key-value strings (floats to 4 digits)."""
    pairs = [
        KeyValue(key=key, value=f"{value:.4g}" if isinstance(value, float) else str(value))
        for key, value in values.items()
    ]
    return DiagnosticStatus(level=level, name=name, message=message, hardware_id=hardware_id, values=pairs)


# An input silent this long (s, node clock) is an ERROR in /diagnostics (the nodes' inputs)
STALE_S = 2.0


class InputMonitor:
    """Arrivals of one input (module docstring); ``started_ns`` is the node's start on its clock."""

    def __init__(self, topic: str, started_ns: int, stale_s: float, min_rate_hz: float = 0.0) -> None:
        self.topic = topic
        self._started_ns = started_ns
        self._stale_ns = round(stale_s * NS_PER_S)
        self._min_rate_hz = min_rate_hz
        self._arrivals: deque[int] = deque(maxlen=WINDOW)
        self.count = 0

    def arrived(self, t_ns: int) -> None:
        self._arrivals.append(t_ns)
        self.count += 1

    def rate_hz(self) -> float:
        """Messages per second over the window (0 with fewer than two)."""
        if len(self._arrivals) < 2 or self._arrivals[-1] <= self._arrivals[0]:
            return 0.0
        return (len(self._arrivals) - 1) * NS_PER_S / (self._arrivals[-1] - self._arrivals[0])

    def level(self, now_ns: int) -> tuple[bytes, str]:
        """``(level, message)`` at ``now_ns``."""
        last_ns = self._arrivals[-1] if self._arrivals else None
        silent_ns = now_ns - (self._started_ns if last_ns is None else last_ns)
        if silent_ns > self._stale_ns:
            what = "nothing yet" if last_ns is None else "nothing"
            return ERROR, f"{what} on {self.topic} for {silent_ns / NS_PER_S:.1f} s"
        rate = self.rate_hz()
        if last_ns is not None and len(self._arrivals) >= 2 and rate < self._min_rate_hz:
            return WARN, f"{self.topic} at {rate:.1f} Hz, below {self._min_rate_hz:.1f} Hz"
        return OK, f"{self.topic} at {rate:.1f} Hz"

    def values(self, now_ns: int) -> dict[str, object]:
        last_ns = self._arrivals[-1] if self._arrivals else None
        age = "never" if last_ns is None else (now_ns - last_ns) / NS_PER_S
        return {
            "topic": self.topic,
            "rate_hz": self.rate_hz(),
            "messages": self.count,
            "last_message_age_s": age,
        }

    def status(self, node: str, now_ns: int) -> DiagnosticStatus:
        level, message = self.level(now_ns)
        return status(f"{node}: {self.topic}", node, level, message, self.values(now_ns))


class DurationMonitor:
    """The last ``WINDOW`` durations (ms) of a step."""

    def __init__(self) -> None:
        self._durations_ms: deque[float] = deque(maxlen=WINDOW)

    def add(self, duration_ms: float) -> None:
        self._durations_ms.append(duration_ms)

    def values(self, name: str) -> dict[str, object]:
        if not self._durations_ms:
            return {f"{name}_ms_median": "none yet", f"{name}_ms_max": "none yet"}
        return {
            f"{name}_ms_median": statistics.median(self._durations_ms),
            f"{name}_ms_max": max(self._durations_ms),
        }


class DiagnosticsPublisher:
    """Publishes ``DiagnosticArray(status=statuses(now_ns))`` on `/diagnostics` every ``PERIOD_S`` of the
    node's clock (1 Hz, as diagnostic_updater does), names and hardware ids prefixed with the node's
    namespace (if any)."""

    PERIOD_S = 1.0

    def __init__(self, node: Node, statuses: Callable[[int], list[DiagnosticStatus]]) -> None:
        self._node = node
        self._statuses = statuses
        self._publisher = node.create_publisher(DiagnosticArray, "/diagnostics", 10)
        node.create_timer(self.PERIOD_S, self._publish)

    def _publish(self) -> None:
        now = self._node.get_clock().now()
        statuses = self._statuses(now.nanoseconds)
        namespace = self._node.get_namespace().strip("/")
        if namespace:
            for status in statuses:
                status.name, status.hardware_id = (
                    f"{namespace}/{status.name}",
                    f"{namespace}/{status.hardware_id}",
                )
        array = DiagnosticArray(status=statuses)
        array.header.stamp = now.to_msg()
        self._publisher.publish(array)
