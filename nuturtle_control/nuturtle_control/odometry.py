"""`odometry`: wheel odometry of the Burger from `joint_states`.

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
    `RobotParams` (the Burger's constants by default), `WheelJoints` (wheel_left, wheel_right),
    `OdometryFrames` (body_id, odom_id), `PathTrailConfig` (path_min_step_m, path_min_turn_rad,
    path_max_poses).

Model (see `wheel_odometry.WheelOdometry`): wheel-angle increments ``dphi = phi_k - phi_{k-1}`` move
the pose along the exact arc ``T_odom_body_k = T_odom_body_{k-1} @ exp([F dphi])``, and the body twist is
``F dphi / dt``. The first message sets the reference (odom then holds the initial pose, zero twist).
Invalid messages (missing or repeated wheel joints, names and positions of different lengths,
non-finite angles) are logged (throttled) and skipped. A stamp earlier than the last one is logged and
the message becomes the new reference without moving the pose (a restarted simulator or a looped bag),
so the node recovers instead of waiting for time to catch up.
"""

from __future__ import annotations

import sys
from dataclasses import dataclass

from builtin_interfaces.msg import Time
from geometry_msgs.msg import PoseStamped, PoseWithCovarianceStamped
from nav_msgs.msg import Odometry, Path
from rclpy.node import Node
from sensor_msgs.msg import JointState

from nuturtle_description.robot_params import RobotParams, burger_params
from nuturtle_ros_common.conversions import (
    odometry_message,
    stamp_seconds,
    transform_from_pose,
    transform_stamped,
)
from nuturtle_ros_common.node_main import run_node
from nuturtle_ros_common.ros_params import declare_dataclass
from nuturtle_ros_common.tf_compat import OptionalTfBroadcaster
from nuturtle_ros_common.throttle import WARN_THROTTLE_S
from nuturtle_ros_common.wheel_joints import WheelJoints, wheel_values
from turtlelib import Transform2D, Twist2D
from turtlelib.path_trail import PathTrail, PathTrailConfig
from turtlelib.validation import names
from turtlelib.wheel_odometry import WheelOdometry


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
        robot = declare_dataclass(self, RobotParams, overrides=vars(burger_params()))
        self.joints = declare_dataclass(self, WheelJoints)
        self.frames = declare_dataclass(self, OdometryFrames)
        self.odometry = WheelOdometry(robot.diff_drive())
        self.trail: PathTrail[PoseStamped] = PathTrail(declare_dataclass(self, PathTrailConfig))
        self._odom_publisher = self.create_publisher(Odometry, "odom", 10)
        self._path_publisher = self.create_publisher(Path, "~/path", 10)
        self._tf = OptionalTfBroadcaster(self)
        self.create_subscription(JointState, "joint_states", self._on_joint_states, 10)
        self.create_subscription(PoseWithCovarianceStamped, "initialpose", self._on_initial_pose, 10)

    def _on_joint_states(self, msg: JointState) -> None:
        try:
            phi_left_rad, phi_right_rad = wheel_values(self.joints, msg.name, msg.position)
        except ValueError as error:
            self.get_logger().warning(f"joint_states skipped: {error}", throttle_duration_sec=WARN_THROTTLE_S)
            return
        t_s = stamp_seconds(msg.header.stamp)
        reference_time_s = self.odometry.reference_time_s
        if reference_time_s is not None and t_s < reference_time_s:
            self.get_logger().warning(
                f"joint_states skipped: time went backwards ({t_s:.9f} s < {reference_time_s:.9f} s); "
                "taking it as the new reference",
                throttle_duration_sec=WARN_THROTTLE_S,
            )
            self.odometry.set_reference(t_s, phi_left_rad, phi_right_rad)
            return
        if reference_time_s is None:
            self.odometry.set_reference(t_s, phi_left_rad, phi_right_rad)
        try:
            V_body = self.odometry.step(t_s, phi_left_rad, phi_right_rad)
        except ValueError as error:  # finite angles whose increment overflows
            self.get_logger().warning(
                f"joint_states skipped: {error}; taking it as the new reference",
                throttle_duration_sec=WARN_THROTTLE_S,
            )
            self.odometry.set_reference(t_s, phi_left_rad, phi_right_rad)
            return
        self._publish(self.odometry.T_odom_body, V_body, msg.header.stamp)

    def _publish(self, T_odom_body: Transform2D, V_body: Twist2D, stamp: Time) -> None:
        frames = self.frames
        odom = odometry_message(T_odom_body, V_body, frames.odom_id, frames.body_id, stamp)
        self._odom_publisher.publish(odom)
        self._tf.send(transform_stamped(T_odom_body, self.frames.odom_id, self.frames.body_id, stamp))
        if self.trail.offer(T_odom_body, PoseStamped(header=odom.header, pose=odom.pose.pose)):
            self._path_publisher.publish(Path(header=odom.header, poses=list(self.trail.items)))

    def _on_initial_pose(self, msg: PoseWithCovarianceStamped) -> None:
        frame_id = msg.header.frame_id
        if frame_id not in ("", self.frames.odom_id):
            self.get_logger().warning(
                f"initialpose skipped: it is in frame {frame_id!r}, odometry resets only from a pose in "
                f"{self.frames.odom_id!r} (set RViz's fixed frame to {self.frames.odom_id!r})",
                throttle_duration_sec=WARN_THROTTLE_S,
            )
            return
        try:
            T_odom_body = transform_from_pose(msg.pose.pose)
        except ValueError as error:
            self.get_logger().warning(f"initialpose skipped: {error}", throttle_duration_sec=WARN_THROTTLE_S)
            return
        self.odometry.T_odom_body = T_odom_body
        self.trail.clear()
        self.get_logger().info(
            f"pose reset to x = {T_odom_body.x:.3f} m, y = {T_odom_body.y:.3f} m, "
            f"theta = {T_odom_body.theta:.3f} rad"
        )


def main(args: list[str] | None = None) -> None:
    sys.exit(run_node(lambda: OdometryNode(), "odometry", args))


if __name__ == "__main__":
    main()
