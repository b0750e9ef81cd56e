"""nav_msgs/Odometry -> plausible odometry-pose samples, for a node that follows an odometry source.

An Odometry message is read (frames ``odom_id -> body_id``, `conversions.transform_from_pose`: a finite
position and a unit quaternion; `conversions.stamp_nanoseconds`) into the sample ``(x, y, theta)`` of
``T_odom_body`` (m, m, rad), then offered to a `turtlelib.SampleGate` whose rate bound is the robot's:
with wheel radius ``r``, track ``b`` and fastest wheel speed ``w`` (rad/s, the robot description's
``wheel_speed_bound``, which its ``model`` sets)::

    |dx|, |dy| <= (1 + speed_margin) r w dt + POSITION_SLACK_M
    |dtheta|   <= (1 + speed_margin) 2 r w / b dt + HEADING_SLACK_RAD

The heading is unwrapped against the last accepted sample (``theta_acc + wrap(theta - theta_acc)``), so
crossing +-pi is motion, not a jump (and the gate reads it modulo 2 pi to tell the source's origin). A
replayed or corrupt message, a time jump or a pose jump (an odometry source reset to the origin) is refused
without moving anything; after ``restart_samples`` messages a silence the robot could have driven across
is bridged (the odometry's net change over it is measured), and a source that really restarted is
followed (`turtlelib.motion.sample_gate`).
"""

from __future__ import annotations

import math
from typing import Protocol

from nav_msgs.msg import Odometry

from turtlelib import Transform2D, normalize_angle
from turtlelib.motion.sample_gate import GateResult, SampleGate, SampleGateConfig

from .conversions import stamp_nanoseconds, transform_from_pose
from .throttle import SourceWarnings
from .wheel_stream import speed_hint, to_apply

# Slack of the rate bound: a pose may be off by this much at either sample (m, rad)
POSITION_SLACK_M = 1e-3
HEADING_SLACK_RAD = 1e-3


class DriveLimits(Protocol):
    """What the rate bound needs of a robot description (``RobotParams`` has it)."""

    @property
    def wheel_speed_bound(self) -> float: ...

    @property
    def wheel_radius(self) -> float: ...

    @property
    def track_width(self) -> float: ...


class OdomStream:
    """The odometry-pose samples of a node's `odom` topic (module docstring), expected in frames
    ``odom_id -> body_id``; problems are warned (throttled) on ``warnings`` under ``source``."""

    def __init__(
        self,
        odom_id: str,
        body_id: str,
        robot: DriveLimits,
        config: SampleGateConfig,
        warnings: SourceWarnings,
        source: str = "odom",
    ) -> None:
        self.frames = (odom_id, body_id)
        max_speed_mps = robot.wheel_radius * robot.wheel_speed_bound
        max_turn_rate = 2.0 * max_speed_mps / robot.track_width
        self.gate = SampleGate(
            config,
            [max_speed_mps, max_speed_mps, max_turn_rate],
            [POSITION_SLACK_M, POSITION_SLACK_M, HEADING_SLACK_RAD],
            speed_hint(f"{max_speed_mps:.4g} m/s, {max_turn_rate:.4g} rad/s"),
            periods=(None, None, 2.0 * math.pi),
        )
        self._warnings = warnings
        self._source = source

    def offer(self, msg: Odometry) -> GateResult | None:
        """The samples ``(t_ns, (x, y, theta))`` to apply for ``msg`` (``ACCEPTED``, ``BRIDGED``: motion on
        from the last one; ``RESTARTED``: start again at the first), or None when there is nothing to apply
        (invalid, refused: warned; an exact duplicate: quietly)."""
        try:
            frames = (msg.header.frame_id, msg.child_frame_id)
            if frames != self.frames:
                raise ValueError(f"frames {frames[0]!r} -> {frames[1]!r}, expected {self.frames[0]!r} -> "
                                 f"{self.frames[1]!r}")  # fmt: skip
            T_odom_body = transform_from_pose(msg.pose.pose)
            result = self.gate.offer(stamp_nanoseconds(msg.header.stamp), self._unwrapped(T_odom_body))
        except ValueError as error:
            self._warnings.warn(self._source, f"{self._source} skipped: {error}")
            return None
        return to_apply(result, self._warnings, self._source)

    def _unwrapped(self, T_odom_body: Transform2D) -> tuple[float, float, float]:
        """``(x, y, theta)`` with theta within pi of the last accepted sample's."""
        accepted = self.gate.accepted
        theta = T_odom_body.theta
        if accepted is not None:
            theta_accepted = accepted[1][2]
            theta = theta_accepted + normalize_angle(theta - theta_accepted)
        return T_odom_body.x, T_odom_body.y, theta
