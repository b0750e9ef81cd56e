"""joint_states -> plausible wheel-angle samples, for every node that integrates the wheels.

A JointState is read (`wheel_joints.wheel_values`: names, lengths, finite angles), its stamp checked
(`conversions.stamp_nanoseconds`), then offered to a `turtlelib.SampleGate` whose rate bound is the
robot's: each wheel turns at most ``(1 + speed_margin) wheel_speed_bound`` (rad/s; the robot description's
``RobotParams.wheel_speed_bound``, which its ``model`` sets), with a slack of ``ENCODER_SLACK_TICKS``
encoder ticks. So a replayed, future-stamped or corrupt message is refused without moving anything (the
warning names the parameters that set the bound). After ``restart_samples`` messages a silence the wheels
could have turned across is bridged (their net turn over it is measured), and a source that really
restarted (a restarted simulator, a looped recording, encoders reset to zero) is followed
(`turtlelib.motion.sample_gate`).
"""

from __future__ import annotations

from typing import Protocol

from rclpy.node import Node
from sensor_msgs.msg import JointState

from turtlelib.motion.sample_gate import GateResult, SampleGate, SampleGateConfig, Verdict

from .conversions import stamp_nanoseconds
from .ros_params import declare_dataclass
from .throttle import SourceWarnings
from .wheel_joints import WheelJoints, wheel_values

# Slack of the rate bound (encoder ticks): a reading may be off by a tick at either sample
ENCODER_SLACK_TICKS = 2.0


def speed_hint(max_rates: str) -> str:
    """How a sample gate's reason ends when a sample moved too fast: its ``max_rates`` come from the robot's
    fastest wheel speed, and the parameters that change them."""
    return (
        f"max rate {max_rates}, from the robot's fastest wheel speed: a faster robot needs its own `model` "
        "(or max_linear_speed, max_angular_speed, motor_cmd_max), or a larger speed_margin"
    )


class WheelStream:
    """The wheel samples of a node's `joint_states` (module docstring): ``wheel_speed_bound`` (rad/s) and
    ``encoder_ticks_per_rad`` set the rate bound; problems are warned (throttled) on ``warnings`` under
    ``source``."""

    def __init__(
        self,
        joints: WheelJoints,
        wheel_speed_bound: float,
        encoder_ticks_per_rad: float,
        config: SampleGateConfig,
        warnings: SourceWarnings,
        source: str = "joint_states",
    ) -> None:
        self.joints = joints
        slack_rad = ENCODER_SLACK_TICKS / encoder_ticks_per_rad
        hint = speed_hint(f"{wheel_speed_bound:.4g} rad/s")
        self.gate = SampleGate(config, [wheel_speed_bound] * 2, [slack_rad] * 2, hint)
        self._warnings = warnings
        self._source = source

    def offer(self, msg: JointState) -> GateResult | None:
        """The samples to apply for ``msg`` (``ACCEPTED``, ``BRIDGED``: motion on from the last one;
        ``RESTARTED``: start again at the first), or None when there is nothing to apply (invalid, refused:
        warned; an exact duplicate: quietly)."""
        try:
            angles = wheel_values(self.joints, msg.name, msg.position)
            result = self.gate.offer(stamp_nanoseconds(msg.header.stamp), angles)
        except ValueError as error:
            self._warnings.warn(self._source, f"{self._source} skipped: {error}")
            return None
        return to_apply(result, self._warnings, self._source)


def to_apply(result: GateResult, warnings: SourceWarnings, source: str) -> GateResult | None:
    """``result`` when it has samples to apply (accepted; bridged, restarted: warned), None otherwise
    (refused: warned; an exact duplicate: quietly). Warnings go to ``warnings`` under ``source``."""
    if result.verdict is Verdict.REFUSED:
        warnings.warn(source, f"{source} refused: {result.reason}")
        return None
    # each its own logger: the refusals before it must not throttle it away
    if result.verdict is Verdict.BRIDGED:
        warnings.warn(f"{source}_bridge", f"{source}: {result.reason}")
    if result.verdict is Verdict.RESTARTED:
        warnings.warn(f"{source}_restart", f"{source}: {result.reason} at the first of them")
    return None if result.verdict is Verdict.DUPLICATE else result


class WheelLimits(Protocol):
    """What the rate bound needs of a robot description (``RobotParams`` has it)."""

    @property
    def wheel_speed_bound(self) -> float: ...

    @property
    def encoder_ticks_per_rad(self) -> float: ...


def declare_wheel_stream(
    node: Node, joints: WheelJoints, robot: WheelLimits, warnings: SourceWarnings
) -> WheelStream:
    """The `WheelStream` of ``node``'s joint_states: ``SampleGateConfig`` declared as its ROS parameters,
    the rate bound from ``robot``."""
    config = declare_dataclass(node, SampleGateConfig)
    return WheelStream(joints, robot.wheel_speed_bound, robot.encoder_ticks_per_rad, config, warnings)
