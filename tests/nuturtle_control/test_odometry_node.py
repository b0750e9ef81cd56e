"""odometry in process with real rclpy: joint_states in, odom and odometry/path out; plus its executable.

The wheel angles of a known arc are built by hand: a quarter circle of radius R = 0.5 m turning left
(arc length s = R pi / 2, heading change pi / 2) takes phi_left = (s - (pi / 2) d / 2) / r and
phi_right = (s + (pi / 2) d / 2) / r with r = 0.033 m, d = 0.16 m, and ends at (0.5, 0.5, pi / 2).
"""

from __future__ import annotations

import math
from itertools import pairwise

import pytest
from geometry_msgs.msg import PoseWithCovarianceStamped
from nav_msgs.msg import Odometry, Path
from rclpy.parameter import Parameter
from sensor_msgs.msg import JointState

from nuturtle_control.odometry import OdometryFrames, OdometryNode
from nuturtle_ros_common.conversions import quaternion_from_yaw, yaw_from_quaternion
from rclpy_harness import matched, record_rosout, warnings_of
from turtlelib.geometry.path_trail import PathTrailConfig

pytestmark = pytest.mark.ros

R_WHEEL = 0.033
TRACK = 0.16
TOL = 1e-9


def quarter_circle_angles(fraction: float) -> tuple[float, float]:
    """Wheel angles (rad) after `fraction` of the left quarter circle of radius 0.5 m."""
    heading = fraction * math.pi / 2
    arc = 0.5 * heading
    return (arc - heading * TRACK / 2) / R_WHEEL, (arc + heading * TRACK / 2) / R_WHEEL


def joint_state(t_s, positions, names=("wheel_left_joint", "wheel_right_joint")) -> JointState:
    msg = JointState(name=list(names), position=[float(p) for p in positions])
    msg.header.stamp.sec = int(t_s)
    msg.header.stamp.nanosec = int(round((t_s - int(t_s)) * 1e9))
    return msg


def pose_of(odom: Odometry) -> tuple[float, float, float]:
    pose = odom.pose.pose
    return pose.position.x, pose.position.y, yaw_from_quaternion(pose.orientation)


class Rig:
    """odometry plus a helper node publishing joint_states / initialpose and recording the outputs."""

    def __init__(self, ros, **node_kwargs) -> None:
        self.ros = ros
        self.node = ros.add(OdometryNode(context=ros.context, **node_kwargs))
        helper = ros.node("odometry_test_helper")
        self.odoms: list[Odometry] = []
        self.paths: list[Path] = []
        self.logs = record_rosout(helper)
        self.joint_states = helper.create_publisher(JointState, "joint_states", 10)
        self.initial_pose = helper.create_publisher(PoseWithCovarianceStamped, "initialpose", 10)
        endpoints = [
            self.joint_states,
            self.initial_pose,
            helper.create_subscription(Odometry, "odom", self.odoms.append, 10),
            helper.create_subscription(Path, "odometry/path", self.paths.append, 10),
        ]
        assert ros.spin_until(lambda: matched(*endpoints), 10.0)

    def send(self, msg: JointState) -> Odometry:
        """Publish joint_states and return the odom it causes."""
        count = len(self.odoms)
        self.joint_states.publish(msg)
        assert self.ros.spin_until(lambda: len(self.odoms) > count, 5.0), "no odom"
        return self.odoms[-1]

    def warnings(self) -> list[str]:
        self.ros.spin_for(0.1)
        return warnings_of(self.logs, "odometry")


def test_a_known_arc_in_steps_ends_at_the_hand_computed_pose_with_its_body_twist(ros):
    rig = Rig(ros)
    first = rig.send(joint_state(100.0, (3.0, -2.0)))  # the reference: any angles, pose stays at zero
    assert pose_of(first) == pytest.approx((0.0, 0.0, 0.0), abs=TOL)
    assert first.header.stamp.sec == 100
    assert (first.header.frame_id, first.child_frame_id) == ("odom", "base_footprint")
    steps = 8
    for k in range(1, steps + 1):
        left, right = quarter_circle_angles(k / steps)
        odom = rig.send(joint_state(100.0 + 0.5 * k, (3.0 + left, -2.0 + right)))
        # halfway: 45 degrees round the circle centred on (0, 0.5)
        if k == steps // 2:
            half = math.pi / 4
            expected = (0.5 * math.sin(half), 0.5 - 0.5 * math.cos(half), half)
            assert pose_of(odom) == pytest.approx(expected, abs=TOL)
    assert pose_of(odom) == pytest.approx((0.5, 0.5, math.pi / 2), abs=TOL)
    assert (odom.header.stamp.sec, odom.header.stamp.nanosec) == (104, 0)
    # body twist over the last 0.5 s step: a 1/8 of the quarter arc per 0.5 s
    twist = odom.twist.twist
    assert twist.linear.x == pytest.approx(0.5 * (math.pi / 16) / 0.5, abs=TOL)
    assert twist.linear.y == 0.0
    assert twist.angular.z == pytest.approx((math.pi / 16) / 0.5, abs=TOL)
    assert rig.warnings() == []


def test_path_is_decimated_published_once_per_period_and_ends_at_the_odometry_pose(ros):
    rig = Rig(ros)
    config = PathTrailConfig()  # the node's defaults: a pose every 5 cm, the path once per second
    rig.send(joint_state(1.0, (0.0, 0.0)))
    # 0.2 m straight in 1 mm steps over 2 s: a new path pose every 5 cm, not every message
    for k in range(1, 201):
        phi = k * 0.001 / R_WHEEL
        odom = rig.send(joint_state(1.0 + 0.01 * k, (phi, phi)))
    assert pose_of(odom) == pytest.approx((0.2, 0.0, 0.0), abs=1e-9)
    rig.ros.spin_for(0.1)
    path = rig.paths[-1]
    assert path.header.frame_id == "odom"
    xs = [pose.pose.position.x for pose in path.poses]
    assert xs == pytest.approx([0.0, 0.05, 0.1, 0.15, 0.2], abs=0.0011)
    assert all(b - a >= config.path_min_step_m - 1e-12 for a, b in pairwise(xs))
    # published whole at t = 1, 2 and 3 s only: once per path_period, not at every kept pose
    stamps = [(p.header.stamp.sec, p.header.stamp.nanosec) for p in rig.paths]
    assert stamps == [(1, 0), (2, 0), (3, 0)]


def test_initialpose_resets_the_pose_and_following_motion_starts_from_it(ros):
    rig = Rig(ros)
    rig.send(joint_state(1.0, (0.0, 0.0)))
    rig.send(joint_state(1.5, (1.0, 2.0)))
    reset = PoseWithCovarianceStamped()
    reset.header.frame_id = "odom"
    reset.pose.pose.position.x, reset.pose.pose.position.y = 1.0, 2.0
    reset.pose.pose.orientation = quaternion_from_yaw(0.5)
    rig.initial_pose.publish(reset)
    rig.ros.spin_for(0.2)
    # 0.1 m straight ahead from (1, 2) facing 0.5 rad
    dphi = 0.1 / R_WHEEL
    odom = rig.send(joint_state(2.0, (1.0 + dphi, 2.0 + dphi)))
    expected = (1.0 + 0.1 * math.cos(0.5), 2.0 + 0.1 * math.sin(0.5), 0.5)
    assert pose_of(odom) == pytest.approx(expected, abs=TOL)
    # a pose in another frame cannot be used without tf: refused with a warning
    reset.header.frame_id = "map"
    reset.pose.pose.position.x = 7.0
    rig.initial_pose.publish(reset)
    rig.ros.spin_for(0.2)
    odom = rig.send(joint_state(2.5, (1.0 + dphi, 2.0 + dphi)))
    assert pose_of(odom)[0] == pytest.approx(1.0 + 0.1 * math.cos(0.5), abs=TOL)
    warnings = rig.warnings()
    assert len(warnings) == 1 and "'map'" in warnings[0]


@pytest.mark.parametrize(
    "orientation",
    [(0.0, 0.0, 0.0, 0.0), (0.0, 0.0, math.inf, -math.inf), (0.0, 0.0, math.nan, 1.0), (0.0, 0.0, 1.0, 1.0)],
    ids=["zero", "infinite", "NaN", "norm sqrt(2)"],
)
def test_an_initialpose_whose_quaternion_is_not_a_rotation_is_refused(ros, orientation):
    rig = Rig(ros)
    rig.send(joint_state(1.0, (0.0, 0.0)))
    reset = PoseWithCovarianceStamped()
    reset.header.frame_id = "odom"
    reset.pose.pose.position.x = 1.0
    reset.pose.pose.orientation.x, reset.pose.pose.orientation.y = orientation[:2]
    reset.pose.pose.orientation.z, reset.pose.pose.orientation.w = orientation[2:]
    rig.initial_pose.publish(reset)
    rig.ros.spin_for(0.2)
    dphi = 0.1 / R_WHEEL
    odom = rig.send(joint_state(1.5, (dphi, dphi)))
    assert pose_of(odom) == pytest.approx((0.1, 0.0, 0.0), abs=TOL), "the pose was not reset"
    warnings = rig.warnings()
    assert len(warnings) == 1 and "not a rotation" in warnings[0]


WHEELS = ["wheel_left_joint", "wheel_right_joint"]
BAD_JOINT_STATES = {
    # kind: (message, part of the warning)
    "missing joint": (joint_state(2.0, (5.0,), names=WHEELS[:1]), "'wheel_right_joint' is missing"),
    "unknown joints": (joint_state(2.0, (5.0, 5.0), names=("left", "right")), "missing"),
    "NaN angle": (joint_state(2.0, (math.nan, 5.0)), "non-finite"),
    "infinite angle": (joint_state(2.0, (5.0, -math.inf)), "non-finite"),
    "sizes differ": (JointState(name=WHEELS, position=[5.0]), "2 joint names but 1 values"),
    "no positions": (JointState(name=WHEELS), "2 joint names but 0 values"),
    "joint twice": (joint_state(2.0, (5.0,) * 3, names=WHEELS + WHEELS[:1]), "more than once"),
}


@pytest.mark.parametrize("kind", BAD_JOINT_STATES)
def test_bad_joint_states_are_skipped_with_a_throttled_warning_and_the_node_keeps_going(ros, kind):
    bad, reason = BAD_JOINT_STATES[kind]
    rig = Rig(ros)
    rig.send(joint_state(1.0, (0.0, 0.0)))
    for _ in range(3):
        rig.joint_states.publish(bad)
    # topics keep their order: the next odom answers this good message, integrated from the first one
    dphi = 0.1 / R_WHEEL
    odom = rig.send(joint_state(1.5, (dphi, dphi)))
    assert pose_of(odom) == pytest.approx((0.1, 0.0, 0.0), abs=TOL)
    assert odom.twist.twist.linear.x == pytest.approx(0.1 / 0.5, abs=TOL)
    warnings = rig.warnings()
    assert len(rig.odoms) == 2
    assert len(warnings) == 1, "three bad messages, one (throttled) warning"
    assert "joint_states skipped" in warnings[0] and reason in warnings[0]


def test_a_restarted_simulator_is_followed_after_restart_samples_messages(ros):
    rig = Rig(ros)
    rig.send(joint_state(10.0, (0.0, 0.0)))
    dphi = 0.1 / R_WHEEL
    rig.send(joint_state(10.5, (dphi, dphi)))  # 0.1 m
    # a restarted simulator: time and wheel angles start again; the first restart_samples - 1 = 2 messages
    # are refused, the third restarts the reference at the first and integrates the motion since
    rig.joint_states.publish(joint_state(0.5, (0.0, 0.0)))
    rig.joint_states.publish(joint_state(1.0, (dphi, dphi)))
    rig.ros.spin_for(0.2)
    assert len(rig.odoms) == 2
    rig.send(joint_state(1.5, (2 * dphi, 2 * dphi)))
    assert rig.ros.spin_until(lambda: len(rig.odoms) == 4), "one odom per message after the new reference"
    odom = rig.odoms[3]
    assert pose_of(rig.odoms[2]) == pytest.approx((0.2, 0.0, 0.0), abs=TOL)
    assert pose_of(odom) == pytest.approx((0.3, 0.0, 0.0), abs=TOL)
    assert odom.twist.twist.linear.x == pytest.approx(0.1 / 0.5, abs=TOL)
    warnings = rig.warnings()
    assert len(warnings) == 2 and "not after" in warnings[0] and "restarted" in warnings[1]


def hostile_joint_states(t_s: float, phi: float) -> dict[str, JointState]:
    """Single messages that must not move the odometry of a robot at ``phi`` (both wheels) at ``t_s``."""
    replayed = joint_state(t_s - 1.0, (phi - 1.0, phi - 1.0))
    nanosec = joint_state(t_s, (phi, phi))
    nanosec.header.stamp.nanosec = 4_000_000_000
    return {
        "replayed from 1 s earlier": replayed,
        "stamped 1 s in the future": joint_state(t_s + 1.0, (phi, phi)),
        "nanosec 4e9": nanosec,
        "both wheels +1e6 rad": joint_state(t_s + 0.05, (phi + 1e6, phi + 1e6)),
        "one wheel +1e6 rad": joint_state(t_s + 0.05, (phi + 1e6, phi)),
        "both wheels +1e200 rad": joint_state(t_s + 0.05, (1e200, 1e200)),
        "negative sec": joint_state(-5.0, (phi, phi)),
    }


@pytest.mark.parametrize("kind", list(hostile_joint_states(0.0, 0.0)))
def test_a_single_implausible_joint_states_is_refused_and_motion_is_counted_once(ros, kind):
    """Issue: a joint_states replayed from 1 s earlier, stamped in the future or with nanosec 4e9 made
    odometry count a second of motion twice or lose it; +1e6 rad on one wheel put odom 0.78 m off."""
    rig = Rig(ros)
    dphi = 0.01 / R_WHEEL  # 1 cm per 50 ms
    for k in range(21):
        rig.send(joint_state(1.0 + 0.05 * k, (k * dphi, k * dphi)))
    rig.joint_states.publish(hostile_joint_states(2.0, 20 * dphi)[kind])
    for k in range(21, 41):
        odom = rig.send(joint_state(1.0 + 0.05 * k, (k * dphi, k * dphi)))
    assert pose_of(odom) == pytest.approx((0.4, 0.0, 0.0), abs=TOL)
    assert len(rig.odoms) == 41, "the hostile message published nothing"
    warnings = rig.warnings()
    assert len(warnings) == 1 and ("refused" in warnings[0] or "invalid stamp" in warnings[0])


def test_absurd_finite_angles_are_refused_and_forgotten(ros):
    rig = Rig(ros)
    rig.send(joint_state(1.0, (0.0, 0.0)))
    rig.joint_states.publish(joint_state(1.1, (1e308, -1e308)))  # the turn rate would overflow to inf
    rig.send(joint_state(1.2, (0.0, 0.0)))
    dphi = 0.1 / R_WHEEL
    odom = rig.send(joint_state(1.7, (dphi, dphi)))
    assert pose_of(odom) == pytest.approx((0.1, 0.0, 0.0), abs=TOL)
    assert len(rig.odoms) == 3
    warnings = rig.warnings()
    assert len(warnings) == 1 and "value 0 moved" in warnings[0]


def test_parameters_set_joint_names_frames_and_robot_constants(ros):
    overrides = [
        Parameter("wheel_left", value="l"),
        Parameter("wheel_right", value="r"),
        Parameter("body_id", value="robot/base_footprint"),
        Parameter("odom_id", value="robot/odom"),
        Parameter("wheel_radius", value=0.05),
    ]
    rig = Rig(ros, parameter_overrides=overrides)
    names = ("r", "other", "l")  # any order, other joints ignored
    rig.send(joint_state(1.0, (0.0, 9.0, 0.0), names=names))
    odom = rig.send(joint_state(1.5, (2.0, -9.0, 2.0), names=names))  # 2 rad of a 5 cm wheel
    assert pose_of(odom) == pytest.approx((0.1, 0.0, 0.0), abs=TOL)
    assert (odom.header.frame_id, odom.child_frame_id) == ("robot/odom", "robot/base_footprint")


@pytest.mark.parametrize(
    "fields, message",
    [
        (dict(body_id=""), "body_id must be a non-empty frame id, got ''"),
        (dict(odom_id=None), "odom_id must be a non-empty frame id, got None"),
        (dict(odom_id="base_footprint"), "body_id, odom_id must be distinct frame ids"),
    ],
)
def test_odometry_frames_must_be_non_empty_and_distinct(fields, message):
    with pytest.raises(ValueError, match=message):
        OdometryFrames(**fields)


@pytest.mark.parametrize("model", ["burger", "waffle"])
def test_the_wheel_speed_bound_is_the_model_s_and_a_refusal_names_the_parameters_to_change(ros, model):
    """22 rad/s: beyond the Burger's bound, 1.5 x (0.22 + 2.84 x 0.08) / 0.033 = 20.3 rad/s; within the
    Waffle's, 1.5 x (0.26 + 1.82 x 0.1435) / 0.033 = 23.7 rad/s (a Gazebo Waffle at both teleop bounds)."""
    rig = Rig(ros, parameter_overrides=[Parameter("model", value=model)])
    rig.send(joint_state(1.0, (0.0, 0.0)))
    dphi = 22.0 * 0.05
    rig.joint_states.publish(joint_state(1.05, (dphi, dphi)))
    ros.spin_for(0.3)
    warnings = rig.warnings()
    if model == "waffle":
        assert len(rig.odoms) == 2 and not warnings
        assert pose_of(rig.odoms[-1]) == pytest.approx((dphi * R_WHEEL, 0.0, 0.0), abs=TOL)
    else:
        assert len(rig.odoms) == 1 and len(warnings) == 1
        assert "joint_states refused: value 0 moved 1.1 in 0.050 s" in warnings[0]
        assert "max rate 13.55 rad/s" in warnings[0]
        assert "a faster robot needs its own `model`" in warnings[0] and "speed_margin" in warnings[0]
