"""turtle_control in process with real rclpy: cmd_vel in, wheel_cmd out.

Expected wheel speeds are computed by hand from the Burger's constants (r = 0.033 m, d = 0.16 m,
limit 265 / 41.6666667 = 6.36 rad/s): phi_dot_left = (vx - omega d / 2) / r,
phi_dot_right = (vx + omega d / 2) / r.
"""

from __future__ import annotations

import math

import pytest
from geometry_msgs.msg import Twist
from rclpy.parameter import Parameter
from sensor_msgs.msg import JointState

from nuturtle_control.turtle_control import TurtleControlNode
from rclpy_harness import matched, record_rosout, warnings_of

pytestmark = pytest.mark.ros

TOL = 1e-9


class Rig:
    """turtle_control plus a helper node publishing cmd_vel and recording wheel_cmd and /rosout."""

    def __init__(self, ros, **node_kwargs) -> None:
        self.ros = ros
        self.node = ros.add(TurtleControlNode(context=ros.context, **node_kwargs))
        helper = ros.node("turtle_control_test_helper")
        self.wheel_cmds: list[JointState] = []
        self.logs = record_rosout(helper)
        self.cmd_vel = helper.create_publisher(Twist, "cmd_vel", 10)
        wheel_cmd = helper.create_subscription(JointState, "wheel_cmd", self.wheel_cmds.append, 10)
        assert ros.spin_until(lambda: matched(self.cmd_vel, wheel_cmd), 10.0)

    def publish(self, vx=0.0, omega=0.0, vy=0.0) -> None:
        msg = Twist()
        msg.linear.x, msg.linear.y, msg.angular.z = vx, vy, omega
        self.cmd_vel.publish(msg)

    def send(self, vx=0.0, omega=0.0, vy=0.0) -> JointState:
        """Publish one Twist and return the wheel_cmd it causes."""
        count = len(self.wheel_cmds)
        self.publish(vx, omega, vy)
        assert self.ros.spin_until(lambda: len(self.wheel_cmds) > count, 5.0), "no wheel_cmd"
        return self.wheel_cmds[-1]

    def warnings(self) -> list[str]:
        self.ros.spin_for(0.1)
        return warnings_of(self.logs, "turtle_control")


def test_straight_turning_and_in_place_commands_give_the_hand_computed_wheel_speeds(ros):
    rig = Rig(ros)
    cases = [
        # (vx m/s, omega rad/s) -> (left, right) rad/s
        ((0.1, 0.0), (0.1 / 0.033, 0.1 / 0.033)),
        ((-0.2, 0.0), (-0.2 / 0.033, -0.2 / 0.033)),
        ((0.1, 0.5), ((0.1 - 0.04) / 0.033, (0.1 + 0.04) / 0.033)),
        ((0.1, -0.5), ((0.1 + 0.04) / 0.033, (0.1 - 0.04) / 0.033)),
        ((0.0, 1.0), (-0.08 / 0.033, 0.08 / 0.033)),
        ((0.0, 0.0), (0.0, 0.0)),
    ]
    for (vx, omega), (left, right) in cases:
        wheel_cmd = rig.send(vx, omega)
        assert wheel_cmd is not None
        assert list(wheel_cmd.name) == ["wheel_left_joint", "wheel_right_joint"]
        assert list(wheel_cmd.velocity) == pytest.approx([left, right], abs=TOL)
        assert len(wheel_cmd.position) == 0 and len(wheel_cmd.effort) == 0
    assert rig.warnings() == []


def test_wheel_cmd_is_stamped_with_the_time_of_the_command(ros):
    rig = Rig(ros)
    before_ns = rig.node.get_clock().now().nanoseconds
    wheel_cmd = rig.send(0.1, 0.0)
    after_ns = rig.node.get_clock().now().nanoseconds
    stamp_ns = wheel_cmd.header.stamp.sec * 10**9 + wheel_cmd.header.stamp.nanosec
    assert before_ns <= stamp_ns <= after_ns


def test_over_limit_command_is_scaled_along_the_same_arc_with_a_warning(ros):
    rig = Rig(ros)
    limit = 265 / 41.6666667
    # vx = 0.3 m/s, omega = 1 rad/s: (0.22, 0.38) / 0.033 = (6.67, 11.52) rad/s, both over 6.36
    wheel_cmd = rig.send(0.3, 1.0)
    left, right = wheel_cmd.velocity
    assert right == pytest.approx(limit, abs=1e-6)
    assert left == pytest.approx(limit * 0.22 / 0.38, abs=1e-6)
    # same curvature omega / vx = 1 / 0.3: omega = r (R - L) / d, vx = r (L + R) / 2
    omega = 0.033 * (right - left) / 0.16
    vx = 0.033 * (left + right) / 2
    assert omega / vx == pytest.approx(1.0 / 0.3, rel=1e-9)
    # backwards and turning clockwise: the faster wheel is at -limit
    left, right = rig.send(-0.3, -1.0).velocity
    assert (left, right) == pytest.approx((-limit * 0.22 / 0.38, -limit), abs=1e-6)
    warnings = rig.warnings()
    assert len(warnings) == 1, "the saturation warning is throttled"
    assert "exceeds the wheel speed limit" in warnings[0]


def test_lateral_velocity_is_dropped_with_a_warning(ros):
    rig = Rig(ros)
    wheel_cmd = rig.send(vx=0.1, omega=0.5, vy=0.05)
    assert list(wheel_cmd.velocity) == pytest.approx([0.06 / 0.033, 0.14 / 0.033], abs=TOL)
    warnings = rig.warnings()
    assert len(warnings) == 1 and "linear.y" in warnings[0]


@pytest.mark.parametrize(
    "bad", [dict(vx=math.nan), dict(omega=math.inf), dict(vy=-math.inf), dict(vx=1e308, omega=1e308)]
)
def test_bad_commands_are_skipped_with_a_warning_and_the_node_keeps_going(ros, bad):
    rig = Rig(ros)
    rig.publish(**bad)
    rig.publish(**bad)
    # topics keep their order: the first wheel_cmd after the bad commands answers the good one
    wheel_cmd = rig.send(0.1, 0.0)
    assert list(wheel_cmd.velocity) == pytest.approx([0.1 / 0.033] * 2, abs=TOL)
    warnings = rig.warnings()
    assert len(rig.wheel_cmds) == 1
    assert len(warnings) == 1, "repeated bad commands are throttled to one warning"
    assert "cmd_vel skipped" in warnings[0]


def test_parameters_override_the_burger_constants_and_joint_names(ros):
    overrides = [
        Parameter("wheel_radius", value=0.05),
        Parameter("track_width", value=1),  # an int where a float is expected
        Parameter("wheel_left", value="left"),
        Parameter("wheel_right", value="right"),
    ]
    rig = Rig(ros, parameter_overrides=overrides)
    wheel_cmd = rig.send(0.1, 0.2)
    assert list(wheel_cmd.name) == ["left", "right"]
    assert list(wheel_cmd.velocity) == pytest.approx([(0.1 - 0.1) / 0.05, (0.1 + 0.1) / 0.05], abs=TOL)


@pytest.mark.parametrize(
    "parameter",
    [
        Parameter("wheel_radius", value=-0.033),
        Parameter("motor_cmd_max", value=0),
        Parameter("track_width", value="wide"),
        Parameter("wheel_right", value="wheel_left_joint"),
    ],
    ids=lambda p: p.name,
)
def test_invalid_parameters_refuse_to_construct(ros, parameter):
    with pytest.raises(ValueError, match=parameter.name):
        TurtleControlNode(context=ros.context, parameter_overrides=[parameter])


def test_the_wheels_stop_cmd_timeout_after_the_last_command(ros):
    rig = Rig(ros, parameter_overrides=[Parameter("cmd_timeout", value=0.3)])
    moving = rig.send(vx=0.1)
    assert list(moving.velocity) != [0.0, 0.0]
    sent = rig.node.get_clock().now().nanoseconds
    assert ros.spin_until(lambda: list(rig.wheel_cmds[-1].velocity) == [0.0, 0.0], 5.0), "never stopped"
    stopped = rig.node.get_clock().now().nanoseconds
    assert (stopped - sent) * 1e-9 >= 0.3
    # once: no stream of zero commands
    count = len(rig.wheel_cmds)
    ros.spin_for(0.5)
    assert len(rig.wheel_cmds) == count


def test_a_zero_cmd_timeout_holds_the_command(ros):
    rig = Rig(ros, parameter_overrides=[Parameter("cmd_timeout", value=0.0)])
    rig.send(vx=0.1)
    count = len(rig.wheel_cmds)
    ros.spin_for(0.8)
    assert len(rig.wheel_cmds) == count
