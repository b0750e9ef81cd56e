"""`odometry`: wheel odometry of a TurtleBot3 from `joint_states`.

Subscribes
    `joint_states` (sensor_msgs/JointState): wheel angles (rad) of joints `wheel_left`, `wheel_right`.
    `initialpose` (geometry_msgs/PoseWithCovarianceStamped, RViz's "2D Pose Estimate"): resets the pose;
        accepted in frame `odom_id` (or an empty frame id).
Publishes
    `odom` (nav_msgs/Odometry): pose of `body_id` in `odom_id` and its body twist (rad/s, m/s), stamped
        with the joint_states stamp; the pose covariance is left zero (not estimated).
    `~/path` (nav_msgs/Path, frame `odom_id`): the trail, decimated by `PathTrailConfig`.
    `/tf` `odom_id` -> `body_id` where tf2_msgs is installed.
Parameters
    `model`, then `RobotParams` (that model's constants by default), `WheelJoints` (wheel_left, wheel_right),
    `OdometryFrames` (body_id, odom_id), `PathTrailConfig` (path_min_step_m, path_min_turn_rad,
    path_max_poses), `turtlelib.SampleGateConfig` (speed_margin, max_sample_gap, max_bridged_gap,
    restart_samples).

Model (see `wheel_odometry.WheelOdometry`): wheel-angle increments ``dphi = phi_k - phi_{k-1}`` move
the pose along the exact arc ``T_odom_body_k = T_odom_body_{k-1} @ exp([F dphi])``, and the body twist is
``F dphi / dt``. The first message sets the reference (odom then holds the initial pose, zero twist).
Invalid messages (missing or repeated wheel joints, names and positions of different lengths,
non-finite angles, an invalid stamp) are logged (throttled) and skipped. Implausible ones are refused
(`nuturtle_ros_common.wheel_stream`): a stamp not after the last (an exact copy is ignored), more than
`max_sample_gap` after it, or wheels that would have turned faster than the motors can. Once
`restart_samples` refused messages in a row continue each other, either the wheels went on after a silence
(at most `max_bridged_gap`, a turn the motors could make over it, not back at zero): the silence is
integrated as one arc of the measured net turn (bridged); or the source restarted (a restarted simulator, a
looped bag, encoders reset to zero): the first of them becomes the new reference without moving the pose,
and the motion along the others is integrated. An `initialpose` whose quaternion is not a rotation is
refused.
"""

from __future__ import annotations

import sys
from dataclasses import dataclass

from builtin_interfaces.msg import Time
from geometry_msgs.msg import PoseWithCovarianceStamped
from nav_msgs.msg import Odometry
from rclpy.node import Node
from sensor_msgs.msg import JointState

from nuturtle_description.robot_declaration import declare_robot
from nuturtle_ros_common.conversions import (
    odometry_message,
    stamp_from_nanoseconds,
    transform_from_pose,
    transform_stamped,
)
from nuturtle_ros_common.node_main import run_node
from nuturtle_ros_common.path_topic import PathTopic
from nuturtle_ros_common.ros_params import declare_dataclass
from nuturtle_ros_common.tf_compat import OptionalTfBroadcaster
from nuturtle_ros_common.throttle import SourceWarnings
from nuturtle_ros_common.wheel_joints import WheelJoints
from nuturtle_ros_common.wheel_stream import declare_wheel_stream
from turtlelib import Transform2D, Twist2D
from turtlelib.motion.sample_gate import Verdict
from turtlelib.motion.wheel_odometry import WheelOdometry
from turtlelib.util.validation import names


@dataclass(frozen=True)
class OdometryFrames:
    """Frame ids of the odometry, ``odom_id`` (the parent) and ``body_id`` (the child): non-empty and
    distinct (ValueError otherwise)."""

    body_id: str = "base_footprint"
    odom_id: str = "odom"

    def __post_init__(self) -> None:
        names("frame id", body_id=self.body_id, odom_id=self.odom_id)


class OdometryNode(Node):
    """The `odometry` node (see the module docstring); kwargs go to rclpy's Node."""

    def __init__(self, **kwargs) -> None:
        super().__init__("odometry", **kwargs)
        robot = declare_robot(self)
        self.joints = declare_dataclass(self, WheelJoints)
        self.frames = declare_dataclass(self, OdometryFrames)
        self._warnings = SourceWarnings(self.get_logger())
        self._wheels = declare_wheel_stream(self, self.joints, robot, self._warnings)
        self.odometry = WheelOdometry(robot.diff_drive())
        self.path = PathTopic(self)
        self._odom_publisher = self.create_publisher(Odometry, "odom", 10)
        self._tf = OptionalTfBroadcaster(self)
        self.create_subscription(JointState, "joint_states", self._on_joint_states, 10)
        self.create_subscription(PoseWithCovarianceStamped, "initialpose", self._on_initial_pose, 10)

    def _on_joint_states(self, msg: JointState) -> None:
        result = self._wheels.offer(msg)
        if result is None:
            return
        samples = list(result.samples)
        if result.verdict is Verdict.RESTARTED or self.odometry.reference_time_s is None:
            t_ns, (phi_left_rad, phi_right_rad) = samples.pop(0)
            self.odometry.set_reference(t_ns * 1e-9, phi_left_rad, phi_right_rad)
            if not samples:
                self._publish(self.odometry.T_odom_body, Twist2D(), stamp_from_nanoseconds(t_ns))
        for t_ns, (phi_left_rad, phi_right_rad) in samples:
            try:
                V_body = self.odometry.step(t_ns * 1e-9, phi_left_rad, phi_right_rad)
            except ValueError as error:  # finite angles whose increment the kinematics cannot take
                self._warnings.warn(
                    "joint_states", f"joint_states skipped: {error}; taking it as the new reference"
                )
                self.odometry.set_reference(t_ns * 1e-9, phi_left_rad, phi_right_rad)
                continue
            self._publish(self.odometry.T_odom_body, V_body, stamp_from_nanoseconds(t_ns))

    def _publish(self, T_odom_body: Transform2D, V_body: Twist2D, stamp: Time) -> None:
        frames = self.frames
        odom = odometry_message(T_odom_body, V_body, frames.odom_id, frames.body_id, stamp)
        self._odom_publisher.publish(odom)
        self._tf.send(transform_stamped(T_odom_body, self.frames.odom_id, self.frames.body_id, stamp))
        self.path.add(T_odom_body, odom)

    def _on_initial_pose(self, msg: PoseWithCovarianceStamped) -> None:
        frame_id = msg.header.frame_id
        if frame_id not in ("", self.frames.odom_id):
            self._warnings.warn(
                "initialpose",
                f"initialpose skipped: it is in frame {frame_id!r}, odometry resets only from a pose in "
                f"{self.frames.odom_id!r} (set RViz's fixed frame to {self.frames.odom_id!r})",
            )
            return
        try:
            T_odom_body = transform_from_pose(msg.pose.pose)
        except ValueError as error:
            self._warnings.warn("initialpose", f"initialpose skipped: {error}")
            return
        self.odometry.T_odom_body = T_odom_body
        self.path.clear()
        self.get_logger().info(
            f"pose reset to x = {T_odom_body.x:.3f} m, y = {T_odom_body.y:.3f} m, "
            f"theta = {T_odom_body.theta:.3f} rad"
        )


def main(args: list[str] | None = None) -> None:
    sys.exit(run_node(lambda: OdometryNode(), "odometry", __doc__, args))


if __name__ == "__main__":
    main()
