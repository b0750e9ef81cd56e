"""`circle`: drive the robot around a circle by publishing a constant body twist.

Publishes
    `cmd_vel` (geometry_msgs/Twist) at `frequency` Hz: ``vx = s v``, ``omega = s v / R`` for linear speed
        `velocity` v (m/s), `radius` R (m) and direction s = +1 (counter-clockwise when v > 0) or -1.
Services (std_srvs/Empty)
    `~/reverse`: flip the direction of travel (s -> -s): the same circle, driven the other way.
    `~/stop`: publish one zero Twist, then publish nothing until `~/reverse` is called or one of this
        node's parameters (frequency, radius, velocity) is set; either resumes driving (reverse in the
        flipped direction; setting a parameter, even to its current value, in the current one).
        Nothing is published while stopped, so another command source (teleop) can take over.
        The node publishes one zero Twist when it stops (SIGINT, SIGTERM, SIGHUP).
Parameters (`CircleConfig`, changeable at run time; invalid values are rejected with the reason)
    `frequency` (Hz, finite > 0), `radius` (m, finite > 0), `velocity` (m/s, finite; negative drives
    backwards).
"""

from __future__ import annotations

import math
import sys
from dataclasses import dataclass

from geometry_msgs.msg import Twist
from rcl_interfaces.msg import SetParametersResult
from rclpy.node import Node
from rclpy.parameter import Parameter
from std_srvs.srv import Empty

from nuturtle_ros_common.node_main import run_node
from nuturtle_ros_common.ros_params import declare_dataclass, replace_from_parameters
from turtlelib import Twist2D
from turtlelib.util.validation import finite_real, positive, store


@dataclass(frozen=True)
class CircleConfig:
    """Circle driving: `frequency` (Hz) and `radius` (m) finite and > 0, `velocity` (m/s) finite."""

    frequency: float = 20.0
    radius: float = 0.5
    velocity: float = 0.1

    def __post_init__(self) -> None:
        store(self, ("frequency", "radius"), positive)
        store(self, ("velocity",), finite_real)
        if not math.isfinite(self.velocity / self.radius):
            raise ValueError(f"velocity / radius overflows: {self.velocity!r} / {self.radius!r}")

    def body_twist(self, direction: float) -> Twist2D:
        """``V_b = s [v / R, v, 0]`` for direction ``s`` = +1 or -1."""
        return Twist2D(direction * self.velocity / self.radius, direction * self.velocity, 0.0)


def twist_message(V_body: Twist2D) -> Twist:
    msg = Twist()
    msg.linear.x = V_body.vx
    msg.linear.y = V_body.vy
    msg.angular.z = V_body.omega
    return msg


class CircleNode(Node):
    """The `circle` node (see the module docstring); kwargs go to rclpy's Node."""

    def __init__(self, **kwargs) -> None:
        super().__init__("circle", **kwargs)
        self.config = declare_dataclass(self, CircleConfig, read_only=False)
        self.direction = 1.0
        self.stopped = False
        self._cmd_vel_publisher = self.create_publisher(Twist, "cmd_vel", 10)
        self._timer = self.create_timer(1.0 / self.config.frequency, self._on_timer)
        self.add_on_set_parameters_callback(self._check_parameters)
        self.add_post_set_parameters_callback(self._apply_parameters)
        self.create_service(Empty, "~/reverse", self._on_reverse)
        self.create_service(Empty, "~/stop", self._on_stop)

    def _on_timer(self) -> None:
        if not self.stopped:
            self._cmd_vel_publisher.publish(twist_message(self.config.body_twist(self.direction)))

    def _check_parameters(self, parameters: list[Parameter]) -> SetParametersResult:
        try:
            replace_from_parameters(self.config, parameters)
        except ValueError as error:
            return SetParametersResult(successful=False, reason=str(error))
        return SetParametersResult(successful=True)

    def _apply_parameters(self, parameters: list[Parameter]) -> None:
        if not any(parameter.name in vars(self.config) for parameter in parameters):
            return
        config = replace_from_parameters(self.config, parameters)
        if config.frequency != self.config.frequency:
            self._timer.timer_period_ns = round(1e9 / config.frequency)
        self.config = config
        self.stopped = False
        self.get_logger().info(f"driving {config}")

    def _on_reverse(self, request: Empty.Request, response: Empty.Response) -> Empty.Response:
        self.direction = -self.direction
        self.stopped = False
        return response

    def _on_stop(self, request: Empty.Request, response: Empty.Response) -> Empty.Response:
        self.stop()
        return response

    def stop(self) -> None:
        """Publish one zero Twist and stop driving (`~/stop`, and the node's own stop: `run_node`)."""
        self.stopped = True
        self._cmd_vel_publisher.publish(Twist())


def main(args: list[str] | None = None) -> None:
    sys.exit(run_node(lambda: CircleNode(), "circle", __doc__, args))


if __name__ == "__main__":
    main()
