"""`driver`: drive the robot along a figure eight through the arena, tracking it with the SLAM pose.

Route
-----
Two circles of radius ``radius`` R (m) that touch at the start pose: the first, counter-clockwise, has
its centre R to the robot's left, the second, clockwise, R to its right. At linear speed ``velocity`` v
(m/s) and turn rate ``omega = v / R`` each loop takes ``T = 2 pi / omega`` s, and loop ``k``
(``k = floor(tau / T)`` for the time ``tau`` since the route began) has the reference twist and pose::

    V_ref = [(-1)^k omega, v, 0],     T_start_ref(tau) = exp([V_ref] (tau - k T))

so the reference is back at the start pose after each loop and turns the other way. The motors hold
wheel speeds on a grid of ``1 / motor_cmd_per_rad_sec`` rad/s, so the reference uses the nearest wheel
speeds on that grid (:class:`FigureEight`): driven open loop, its loops close up to wheel slip.
The robot first stands still for ``start_delay`` s (the estimators see the start from a known pose).
A robot may join the route ``route_start_s`` s in: it starts at ``T_start_ref(route_start_s)`` and
follows ``T_start_ref(tau)``, ``tau = route_start_s + (t - t_0 - start_delay)``. That continues a run
that drove the route for ``route_start_s`` s and stopped, from the pose it stopped at (docs/maps.md,
"Continuing over sessions"), and spaces the demo's robots along one figure eight.

Tracking (Kanayama et al. 1990)
-------------------------------
With the pose estimate ``T_map_body`` (from `slam/odom`) and the reference ``T_map_ref = T_map_route @
T_start_ref(tau)``, the error in the body frame ``[e_x, e_y, e_theta] = T_map_body^-1 T_map_ref``
gives::

    v = v_ref cos(e_theta) + k_x e_x
    w = w_ref + v_ref (k_y e_y + k_theta sin(e_theta))

(asymptotically stable for k_x, k_y, k_theta > 0 and v_ref > 0). ``T_map_route`` is the route's start
(its crossing): the first pose received ``T_map_first`` composed back along the route already driven,
``T_map_route = T_map_first @ T_start_ref(route_start_s)^-1`` (the first pose itself when the route
begins at its start); until a pose arrives, or with ``feedback`` false, the reference twist is sent as it
is (open loop).
Feeding back the SLAM pose keeps the true robot on the figure eight while wheel odometry drifts: in the
default world (cylinders 0.75 m to 1.85 m from the centre, start at the origin facing +x) a radius of
0.75 m keeps the robot's disc about 0.45 m clear of every cylinder and brings every cylinder within
0.8 m of the route.

Subscribes
    `slam/odom` (nav_msgs/Odometry) when ``feedback`` is true.
Publishes
    `cmd_vel` (geometry_msgs/Twist) at ``rate`` Hz (timer on the node's clock: run it with
    ``use_sim_time`` so the route follows simulation time); one zero twist when the node stops (SIGINT,
    SIGTERM, SIGHUP) or ``stop()`` is called.
Parameters
    `RouteConfig`, `model` and `RobotParams` (that model's constants by default).
"""

from __future__ import annotations

import math
import sys
from dataclasses import dataclass
from typing import Any

import numpy as np
from geometry_msgs.msg import Twist
from nav_msgs.msg import Odometry
from rclpy.node import Node

from nuturtle_control.circle import twist_message
from nuturtle_description.robot_declaration import declare_robot
from nuturtle_description.robot_params import RobotParams
from nuturtle_ros_common.conversions import transform_from_pose
from nuturtle_ros_common.node_main import run_node
from nuturtle_ros_common.ros_params import declare_dataclass
from turtlelib import Transform2D, Twist2D
from turtlelib.util.validation import non_negative, positive, store


@dataclass(frozen=True)
class RouteConfig:
    """The figure eight: loop ``radius`` (m), linear ``velocity`` (m/s), command ``rate`` (Hz), all
    finite and > 0; ``start_delay`` (s, >= 0) standing still first; tracking gains ``k_x`` (1/s),
    ``k_y`` (1/m^2), ``k_theta`` (1/m), finite and >= 0; ``feedback``: track the `slam/odom` pose;
    ``route_start_s`` (s, finite, >= 0) how far into the route the driver begins (module docstring)."""

    radius: float = 0.75
    velocity: float = 0.14
    rate: float = 10.0
    start_delay: float = 3.0
    k_x: float = 1.0
    k_y: float = 25.0
    k_theta: float = 10.0
    feedback: bool = True
    route_start_s: float = 0.0

    def __post_init__(self) -> None:
        store(self, ("radius", "velocity", "rate"), positive)
        store(self, ("start_delay", "k_x", "k_y", "k_theta", "route_start_s"), non_negative)


@dataclass(frozen=True)
class FigureEight:
    """The loop twist ``V_b = [v / R, v, 0]`` as the motors can hold it, and its loop period.

    ``wheel_speeds_rad_s`` (left, right) on the counter-clockwise loop (swapped on the clockwise one).
    The motors hold wheel speeds in steps of ``1 / motor_cmd_per_rad_sec`` rad/s, so the requested
    wheel speeds ``phi_dot = H(0) V_b`` are rounded to that grid and the twist and the period
    ``T = 2 pi / omega`` are those of the rounded speeds: then each loop closes (up to slip).
    """

    left_loop: Twist2D
    loop_period_s: float
    wheel_speeds_rad_s: tuple[float, float]

    @classmethod
    def for_robot(cls, route: RouteConfig, robot: RobotParams) -> FigureEight:
        drive = robot.diff_drive()
        step_rad_s = 1.0 / robot.motor_cmd_per_rad_sec
        # phi_dot = H(0) V_b, rounded to the motor's speed resolution
        wheel_rad_s = np.array(
            drive.wheel_speeds(Twist2D(route.velocity / route.radius, route.velocity, 0.0))
        )
        left_rad_s, right_rad_s = np.round(wheel_rad_s / step_rad_s) * step_rad_s
        if max(abs(left_rad_s), abs(right_rad_s)) > robot.max_wheel_speed:
            raise ValueError(
                f"velocity {route.velocity} m/s on radius {route.radius} m needs wheel speeds above "
                f"{robot.max_wheel_speed:.3f} rad/s"
            )
        if right_rad_s <= left_rad_s:
            raise ValueError(f"radius {route.radius} m is too large to turn at the motors' resolution")
        twist = drive.body_twist(left_rad_s, right_rad_s)
        return cls(twist, 2.0 * math.pi / twist.omega, (float(left_rad_s), float(right_rad_s)))

    def body_twist(self, tau_s: float) -> Twist2D:
        """``V_ref(tau) = [(-1)^k omega, v, 0]``, ``k = floor(tau / T)``, ``tau >= 0`` s into the route."""
        k = math.floor(max(tau_s, 0.0) / self.loop_period_s)
        sign = 1.0 if k % 2 == 0 else -1.0
        return Twist2D(sign * self.left_loop.omega, self.left_loop.vx, 0.0)

    def reference(self, tau_s: float) -> Transform2D:
        """``T_start_ref(tau) = exp([V_ref] (tau - k T))``: every loop starts again at the start pose."""
        tau_s = max(tau_s, 0.0)
        into_loop_s = tau_s - math.floor(tau_s / self.loop_period_s) * self.loop_period_s
        return Transform2D.exp(self.body_twist(tau_s) * into_loop_s)


def track(T_map_body: Transform2D, T_map_ref: Transform2D, V_ref: Twist2D, config: RouteConfig) -> Twist2D:
    """Kanayama's tracking law (module docstring): the body twist that steers onto the reference."""
    # [e_x, e_y, e_theta] = T_map_body^-1 T_map_ref
    error = T_map_body.inverse() @ T_map_ref
    # v = v_ref cos(e_theta) + k_x e_x
    v = V_ref.vx * math.cos(error.theta) + config.k_x * error.x
    # w = w_ref + v_ref (k_y e_y + k_theta sin(e_theta))
    omega = V_ref.omega + V_ref.vx * (config.k_y * error.y + config.k_theta * math.sin(error.theta))
    return Twist2D(omega, v, 0.0)


class FigureEightDriver(Node):
    """The `driver` node (module docstring); ``stop()`` publishes a zero twist and ends the route."""

    def __init__(self, **kwargs: Any) -> None:
        super().__init__("driver", **kwargs)
        self.config = declare_dataclass(self, RouteConfig)
        self.robot = declare_robot(self)
        self.route = FigureEight.for_robot(self.config, self.robot)
        self._publisher = self.create_publisher(Twist, "cmd_vel", 10)
        self._t_start_s: float | None = None
        # where the route's reference starts (module docstring)
        self.T_map_route: Transform2D | None = None
        self.T_map_body: Transform2D | None = None
        # s into the route of the last command (route_start_s while standing still)
        self.route_time_s = self.config.route_start_s
        self.stopped = False
        if self.config.feedback:
            self.create_subscription(Odometry, "slam/odom", self._on_pose, 10)
        self.create_timer(1.0 / self.config.rate, self._on_timer)

    def _on_pose(self, msg: Odometry) -> None:
        try:
            self.T_map_body = transform_from_pose(msg.pose.pose)
        except ValueError as error:
            self.get_logger().warning(f"slam/odom skipped: {error}", throttle_duration_sec=2.0)
            return
        if self.T_map_route is None:
            # T_map_route = T_map_first @ T_start_ref(route_start_s)^-1
            self.T_map_route = self.T_map_body @ self.route.reference(self.config.route_start_s).inverse()

    def _on_timer(self) -> None:
        if self.stopped:
            return
        t_s = self.get_clock().now().nanoseconds * 1e-9
        if self._t_start_s is None:
            self._t_start_s = t_s
        driven_s = t_s - self._t_start_s - self.config.start_delay
        if driven_s < 0.0:
            self._publisher.publish(Twist())
            return
        tau_s = self.config.route_start_s + driven_s
        self.route_time_s = tau_s
        V_ref = self.route.body_twist(tau_s)
        if self.T_map_route is not None and self.T_map_body is not None:
            T_map_ref = self.T_map_route @ self.route.reference(tau_s)
            V_ref = track(self.T_map_body, T_map_ref, V_ref, self.config)
        self._publisher.publish(twist_message(V_ref))

    def stop(self) -> None:
        self.stopped = True
        self._publisher.publish(Twist())


def main(args: list[str] | None = None) -> None:
    sys.exit(run_node(lambda: FigureEightDriver(), "driver", __doc__, args))


if __name__ == "__main__":
    main()
