"""`turtle_control`: body velocity commands to wheel speed commands for a TurtleBot3.

Subscribes
    `cmd_vel` (geometry_msgs/Twist): body twist, linear.x (m/s) and angular.z (rad/s).
Publishes
    `wheel_cmd` (sensor_msgs/JointState): `velocity` = (left, right) wheel speeds in rad/s for joints
        `wheel_left`, `wheel_right`, stamped with the time of the command's arrival.
Parameters
    `model`, then `RobotParams` (that model's constants by default), `WheelJoints` (wheel_left, wheel_right),
    `CommandTimeoutConfig` (cmd_timeout).

Model: inverse kinematics ``phi_dot = H(0) V_b`` (``turtlelib.DiffDrive.wheel_speeds``), then
curvature-preserving saturation to ``max_wheel_speed = motor_cmd_max / motor_cmd_per_rad_sec``
(`wheel_limits.limit_wheel_speeds`: both wheels scaled by one factor, so the robot keeps the commanded
arc, only slower). A lateral velocity (linear.y) cannot be followed by a differential drive: it is
dropped with a warning and the rest of the command is executed. The out-of-plane components (linear.z,
angular.x, angular.y) are ignored. A command with a non-finite component is logged and skipped.
Warnings are throttled. A command holds for `cmd_timeout` s (node clock) without a newer one; then one
zero `wheel_cmd` stops the wheels. The node also publishes one zero `wheel_cmd` when it stops (SIGINT,
SIGTERM, SIGHUP: `nuturtle_ros_common.node_main`), so the wheels never keep the last command.
"""

from __future__ import annotations

import math
import sys

from geometry_msgs.msg import Twist
from rclpy.node import Node
from sensor_msgs.msg import JointState

from nuturtle_description.robot_declaration import declare_robot
from nuturtle_ros_common.command_timeout import CommandTimeoutConfig, CommandWatchdog
from nuturtle_ros_common.node_main import run_node
from nuturtle_ros_common.ros_params import declare_dataclass
from nuturtle_ros_common.throttle import WARN_THROTTLE_S
from nuturtle_ros_common.wheel_joints import WheelJoints
from turtlelib import Twist2D
from turtlelib.motion.wheel_limits import limit_wheel_speeds

# How often the command timeout is checked (s, node clock)
WATCHDOG_PERIOD_S = 0.05


class TurtleControlNode(Node):
    """The `turtle_control` node (see the module docstring); kwargs go to rclpy's Node."""

    def __init__(self, **kwargs) -> None:
        super().__init__("turtle_control", **kwargs)
        self.robot = declare_robot(self)
        self.joints = declare_dataclass(self, WheelJoints)
        self.watchdog = CommandWatchdog(declare_dataclass(self, CommandTimeoutConfig))
        self.drive = self.robot.diff_drive()
        self._wheel_cmd_publisher = self.create_publisher(JointState, "wheel_cmd", 10)
        self.create_subscription(Twist, "cmd_vel", self._on_cmd_vel, 10)
        self.create_timer(WATCHDOG_PERIOD_S, self._on_watchdog)

    def _on_watchdog(self) -> None:
        if self.watchdog.expired(self.get_clock().now().nanoseconds):
            self.stop()
            self.get_logger().info("no cmd_vel for cmd_timeout: wheels stopped")

    def stop(self) -> None:
        """Publish one zero `wheel_cmd` (the command timeout, and the node's own stop: `run_node`)."""
        stop = JointState(name=self.joints.names, velocity=[0.0, 0.0])
        stop.header.stamp = self.get_clock().now().to_msg()
        self._wheel_cmd_publisher.publish(stop)

    def _on_cmd_vel(self, msg: Twist) -> None:
        components = (msg.linear.x, msg.linear.y, msg.linear.z, msg.angular.x, msg.angular.y, msg.angular.z)
        if not all(math.isfinite(value) for value in components):
            self.get_logger().warning(
                f"cmd_vel skipped: non-finite component in linear {components[:3]}, angular {components[3:]}",
                throttle_duration_sec=WARN_THROTTLE_S,
            )
            return
        if msg.linear.y != 0.0:
            self.get_logger().warning(
                f"cmd_vel has a lateral velocity linear.y = {msg.linear.y} m/s that a differential "
                "drive cannot follow: it is dropped",
                throttle_duration_sec=WARN_THROTTLE_S,
            )
        V_body = Twist2D(msg.angular.z, msg.linear.x, 0.0)
        try:
            # phi_dot = H(0) V_b
            left_rad_s, right_rad_s = self.drive.wheel_speeds(V_body)
            left_rad_s, right_rad_s, scale = limit_wheel_speeds(
                left_rad_s, right_rad_s, self.robot.max_wheel_speed
            )
        except ValueError as error:  # finite but so large that the wheel speeds overflow
            self.get_logger().warning(f"cmd_vel skipped: {error}", throttle_duration_sec=WARN_THROTTLE_S)
            return
        if scale < 1.0:
            self.get_logger().warning(
                f"cmd_vel (vx = {V_body.vx} m/s, omega = {V_body.omega} rad/s) exceeds the wheel "
                f"speed limit {self.robot.max_wheel_speed:.3f} rad/s: scaled by {scale:.3f} along "
                "the same arc",
                throttle_duration_sec=WARN_THROTTLE_S,
            )
        now = self.get_clock().now()
        wheel_cmd = JointState(name=self.joints.names, velocity=[left_rad_s, right_rad_s])
        wheel_cmd.header.stamp = now.to_msg()
        self._wheel_cmd_publisher.publish(wheel_cmd)
        self.watchdog.command(now.nanoseconds)


def main(args: list[str] | None = None) -> None:
    sys.exit(run_node(lambda: TurtleControlNode(), "turtle_control", __doc__, args))


if __name__ == "__main__":
    main()
