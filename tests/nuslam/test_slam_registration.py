"""slam with `scan_registration` (real rclpy): scans of a room registered with the wheels as the prior
correct wheels that drift, and /diagnostics says what the pose rests on. The registration's own properties
(accuracy, outliers, degeneracy, covariance by Monte Carlo, never worse than the input) are tested in
tests/turtlelib/test_scan_registration.py."""

from __future__ import annotations

import math

import numpy as np
import pytest
from diagnostic_msgs.msg import DiagnosticArray, DiagnosticStatus
from ros_test_messages import stamp, stamp_ns
from test_slam_grid import scan_message
from test_slam_maps import diagnostics
from test_slam_node import Arc, Rig, S, TfRecorder, joint_state, pose_of

from nuturtle_ros_common.conversions import odometry_message
from turtlelib import Transform2D, Twist2D

pytestmark = pytest.mark.ros

STEPS = 12


def test_registered_scans_correct_drifting_wheels_and_diagnostics_say_so(ros):
    rig = Rig(ros, scan_registration=True, lidar_x=0.25, lidar_y=-0.1, lidar_yaw=0.5)
    # every report from the start: one that comes after the last scan says only that no scan came since
    reports: list[DiagnosticArray] = []
    rig.helper.create_subscription(DiagnosticArray, "/diagnostics", reports.append, 10)
    truth = Arc(Transform2D(), S, vx=0.15, omega=0.5)
    # the wheels report 0.3 rad/s more turn than the robot makes (a wheel slipping)
    wheels = Arc(Transform2D(), S, vx=0.15, omega=0.8)
    rng = np.random.default_rng(2)
    for k in range(STEPS):
        t_ns = S + k * S // 5
        count = len(rig.odoms)
        # the scan first: the first one reaches slam before the first joint_states, so the map starts at the
        # start pose (joint_states alone, with the LiDAR quiet, would move the filter on by the wheels)
        rig.scans.publish(scan_message(truth.pose(t_ns), t_ns, rng))
        if k == 0:
            ros.spin_for(0.2)
        rig.joint_states.publish(joint_state(t_ns, wheels.angles(t_ns)))
        # the pose starts at the first registered scan: from the second step on, each joint_states gives one
        assert k == 0 or ros.spin_until(lambda c=count: len(rig.odoms) > c, 5.0), f"no odom at step {k}"
    # a joint_states sample 1 ms after the last scan (registered by then): the pose there is that scan's
    ros.spin_for(0.3)
    count = len(rig.odoms)
    rig.joint_states.publish(joint_state(t_ns + 1_000_000, wheels.angles(t_ns + 1_000_000)))
    assert ros.spin_until(lambda: len(rig.odoms) > count, 5.0)
    T_slam = Transform2D(*pose_of(rig.odoms[-1]))
    T_true, T_wheels = truth.pose(t_ns), wheels.pose(t_ns)
    assert abs(T_wheels.theta - T_true.theta) == pytest.approx(0.66, abs=1e-6)
    error = T_true.inverse() @ T_slam
    assert math.hypot(error.x, error.y) < 0.02
    assert abs(error.theta) < math.radians(1.0)
    diagnostics(rig, "slam: scan registration")  # one more report, after the last scan's
    statuses = [s for a in reports for s in a.status if s.name == "slam: scan registration"]
    assert any("the pose rests on scan registration" in status.message for status in statuses)
    counts = [
        {pair.key: int(pair.value) for pair in status.values if pair.value.isdigit()} for status in statuses
    ]
    assert sum(c["scans_registered"] for c in counts) >= STEPS - 2
    assert sum(c["scans_skipped"] for c in counts) == 0


def test_a_scan_older_than_the_last_registered_one_is_skipped_counted_and_slam_goes_on(ros):
    """A late scan stamped before the newest registered one: skipped, counted in /diagnostics, and the
    next scan and joint_states are taken as usual (the skip path once raised in a callback)."""
    rig = Rig(ros, scan_registration=True)
    reports: list[DiagnosticArray] = []
    rig.helper.create_subscription(DiagnosticArray, "/diagnostics", reports.append, 10)
    truth = Arc(Transform2D(), S, vx=0.15, omega=0.5)
    rng = np.random.default_rng(3)
    for k in range(5):
        t_ns = S + k * S // 5
        count = len(rig.odoms)
        if k == 3:  # the late one, stamped at step 1
            rig.scans.publish(scan_message(truth.pose(S + S // 5), S + S // 5, rng))
        rig.scans.publish(scan_message(truth.pose(t_ns), t_ns, rng))
        if k == 0:
            ros.spin_for(0.2)
        rig.joint_states.publish(joint_state(t_ns, truth.angles(t_ns)))
        assert k == 0 or ros.spin_until(lambda c=count: len(rig.odoms) > c, 5.0), f"no odom at step {k}"
    diagnostics(rig, "slam: scan registration")
    statuses = [s for a in reports for s in a.status if s.name == "slam: scan registration"]
    skipped = [int(pair.value) for s in statuses for pair in s.values if pair.key == "scans_skipped"]
    assert sum(skipped) == 1


def test_with_the_lidar_quiet_slam_goes_on_with_the_wheels_and_says_so(ros):
    """No scan at all: every joint_states gets its pose, the wheels' dead reckoning exactly (never worse than
    the input), and /diagnostics says the pose rests on the motion input alone (ERROR)."""
    rig = Rig(ros, scan_registration=True)
    wheels = Arc(Transform2D(), S, vx=0.15, omega=0.8)
    for k in range(6):
        t_ns = S + k * S // 5
        odom = rig.wheels(t_ns, wheels.angles(t_ns))
        assert pose_of(odom) == pytest.approx(wheels.pose(t_ns).as_array(), abs=1e-9)
    status = diagnostics(rig, "slam: scan registration")
    assert status.level == DiagnosticStatus.ERROR
    assert "the motion input alone" in status.message


def test_a_scan_that_comes_after_the_wheels_corrects_the_pose_published_at_its_stamp(ros):
    """A LiDAR's messages reach slam after the wheels' of the same instant: the scan is registered then, and
    slam publishes the pose at that stamp again, corrected (the last pose at a stamp is the best one);
    map -> odom goes out once per stamp (tf2 drops a repeated one with a warning)."""
    rig = Rig(ros, scan_registration=True, lidar_x=0.25, lidar_y=-0.1, lidar_yaw=0.5)  # scan_message's mount
    recorder = rig.node._map_to_odom._tf = TfRecorder()
    truth = Arc(Transform2D(), S, vx=0.15, omega=0.5)
    wheels = Arc(Transform2D(), S, vx=0.15, omega=0.8)  # 0.06 rad too much turn per step
    rng = np.random.default_rng(4)
    rig.scans.publish(scan_message(truth.pose(S), S, rng))  # the map starts at the start pose
    ros.spin_for(0.2)
    for k in range(STEPS):
        t_ns = S + k * S // 5
        count = len(rig.odoms)
        rig.odom.publish(
            odometry_message(wheels.pose(t_ns), Twist2D(), "odom", "base_footprint", stamp(t_ns))
        )
        rig.joint_states.publish(joint_state(t_ns, wheels.angles(t_ns)))
        assert ros.spin_until(lambda c=count: len(rig.odoms) > c, 5.0), f"no odom at step {k}"
        if k == 0:
            continue
        rig.scans.publish(scan_message(truth.pose(t_ns), t_ns, rng))
        assert ros.spin_until(lambda c=count: len(rig.odoms) > c + 1, 5.0), f"no corrected odom at step {k}"
        predicted, corrected = rig.odoms[-2:]
        assert stamp_ns(predicted.header.stamp) == stamp_ns(corrected.header.stamp) == t_ns
        heading_error = [
            abs((truth.pose(t_ns).inverse() @ Transform2D(*pose_of(odom))).theta)
            for odom in (predicted, corrected)
        ]
        assert heading_error[0] > math.radians(2.0), "the wheels' prediction turned too far"
        assert heading_error[1] < math.radians(1.0), "the scan corrected it"
    stamps = [stamp_ns(sent.header.stamp) for sent in recorder.sent]
    assert len(stamps) == len(set(stamps)) == STEPS, "one map -> odom per stamp"
