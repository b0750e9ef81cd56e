"""What slam counts and reports: its inputs' rates, the filter's fusions and refusals, slip recovery and the
occupancy grid, in `/diagnostics` (1 Hz), and the throttled warnings of a map that is full, a
relocalization, and a robot that moves without observations.

Statuses (diagnostic_msgs/DiagnosticStatus, hardware id ``slam``)
    `slam: <motion_source>`, `slam: <observation topic>`: rates; ERROR after ``STALE_S`` of the node's clock
        without a message.
    `slam: motion gate`: the motion samples refused (implausible: a time gap, faster than the robot's
        speed bounds), the silences of the motion stream bridged (and the longest) and its restarts so far,
        with the last reason; WARN when some came since the last report.
    `slam: filter`: mode, landmarks mapped and tentative, landmarks removed (the LiDAR saw through them),
        observations fused, rejected and (localization) unmapped, arrays skipped, time per applied scan;
        WARN when observations were rejected or arrays skipped since the last report.
    `slam: motion vs LiDAR` (`turtlelib.estimation.slip_recovery`): WARN naming the cause while scans
        contradict the wheels' motion and for ``slip_report_s`` after each relocalization against the map,
        ERROR when they keep coming; scans held, relocalizations and stalls so far, the last correction's
        size.
    `slam: occupancy grid` (`nuslam.grid_mapping`), when the grid is on.
"""

from __future__ import annotations

import numpy as np
from diagnostic_msgs.msg import DiagnosticStatus

from nuslam.grid_mapping import GridMapping
from nuturtle_ros_common.diagnostics import (
    ERROR,
    OK,
    STALE_S,
    WARN,
    DiagnosticsPublisher,
    DurationMonitor,
    InputMonitor,
)
from nuturtle_ros_common.diagnostics import status as diagnostic_status
from nuturtle_ros_common.throttle import SourceWarnings
from turtlelib import EkfSlam, Outcome, ScanResult
from turtlelib.estimation.landmark_removal import LandmarkRemoval
from turtlelib.estimation.slip_recovery import SlipRecovery
from turtlelib.motion.sample_gate import GateTally

# SlipStatus.level -> diagnostic level
SLIP_LEVELS = {"ok": OK, "warn": WARN, "error": ERROR}


class SlamReport:
    """slam's counts and statuses (module docstring) over its ``slam`` filter, ``recovery`` and ``grid``;
    the inputs are ``motion_topic`` and ``observation_topic``, watched from ``started_ns`` (node clock), the
    motion samples gated with the totals ``motion_tally``; ``removal`` removes the landmarks the LiDAR sees
    through (None: off)."""

    def __init__(
        self,
        slam: EkfSlam,
        recovery: SlipRecovery,
        grid: GridMapping,
        warnings: SourceWarnings,
        topics: tuple[str, str],
        started_ns: int,
        motion_tally: GateTally,
        removal: LandmarkRemoval | None = None,
    ) -> None:
        self._slam, self._recovery, self._grid, self._warnings = slam, recovery, grid, warnings
        self._removal = removal
        self._motion_tally = motion_tally
        self._motion_topic = topics[0]
        motion_topic, self.observation_topic = topics
        self.motion_input = InputMonitor(motion_topic, started_ns, STALE_S)
        self.observation_input = InputMonitor(self.observation_topic, started_ns, STALE_S)
        self._update_time = DurationMonitor()
        self.counts = {"fused": 0, "rejected": 0, "unmapped": 0, "skipped": 0, "arrays_applied": 0}
        self._reported = {"skipped": 0, "rejected": 0, "motion": (0, 0, 0)}

    def applied(self, results: list[ScanResult], elapsed_ms: float) -> None:
        """Count the observation arrays among the applied measurements (a pose source's have no association)
        and the time of the call that applied them; warn when observations were rejected because the map is
        full, and at each relocalization against the map."""
        arrays = [result for result in results if result.association is not None]
        if not arrays:
            return
        self._update_time.add(elapsed_ms)
        self.counts["arrays_applied"] += len(arrays)
        for result in arrays:
            tally = result.association.counts
            self.counts["rejected"] += tally["rejected"]
            self.counts["unmapped"] += tally["unmapped"]
            self.counts["fused"] += tally["matched"] + tally["new"]
            if tally["rejected"] and self._slam.map_full:
                self._warnings.warn(
                    "map",
                    f"the map holds max_landmarks = {self._slam.config.max_landmarks} landmarks: "
                    "new ones are not added",
                )
            if result.outcome is Outcome.RELOCALIZED:
                self._warnings.warn("slip", self._recovery.status.message)

    @property
    def landmarks_removed(self) -> int:
        """Confirmed landmarks removed so far because the LiDAR saw through them (0 without removal)."""
        return 0 if self._removal is None else len(self._removal.removals)

    def skipped(self, error: Exception) -> None:
        """An observation array refused (warned, throttled, and counted)."""
        topic = self.observation_topic
        self._warnings.warn(topic, f"{topic} skipped: {error}")
        self.counts["skipped"] += 1

    def silent(self, silent_s: float) -> None:
        """The robot moved ``silent_s`` without an observation arriving: warn (throttled)."""
        topic = self.observation_topic
        source = "nusim's fake sensor" if topic == "fake_sensor" else "the landmarks node"
        self._warnings.warn(
            "observations",
            f"no {topic} for {silent_s:.1f} s while the robot moves: slam is only dead-reckoning "
            f"(is {source} running and publishing {topic}"
            + ("? Its /diagnostics count the scans it refuses)" if topic == "landmarks" else "?)"),
        )

    def statuses(self, now_ns: int) -> list[DiagnosticStatus]:
        """The statuses (module docstring) at ``now_ns`` (node clock)."""
        skipped = self.counts["skipped"] - self._reported["skipped"]
        rejected = self.counts["rejected"] - self._reported["rejected"]
        motion = self._motion_status()
        self._reported = {"skipped": self.counts["skipped"], "rejected": self.counts["rejected"],
                          "motion": self._motion_counts()}  # fmt: skip
        slam = self._slam
        mapped, tentative = len(slam.landmark_ids), len(slam.tentative_ids)
        message = f"{slam.config.mode}: {mapped} landmarks mapped, {tentative} tentative"
        if skipped or rejected:
            period = f"{DiagnosticsPublisher.PERIOD_S:g} s"
            message += f"; in the last {period} {skipped} arrays skipped, {rejected} observations rejected"
        values = {
            "landmarks_mapped": mapped,
            "landmarks_tentative": tentative,
            "observations_fused": self.counts["fused"],
            "observations_rejected": self.counts["rejected"],
            "observations_unmapped": self.counts["unmapped"],
            "observation_arrays_skipped": self.counts["skipped"],
            "landmarks_removed": self.landmarks_removed,
            **self._update_time.values("scan_update"),
        }
        slip = self._recovery.status
        slip_values = {"scans_held": slip.held, "relocalizations": slip.relocalized, "stalls": slip.stalls}
        if slip.last_correction is not None:
            c = slip.last_correction
            slip_values["last_correction_m"] = round(float(np.hypot(c.x, c.y)), 3)
            slip_values["last_correction_rad"] = round(c.theta, 3)
        grid = self._grid.status()
        return [
            self.motion_input.status("slam", now_ns),
            motion,
            self.observation_input.status("slam", now_ns),
            diagnostic_status("slam: filter", "slam", WARN if skipped or rejected else OK, message, values),
            diagnostic_status(
                "slam: motion vs LiDAR", "slam", SLIP_LEVELS[slip.level], slip.message, slip_values
            ),
            *([grid] if grid is not None else []),
        ]

    def _motion_counts(self) -> tuple[int, int, int]:
        """The motion gate's refused samples, bridged silences and restarts so far."""
        tally = self._motion_tally
        return tally.refused, tally.bridged, tally.restarts

    def _motion_status(self) -> DiagnosticStatus:
        """`slam: motion gate`: the refused motion samples, bridged silences and restarts so far, WARN when
        some are new."""
        tally, topic = self._motion_tally, self._motion_topic
        new = self._motion_counts() != self._reported["motion"]
        message = f"every {topic} sample plausible"
        if any(self._motion_counts()):
            message = (
                f"{tally.refused} {topic} samples refused, {tally.bridged} silences bridged (the longest "
                f"{tally.longest_bridge_s:.3f} s), {tally.restarts} restarts of the stream so far; the last: "
                f"{tally.last_reason}"
            )
        values = {
            "motion_samples_refused": tally.refused,
            "motion_silences_bridged": tally.bridged,
            "motion_longest_bridge_s": round(tally.longest_bridge_s, 3),
            "motion_restarts": tally.restarts,
        }
        return diagnostic_status("slam: motion gate", "slam", WARN if new else OK, message, values)
