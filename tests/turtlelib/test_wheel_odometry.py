"""WheelOdometry (dead reckoning from wheel angles), without ROS."""

from __future__ import annotations

import math

import pytest
from hypothesis import given
from hypothesis import strategies as st

from turtlelib import DiffDrive, Transform2D
from turtlelib.motion.wheel_odometry import WheelOdometry

DRIVE = DiffDrive(0.033, 0.16)
TOL = 1e-9


def test_first_sample_is_only_a_reference():
    odometry = WheelOdometry(DRIVE)
    assert odometry.reference_time_s is None
    with pytest.raises(ValueError, match="reference"):
        odometry.step(0.0, 1.0, 1.0)
    odometry.set_reference(5.0, 100.0, -7.0)
    assert odometry.reference_time_s == 5.0
    assert odometry.T_odom_body == Transform2D()


def test_straight_line_and_turn_in_place_by_hand():
    odometry = WheelOdometry(DRIVE, Transform2D(1.0, 0.0, math.pi / 2))
    odometry.set_reference(0.0, 10.0, 20.0)
    # both wheels 2 rad: 0.066 m along the heading (+y)
    V_body = odometry.step(2.0, 12.0, 22.0)
    assert odometry.T_odom_body.as_array() == pytest.approx([1.0, 0.066, math.pi / 2], abs=TOL)
    assert (V_body.omega, V_body.vx, V_body.vy) == pytest.approx((0.0, 0.033, 0.0), abs=TOL)
    # right wheel +1 rad, left -1 rad: omega = 0.033 * 2 / 0.16 = 0.4125 rad in place
    V_body = odometry.step(3.0, 11.0, 23.0)
    assert odometry.T_odom_body.as_array() == pytest.approx([1.0, 0.066, math.pi / 2 + 0.4125], abs=TOL)
    assert (V_body.omega, V_body.vx) == pytest.approx((0.4125, 0.0), abs=TOL)
    assert odometry.reference_time_s == 3.0


def test_equal_stamps_move_the_pose_but_report_zero_twist():
    odometry = WheelOdometry(DRIVE)
    odometry.set_reference(1.0, 0.0, 0.0)
    V_body = odometry.step(1.0, 1.0, 1.0)
    assert odometry.T_odom_body.x == pytest.approx(0.033, abs=TOL)
    assert (V_body.omega, V_body.vx, V_body.vy) == (0.0, 0.0, 0.0)


@pytest.mark.parametrize(
    "sample", [(0.5, 1.0, 1.0), (2.0, math.nan, 1.0), (2.0, 1.0, math.inf), (math.nan, 1.0, 1.0)]
)
def test_invalid_samples_raise_and_leave_the_state_unchanged(sample):
    odometry = WheelOdometry(DRIVE, Transform2D(0.3, -0.2, 0.1))
    odometry.set_reference(1.0, 0.0, 0.0)
    with pytest.raises(ValueError):
        odometry.step(*sample)
    assert odometry.T_odom_body == Transform2D(0.3, -0.2, 0.1)
    assert odometry.reference_time_s == 1.0
    odometry.step(2.0, 1.0, 1.0)  # still integrates from the old reference
    assert odometry.T_odom_body.as_array() == pytest.approx(
        [0.3 + 0.033 * math.cos(0.1), -0.2 + 0.033 * math.sin(0.1), 0.1], abs=TOL
    )


increments = st.lists(st.tuples(st.floats(-3.0, 3.0), st.floats(-3.0, 3.0)), min_size=1, max_size=20)


@given(
    st.lists(st.floats(0.01, 1.0), min_size=1, max_size=20),
    st.floats(-20.0, 20.0),
    st.floats(-20.0, 20.0),
)
def test_one_arc_ends_at_the_same_pose_however_it_is_sampled(weights, total_left, total_right):
    """Angles, not speeds, are integrated: wheels turning at a constant ratio (one arc) reach the same
    pose in many samples of any sizes as in a single one."""
    fine = WheelOdometry(DRIVE)
    fine.set_reference(0.0, 0.0, 0.0)
    done = 0.0
    for k, weight in enumerate(weights, start=1):
        done += weight / sum(weights)
        fine.step(float(k), done * total_left, done * total_right)
    coarse = WheelOdometry(DRIVE)
    coarse.set_reference(0.0, 0.0, 0.0)
    coarse.step(1.0, total_left, total_right)
    assert fine.T_odom_body.x == pytest.approx(coarse.T_odom_body.x, abs=1e-9)
    assert fine.T_odom_body.y == pytest.approx(coarse.T_odom_body.y, abs=1e-9)
    assert math.remainder(fine.T_odom_body.theta - coarse.T_odom_body.theta, math.tau) == pytest.approx(
        0.0, abs=1e-9
    )


@given(increments)
def test_going_back_to_the_start_angles_in_reverse_order_returns_to_the_start_pose(dphis):
    odometry = WheelOdometry(DRIVE, Transform2D(0.5, 0.5, 1.0))
    angles = [(0.0, 0.0)]
    for dl, dr in dphis:
        angles.append((angles[-1][0] + dl, angles[-1][1] + dr))
    odometry.set_reference(0.0, *angles[0])
    path = angles[1:] + angles[-2::-1]  # out and back along the same wheel-angle path
    for k, (left, right) in enumerate(path, start=1):
        odometry.step(float(k), left, right)
    assert odometry.T_odom_body.as_array() == pytest.approx([0.5, 0.5, 1.0], abs=1e-9)
