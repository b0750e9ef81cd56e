"""Diagnostics levels (hand-made arrival times) and one status message's key-value pairs."""

from __future__ import annotations

from diagnostic_msgs.msg import DiagnosticStatus

from nuturtle_ros_common.diagnostics import DurationMonitor, InputMonitor, status

S = 1_000_000_000


def test_an_input_that_never_arrives_is_an_error_after_stale_s():
    monitor = InputMonitor("scan", started_ns=10 * S, stale_s=2.0)
    assert monitor.level(11 * S)[0] == DiagnosticStatus.OK  # still starting
    level, message = monitor.level(12 * S + 1)
    assert level == DiagnosticStatus.ERROR and "nothing yet on scan" in message


def test_rate_and_staleness_of_an_arriving_input():
    monitor = InputMonitor("scan", started_ns=0, stale_s=2.0, min_rate_hz=4.0)
    for k in range(11):
        monitor.arrived(k * S // 5)  # 5 Hz for 2 s
    assert monitor.rate_hz() == 5.0
    assert monitor.level(2 * S) == (DiagnosticStatus.OK, "scan at 5.0 Hz")
    level, message = monitor.level(4 * S + 1)
    assert level == DiagnosticStatus.ERROR and message == "nothing on scan for 2.0 s"
    slow = InputMonitor("scan", started_ns=0, stale_s=2.0, min_rate_hz=4.0)
    for k in range(5):
        slow.arrived(k * S // 2)  # 2 Hz
    assert slow.level(2 * S)[0] == DiagnosticStatus.WARN


def test_durations_and_status_values():
    durations = DurationMonitor()
    assert durations.values("update") == {"update_ms_median": "none yet", "update_ms_max": "none yet"}
    for value in (1.0, 3.0, 2.0):
        durations.add(value)
    assert durations.values("update") == {"update_ms_median": 2.0, "update_ms_max": 3.0}
    message = status("slam: filter", "slam", DiagnosticStatus.OK, "fine", {"landmarks": 3, "ms": 1.23456})
    assert message.name == "slam: filter" and message.level == DiagnosticStatus.OK
    assert [(pair.key, pair.value) for pair in message.values] == [("landmarks", "3"), ("ms", "1.235")]
