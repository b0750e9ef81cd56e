"""slam's LiDAR odometry (``scan_registration: true``): each `scan` registered to a local map of recent
scans with the motion input (wheels or odom) as its prior (`turtlelib.LidarOdometry`); the registered
motion, with its covariance, is what the filter predicts with (`turtlelib.MeasuredMotion`).

Timing: a scan stamped ``t_s`` is registered once the motion input reaches ``t_s`` (its pose there is the
prior's anchor; the input's poses are kept, interpolated between samples, ``INPUT_POSES`` of them), in stamp
order; it waits for that up to ``MAX_WAITING_SCANS`` newer scans. A scan older than the filter's newest
sample is skipped, but for the first ones (the input drives the filter at once until the first scan comes,
and a LiDAR's messages often arrive after the wheels'): they start the local map
(`turtlelib.LidarOdometry.seed_map`). While the LiDAR is quiet (none yet, or none stamped within
``QUIET_SCANS`` of its usual intervals and at least ``QUIET_MIN_NS`` of the newest input: unplugged,
stopped) the input's samples, ``LAG_NS`` behind the newest, are the filter's next motion samples themselves,
so slam is then exactly as without registration. A registered scan's pose becomes the filter's next motion
sample, so the filter runs at the newest registered scan, and the pose slam publishes at a newer input stamp
``t`` is the filter's at ``t_s`` moved on by the input's own motion from ``t_s`` to ``t``
(:meth:`ScanOdometry.moved_on`).

`/diagnostics` (`slam: scan registration`): what the pose rests on since the last report - scans registered,
scans degenerate (registered, but weak along a direction, as in a long corridor: WARN), scans on the motion
input alone (nothing to match: no map yet, too few returns), input samples taken alone while the LiDAR is
quiet, scans that only started the map (seeded) - and, with the landmark observations fused in that time,
ERROR when neither registration nor landmarks held the pose (the wheels alone: the estimate drifts as they
do).
"""

from __future__ import annotations

import math
from collections import deque
from collections.abc import Callable

import numpy as np
from diagnostic_msgs.msg import DiagnosticStatus
from numpy.typing import NDArray

from nuturtle_ros_common.diagnostics import ERROR, OK, WARN, status
from nuturtle_ros_common.throttle import SourceWarnings
from turtlelib import Transform2D, TwistNoise
from turtlelib.estimation.lidar_odometry import (
    Basis,
    LidarOdometry,
    LidarOdometryConfig,
    OdometryStep,
    scan_points,
)
from turtlelib.geometry.pose_buffer import PoseBuffer
from turtlelib.geometry.se2 import right_composition_jacobian
from turtlelib.sensing.range_scan import RangeScan
from turtlelib.util.timebase import NS_PER_S

# Motion-input poses kept to anchor scans (20 Hz joint_states: 50 s; 100 Hz odom: 10 s)
INPUT_POSES = 1000
# Scans that may wait for the motion input to reach their stamp
MAX_WAITING_SCANS = 10
# The LiDAR is quiet when no scan is stamped within QUIET_SCANS of its own intervals (their running mean)
# and at least QUIET_MIN_NS of the newest motion input; the input alone then drives the filter, LAG_NS
# behind the newest input (the scans' transport delay may be up to this: a later scan must still register)
QUIET_SCANS = 3.0
QUIET_MIN_NS = 1_000_000_000
LAG_NS = 500_000_000
# weight of the newest interval in the running mean of the scans' intervals
INTERVAL_GAIN = 0.1


class ScanOdometry:
    """The scans' registration between the motion input and slam's filter (module docstring).
    ``speed_bounds`` are the robot's ``(max_linear_speed, max_angular_speed)`` (m/s, rad/s)."""

    def __init__(
        self,
        config: LidarOdometryConfig,
        noise: TwistNoise,
        speed_bounds: tuple[float, float],
        warnings: SourceWarnings,
    ) -> None:
        self._odometry = LidarOdometry(config, noise, *speed_bounds)
        self.noise = noise
        self._warnings = warnings
        self._inputs = PoseBuffer(INPUT_POSES)
        self._waiting: deque[tuple[int, RangeScan, Transform2D]] = deque()
        self._last_ns: int | None = None
        self._newest_scan_ns: int | None = None
        self._interval_ns: float | None = None
        self._restarting = False
        self.counts = {basis.value: 0 for basis in Basis} | {"input_only": 0, "seeded": 0, "skipped": 0}
        self._reported = dict(self.counts)
        self.last: OdometryStep | None = None
        # told each step and its scan's body-frame points (n, 2; none for the input alone): slam's loop
        # closure (nuslam.loop_closing)
        self.step_listener: Callable[[OdometryStep, NDArray[np.float64]], None] | None = None

    def input(self, t_ns: int, T_input_body: Transform2D) -> None:
        """The motion input's pose at ``t_ns`` (after the previous one's)."""
        self._inputs.add(t_ns, T_input_body)

    def restart(self) -> None:
        """The motion input restarted (a gap, another odometry frame, a clock that jumped back): forget its
        poses and the waiting scans; the next scan (or, until one comes, the input's next pose) is registered
        to the kept local map from the last registered pose (`turtlelib.LidarOdometry.forget_input`), and
        restarts the filter's timeline if its stamp is not after the last one's."""
        self._inputs.clear()
        self._waiting.clear()
        self._odometry.forget_input()
        self._restarting = True
        # the scans' stamps on the old time base say nothing of the LiDAR on the new one
        self._newest_scan_ns = None

    def add_scan(self, t_ns: int, scan: RangeScan, T_body_scan: Transform2D) -> None:
        """Queue the scan stamped ``t_ns`` (ns), taken by the LiDAR mounted at ``T_body_scan``."""
        self._waiting.append((t_ns, scan, T_body_scan))
        if self._newest_scan_ns is not None and t_ns > self._newest_scan_ns:
            # running mean of the scans' intervals
            interval_ns = t_ns - self._newest_scan_ns
            mean = interval_ns if self._interval_ns is None else self._interval_ns
            self._interval_ns = mean + INTERVAL_GAIN * (interval_ns - mean)
        self._newest_scan_ns = t_ns if self._newest_scan_ns is None else max(self._newest_scan_ns, t_ns)
        if len(self._waiting) > MAX_WAITING_SCANS:
            dropped_ns, _, _ = self._waiting.popleft()
            self.skip(
                f"scan at {dropped_ns} ns skipped by the scan registration: the motion input did not reach "
                f"its stamp while {MAX_WAITING_SCANS} newer scans came (are joint_states / odom arriving?)"
            )

    def reached(self) -> list[tuple[int, tuple[float, ...], bool]]:
        """The filter's next motion samples (`turtlelib.MeasuredPoses`), oldest first, as ``(t_ns, sample,
        restart)``: the waiting scans the motion input reaches, registered; and, while the LiDAR is quiet
        (module docstring), the input's pose ``LAG_NS`` before its newest (before any scan, the newest), so
        that without scans slam goes on with its motion input alone. ``restart`` is True for the first
        after a :meth:`restart` of the clock (stamped no later than the last). A scan not after the last
        sample (but after a restart), or older than the kept input poses, is skipped with a throttled
        warning."""
        samples = []
        latest = self._inputs.latest_time_ns
        while self._waiting and latest is not None and self._waiting[0][0] <= latest:
            t_ns, scan, T_body_scan = self._waiting.popleft()
            sample = self._sample(t_ns, scan, T_body_scan)
            if sample is not None:
                samples.append(sample)
        if latest is None or self._waiting:
            return samples
        if self._newest_scan_ns is None:
            t_coast = latest  # no LiDAR yet: the input drives the filter at once
        else:
            quiet_ns = max(QUIET_MIN_NS, QUIET_SCANS * (self._interval_ns or 0.0))
            t_coast = latest - LAG_NS if latest - self._newest_scan_ns > quiet_ns else None
        if t_coast is not None and (self._last_ns is None or t_coast > self._last_ns or self._restarting):
            sample = self._sample(t_coast, None, None)
            if sample is not None:
                samples.append(sample)
        return samples

    def _sample(
        self, t_ns: int, scan: RangeScan | None, T_body_scan: Transform2D | None
    ) -> tuple[int, tuple, bool] | None:
        """The LiDAR odometry's step at ``t_ns`` (registering ``scan`` from the mount ``T_body_scan``, or the
        input alone for None) as a motion sample, counted; None (skipped with a warning) when it cannot be
        one."""
        T_input_body = self._inputs.at(t_ns)
        went_back = self._last_ns is not None and t_ns <= self._last_ns
        if T_input_body is None or (went_back and not self._restarting):
            # the first scans, when the input alone drove the filter on past them, still start the map
            seeded = T_input_body is not None and scan is not None
            if seeded and self._odometry.seed_map(t_ns, T_input_body, scan, T_body_scan):
                self.counts["seeded"] += 1
                return None
            self.skip(f"scan at {t_ns} ns skipped by the scan registration: older than the last one")
            return None
        try:
            step = self._odometry.step(t_ns, T_input_body, scan, T_body_scan)
        except (ValueError, np.linalg.LinAlgError) as error:
            self.skip(f"scan at {t_ns} ns skipped by the scan registration: {error}")
            return None
        self._last_ns, self.last, self._restarting = t_ns, step, False
        if self.step_listener is not None:
            p_body = np.zeros((0, 2)) if scan is None else scan_points(scan, T_body_scan)
            self.step_listener(step, p_body)
        self.counts[step.basis.value if scan is not None else "input_only"] += 1
        if step.basis is Basis.DEGENERATE:
            self._warnings.warn(
                "registration",
                f"scan registration degenerate: the scan constrains one direction to only "
                f"{step.registration.weakest_std_m:.2f} m (a long corridor?); the motion input holds it",
            )
        return t_ns, step.sample, went_back

    def moved_on(
        self, t_from_ns: int, T_map_body: Transform2D, P_pose: NDArray[np.float64], t_ns: int
    ) -> tuple[Transform2D, NDArray[np.float64]]:
        """The pose ``T_map_body`` (covariance ``P_pose``) at ``t_from_ns`` moved on to ``t_ns`` by the
        motion input's own motion ``U = T_input(t_from)^-1 T_input(t)`` and its noise::

            T = T_map_body U,   P = G P G^T + Q(T_map_body, log U, t - t_from)

        (unchanged where the input's poses do not cover both times)."""
        T_from, T_to = self._inputs.at(t_from_ns), self._inputs.at(t_ns)
        if T_from is None or T_to is None or t_ns <= t_from_ns:
            return T_map_body, P_pose
        U = T_from.inverse() @ T_to
        T = T_map_body @ U
        G = right_composition_jacobian(T_map_body, T)
        Q = self.noise.covariance(T_map_body, U.log(), (t_ns - t_from_ns) / NS_PER_S)
        return T, G @ P_pose @ G.T + Q

    def status(self, fused_since: int) -> DiagnosticStatus:
        """`slam: scan registration` (module docstring); ``fused_since``: landmark observations fused since
        the last report."""
        since = {key: self.counts[key] - self._reported[key] for key in self.counts}
        self._reported = dict(self.counts)
        registered = since[Basis.REGISTERED.value] + since[Basis.DEGENERATE.value]
        motion_only = since[Basis.MOTION.value] + since["input_only"]
        sources = [
            name for name, used in (("scan registration", registered), ("landmarks", fused_since)) if used
        ]
        if not sources and motion_only:
            level, message = (
                ERROR,
                "the pose rests on the motion input alone: no scan registered, no landmark",
            )
        elif since[Basis.DEGENERATE.value]:
            level, degenerate = WARN, since[Basis.DEGENERATE.value]
            message = (
                f"the pose rests on {' and '.join(sources)}; {degenerate} scans degenerate "
                "(a direction the scans do not constrain, held by the motion input)"
            )
        else:
            level = OK
            message = (
                f"the pose rests on {' and '.join(sources)}" if sources else "no scan since the last report"
            )
        values: dict[str, object] = {f"scans_{key}": value for key, value in self.counts.items()}
        if self.last is not None and self.last.registration is not None:
            registration = self.last.registration
            weakest = registration.weakest_std_m
            values |= {
                "last_points_matched": registration.matched,
                "last_weakest_std_m": weakest if math.isfinite(weakest) else "inf",
                "last_prior_nis": registration.prior_nis,
            }
        return status("slam: scan registration", "slam", level, message, values)

    def skip(self, text: str) -> None:
        """A scan not registered (``text`` why): counted in /diagnostics and warned (throttled)."""
        self.counts["skipped"] += 1
        self._warnings.warn("scan registration", text)
