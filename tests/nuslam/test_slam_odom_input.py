"""slam with ``motion_source: odom`` (real rclpy): the motion is the relative pose between consecutive
nav_msgs/Odometry messages of any odometry source, through `turtlelib.OdometryMotion`.

Expected values come from turtlelib: a `turtlelib.EkfSlam` with the same motion model fed the same poses,
and the true landmarks.
"""

from __future__ import annotations

import math

import numpy as np
import pytest
from diagnostic_msgs.msg import DiagnosticStatus
from nav_msgs.msg import Odometry
from ros_test_messages import cylinder_array, stamp
from test_slam_node import (
    LANDMARKS,
    Rig,
    S,
    assert_covariance,
    close_pose,
    mapped,
    motion_gate_status,
    pose_of,
    relative,
)

from nuslam.slam_node import WHEEL_NOISE
from nuturtle_description.robot_params import burger_params
from nuturtle_ros_common.conversions import odometry_message
from turtlelib import EkfSlam, OdometryMotion, SlamConfig, Transform2D, Twist2D, TwistNoise

pytestmark = pytest.mark.ros

DRIVE = burger_params().diff_drive()
T_BODY_SENSOR = Transform2D(-0.032, 0.0, 0.0)


def odom_at(t_ns: int, T_odom_body: Transform2D) -> Odometry:
    return odometry_message(T_odom_body, Twist2D(), "odom", "base_footprint", stamp(t_ns))


class OdomRig(Rig):
    """The slam node following odom (Rig's helper publishes it)."""

    def __init__(self, ros, **parameters) -> None:
        super().__init__(ros, motion_source="odom", **parameters)

    def moved(self, t_ns: int, T_odom_body: Transform2D) -> Odometry:
        """Publish odom and return the slam/odom it causes."""
        count = len(self.odoms)
        self.odom.publish(odom_at(t_ns, T_odom_body))
        assert self.ros.spin_until(lambda: len(self.odoms) > count, 5.0), "no slam/odom"
        return self.odoms[-1]


def test_odom_poses_move_slam_as_the_odometry_motion_model_does(ros):
    T0 = Transform2D(0.5, -0.25, 0.7)
    rig = OdomRig(ros, x0=T0.x, y0=T0.y, theta0=T0.theta, observation_timeout=100.0)
    reference = EkfSlam(SlamConfig(), OdometryMotion(TwistNoise.from_wheel_slip(DRIVE, WHEEL_NOISE)), T0)
    # any odom frame origin: only relative poses count
    T_odom_body = Transform2D(3.0, 1.0, -2.0)
    t_ns = 40 * S
    first = rig.moved(t_ns, T_odom_body)
    assert close_pose(first, T0)
    steps = [Transform2D(0.05, 0.0, 0.0)] * 3 + [Transform2D(0.08, 0.01, 0.3)] * 4
    for T_step in steps:
        t_ns += S // 2
        T_odom_body = T_odom_body @ T_step
        odom = rig.moved(t_ns, T_odom_body)
        reference.predict((T_step.x, T_step.y, T_step.theta, S // 2))
        assert close_pose(odom, reference.pose), (pose_of(odom), reference.pose)
        np.testing.assert_allclose(assert_covariance(odom), reference.pose_covariance, rtol=1e-9, atol=1e-15)
        # the twist is the mean body twist of the step: log(T_step) / dt
        twist = T_step.log()
        assert odom.twist.twist.linear.x == pytest.approx(twist.vx / 0.5, abs=1e-9)
        assert odom.twist.twist.linear.y == pytest.approx(twist.vy / 0.5, abs=1e-9)
        assert odom.twist.twist.angular.z == pytest.approx(twist.omega / 0.5, abs=1e-9)
    assert rig.warnings() == []


def test_joint_states_are_not_followed_with_odom_as_the_motion_source(ros):
    rig = OdomRig(ros)
    assert rig.node.count_publishers("joint_states") == 1
    assert rig.node.count_subscribers("joint_states") == 0, "only the test helper's publisher"


def test_known_landmarks_map_at_their_true_places_from_odom(ros):
    rig = OdomRig(ros, association="known")
    T = Transform2D()
    rig.moved(S, T)
    for k in range(3, 9):
        T = T @ Transform2D(0.05, 0.0, 0.1)
        rig.moved(k * S // 2, T)
    array = rig.observe(cylinder_array("base_footprint", 8 * S // 2, relative(T)))
    for landmark_id, xy in LANDMARKS.items():
        marker = mapped(array)[landmark_id]
        assert (marker.pose.position.x, marker.pose.position.y) == pytest.approx(xy, abs=1e-9)


def test_a_heading_across_pi_is_motion_not_a_jump(ros):
    rig = OdomRig(ros, observation_timeout=100.0)
    rig.moved(S, Transform2D(0.0, 0.0, math.pi - 0.05))
    odom = rig.moved(S + S // 2, Transform2D(0.0, 0.0, -math.pi + 0.05))  # turned 0.1 rad
    assert close_pose(odom, Transform2D(0.0, 0.0, 0.1))
    assert rig.warnings() == []


def test_an_odom_stamped_back_in_time_is_refused_with_a_warning_and_changes_nothing(ros):
    rig = OdomRig(ros, observation_timeout=100.0)
    rig.moved(10 * S, Transform2D())
    before = rig.moved(10 * S + S // 2, Transform2D(0.1, 0.0, 0.0))
    rig.odom.publish(odom_at(5 * S, Transform2D(0.15, 0.0, 0.0)))  # a time jump back
    odom = rig.moved(11 * S, Transform2D(0.2, 0.0, 0.0))
    assert close_pose(odom, Transform2D(0.2, 0.0, 0.0))
    assert len(rig.odoms) == 3, "the refused message published nothing"
    assert close_pose(before, Transform2D(0.1, 0.0, 0.0))
    warnings = rig.warnings(at_least=1)
    assert len(warnings) == 1 and "odom refused" in warnings[0] and "not after" in warnings[0]


def test_an_odometry_silent_for_3_4_s_while_the_robot_drove_on_is_bridged_warned_and_counted(ros):
    # as the Radish ACES recording's odometry does: slam keeps the odometry's motion across the silence
    rig = OdomRig(ros, observation_timeout=100.0)
    rig.moved(10 * S, Transform2D())
    rig.moved(10 * S + S // 2, Transform2D(0.1, 0.0, 0.0))
    # 3.4 s later the robot has driven about 1 m on (the Burger could drive 0.67 m/s x 3.4 s)
    after = [Transform2D(1.0, 0.2, 0.5) @ Transform2D(0.1 * k, 0.0, 0.0) for k in range(3)]
    for k, T_odom_body in enumerate(after):
        rig.odom.publish(odom_at(13_900_000_000 + k * S // 2, T_odom_body))
    assert rig.ros.spin_until(lambda: len(rig.odoms) == 5)
    assert close_pose(rig.odoms[-1], after[-1], 1e-9), pose_of(rig.odoms[-1])
    # the silence is one step of the motion model, with its noise over the whole step
    reference = EkfSlam(SlamConfig(), OdometryMotion(TwistNoise.from_wheel_slip(DRIVE, WHEEL_NOISE)))
    T_before = Transform2D(0.1, 0.0, 0.0)
    T_across = T_before.inverse() @ after[0]
    for T_step, dt_ns in [
        (T_before, S // 2),
        (T_across, 3_400_000_000),
        *[(Transform2D(0.1, 0.0, 0.0), S // 2)] * 2,
    ]:
        reference.predict((T_step.x, T_step.y, T_step.theta, dt_ns))
    np.testing.assert_allclose(
        assert_covariance(rig.odoms[-1]), reference.pose_covariance, rtol=1e-9, atol=1e-15
    )
    warnings = rig.warnings(at_least=2)
    assert len(warnings) == 2 and "odom refused" in warnings[0] and "bridged" in warnings[1]
    gate, values = motion_gate_status(rig)
    assert gate.level == DiagnosticStatus.WARN and "1 silences bridged" in gate.message
    assert (values["motion_silences_bridged"], values["motion_longest_bridge_s"]) == ("1", "3.4")
    assert values["motion_restarts"] == "0"


def test_an_odometry_reset_restarts_from_the_estimate_with_a_warning_and_keeps_the_map(ros):
    rig = OdomRig(ros, association="known", observation_timeout=100.0)
    rig.moved(10 * S, Transform2D(1.0, 2.0, 0.5))
    rig.moved(10 * S + S // 2, Transform2D(1.0, 2.0, 0.5) @ Transform2D(0.1, 0.0, 0.0))
    rig.moved(11 * S, Transform2D(1.0, 2.0, 0.5) @ Transform2D(0.1, 0.0, 0.0))  # standing
    rig.observe(cylinder_array("base_footprint", 11 * S, relative(Transform2D(0.1, 0.0, 0.0))))
    # the base reboots for 5 s: its odometry starts again at the origin. The Burger could have driven
    # there (2.3 m at most 0.67 m/s x 5 s), but a robot that drove on is not back at the origin: the third
    # message (restart_samples) restarts the timeline at the first and moves on along the others
    rig.odom.publish(odom_at(16 * S, Transform2D()))
    rig.odom.publish(odom_at(16 * S + S // 2, Transform2D(0.1, 0.0, 0.0)))
    rig.odom.publish(odom_at(17 * S, Transform2D(0.2, 0.0, 0.0)))
    assert rig.ros.spin_until(lambda: len(rig.odoms) == 5)
    assert close_pose(rig.odoms[-1], Transform2D(0.3, 0.0, 0.0), 1e-9), pose_of(rig.odoms[-1])
    # the map is the one before the reset, and observations go on being applied
    array = rig.observe(cylinder_array("base_footprint", 17 * S, relative(Transform2D(0.3, 0.0, 0.0))))
    for landmark_id, xy in LANDMARKS.items():
        marker = mapped(array)[landmark_id]
        assert (marker.pose.position.x, marker.pose.position.y) == pytest.approx(xy, abs=1e-9)
    warnings = rig.warnings(at_least=2)
    assert len(warnings) == 2 and "odom refused" in warnings[0] and "restarted" in warnings[1]
    assert "origin" in warnings[1]


def test_odom_moving_faster_than_the_robot_is_refused(ros):
    rig = OdomRig(ros, observation_timeout=100.0)
    rig.moved(10 * S, Transform2D())
    # 1 m in 0.1 s: 15 times the Burger's bound, 1.5 x 0.447 m/s (its fastest wheel, 13.55 rad/s, x r)
    rig.odom.publish(odom_at(10 * S + S // 10, Transform2D(1.0, 0.0, 0.0)))
    odom = rig.moved(10 * S + S // 5, Transform2D(0.02, 0.0, 0.0))
    assert close_pose(odom, Transform2D(0.02, 0.0, 0.0))
    warnings = rig.warnings(at_least=1)
    assert len(warnings) == 1 and "odom refused" in warnings[0] and "moved" in warnings[0]


def test_the_map_is_latched_for_late_subscribers(ros):
    from rclpy.qos import DurabilityPolicy, QoSProfile, ReliabilityPolicy
    from visualization_msgs.msg import MarkerArray

    rig = OdomRig(ros, association="known")
    rig.moved(S, Transform2D())
    rig.observe(cylinder_array("base_footprint", S, relative(Transform2D())))
    late: list[MarkerArray] = []
    qos = QoSProfile(
        depth=1, reliability=ReliabilityPolicy.RELIABLE, durability=DurabilityPolicy.TRANSIENT_LOCAL
    )
    rig.helper.create_subscription(MarkerArray, "slam/map", late.append, qos)
    assert ros.spin_until(lambda: len(late) == 1, 5.0), "a late subscriber gets the last map"
    assert set(mapped(late[0])) == set(LANDMARKS)
    info = rig.node.get_publishers_info_by_topic("/slam/map")
    assert [p.qos_profile.durability for p in info] == [DurabilityPolicy.TRANSIENT_LOCAL]
    assert [p.qos_profile.reliability for p in info] == [ReliabilityPolicy.RELIABLE]
