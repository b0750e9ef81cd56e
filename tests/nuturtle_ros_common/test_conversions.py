"""nuturtle_ros_common.conversions: quaternions, poses, stamps and covariances."""

from __future__ import annotations

import math

import numpy as np
import pytest
from builtin_interfaces.msg import Time
from geometry_msgs.msg import Pose, Quaternion
from hypothesis import given
from hypothesis import strategies as st
from sensor_msgs.msg import LaserScan

from nuturtle_ros_common.conversions import (
    covariance_from_6x6,
    planar_covariance_6x6,
    pose_from_transform,
    quaternion_from_yaw,
    range_scan_from_message,
    stamp_from_seconds,
    stamp_nanoseconds,
    stamp_seconds,
    transform_from_pose,
    transform_stamped,
    yaw_from_quaternion,
)
from turtlelib import Transform2D

angles = st.floats(-math.pi, math.pi)


def test_hand_computed_quaternions():
    q = quaternion_from_yaw(math.pi / 2)
    assert (q.x, q.y, q.z, q.w) == pytest.approx((0.0, 0.0, math.sqrt(0.5), math.sqrt(0.5)), abs=1e-15)
    assert yaw_from_quaternion(Quaternion(x=0.0, y=0.0, z=1.0, w=0.0)) == pytest.approx(math.pi)
    # typed by hand, a little off unit norm: (0, 0, 0.7, 0.7) means 90 degrees
    assert yaw_from_quaternion(Quaternion(x=0.0, y=0.0, z=0.7, w=0.7)) == pytest.approx(math.pi / 2)


@pytest.mark.parametrize(
    "q",
    [(0.0, 0.0, 0.0, 0.0), (0.0, 0.0, 1.0, 1.0), (0.0, 0.0, 0.5, 0.5), (math.nan, 0.0, 0.0, 1.0),
     (0.0, 0.0, math.inf, -math.inf), (0.0, 0.0, 0.0, 1e300)],
)  # fmt: skip
def test_a_quaternion_that_is_not_a_rotation_is_refused(q):
    x, y, z, w = q
    with pytest.raises(ValueError, match="not a rotation"):
        yaw_from_quaternion(Quaternion(x=x, y=y, z=z, w=w))


@given(angles, st.floats(0.951, 1.049))
def test_yaw_round_trip_near_unit_norm(yaw, scale):
    q = quaternion_from_yaw(yaw)
    scaled = Quaternion(x=0.0, y=0.0, z=scale * q.z, w=scale * q.w)
    assert math.remainder(yaw_from_quaternion(scaled) - yaw, math.tau) == pytest.approx(0.0, abs=1e-12)


@given(st.floats(-100, 100), st.floats(-100, 100), angles)
def test_pose_round_trip(x, y, theta):
    T = Transform2D(x, y, theta)
    back = transform_from_pose(pose_from_transform(T))
    assert (back.x, back.y) == (x, y)
    assert math.remainder(back.theta - T.theta, math.tau) == pytest.approx(0.0, abs=1e-12)


def test_non_finite_pose_is_a_value_error():
    pose = Pose()
    pose.position.x = math.nan
    with pytest.raises(ValueError):
        transform_from_pose(pose)


def test_transform_stamped_fields():
    stamp = Time(sec=3, nanosec=5)
    msg = transform_stamped(Transform2D(1.0, 2.0, 0.5), "odom", "base_footprint", stamp)
    assert (msg.header.frame_id, msg.child_frame_id) == ("odom", "base_footprint")
    assert msg.header.stamp == stamp
    assert (msg.transform.translation.x, msg.transform.translation.y) == (1.0, 2.0)
    assert yaw_from_quaternion(msg.transform.rotation) == pytest.approx(0.5)


def test_stamp_from_seconds_carries_a_fraction_that_rounds_up_to_a_second():
    assert stamp_from_seconds(1.9999999999) == Time(sec=2, nanosec=0)
    assert stamp_from_seconds(3.25) == Time(sec=3, nanosec=250_000_000)
    assert stamp_from_seconds(-0.5) == Time(sec=-1, nanosec=500_000_000)


@pytest.mark.parametrize(
    ("sec", "nanosec"), [(-1, 0), (0, 1_000_000_000), (5, 4_000_000_000), (0, 2**32 - 1)]
)
def test_an_invalid_stamp_is_refused(sec, nanosec):
    with pytest.raises(ValueError, match="invalid stamp"):
        stamp_nanoseconds(Time(sec=sec, nanosec=nanosec))
    with pytest.raises(ValueError, match="invalid stamp"):
        stamp_seconds(Time(sec=sec, nanosec=nanosec))


@given(st.integers(0, 2**31 - 2), st.integers(0, 999_999_999))
def test_stamp_round_trip_within_float_resolution(sec, nanosec):
    seconds = stamp_seconds(Time(sec=sec, nanosec=nanosec))
    back = stamp_from_seconds(seconds)
    assert 0 <= back.nanosec < 1_000_000_000
    error_ns = (back.sec - sec) * 1_000_000_000 + (back.nanosec - nanosec)
    assert abs(error_ns) <= max(1, math.ulp(seconds) * 1e9)


def test_planar_covariance_embedding_round_trip():
    P = np.array([[1.0, 0.1, 0.2], [0.1, 2.0, 0.3], [0.2, 0.3, 3.0]])
    values = planar_covariance_6x6(P)
    assert len(values) == 36
    P6 = np.reshape(values, (6, 6))
    assert P6[0, 0] == 1.0 and P6[5, 5] == 3.0 and P6[0, 5] == 0.2 and P6[2, 2] == 0.0
    np.testing.assert_array_equal(covariance_from_6x6(values), P)


def lds01_message(**fields) -> LaserScan:
    """An LDS-01 scan: 360 beams of 1 deg from 0 to 2 pi, returns in [0.12, 3.5] m."""
    msg = LaserScan(angle_min=0.0, angle_max=2.0 * math.pi, angle_increment=2.0 * math.pi / 360)
    msg.range_min, msg.range_max = 0.12, 3.5
    msg.ranges = [1.0] * 360
    for name, value in fields.items():
        setattr(msg, name, value)
    return msg


def test_range_scan_from_message_keeps_the_layout_and_the_ranges():
    ranges = np.linspace(0.1, 4.0, 360)
    scan = range_scan_from_message(lds01_message(ranges=ranges.tolist(), intensities=[5.0] * 360))
    np.testing.assert_array_equal(scan.ranges, ranges.astype(np.float32))
    assert (scan.angle_min, scan.range_min, scan.range_max) == (0.0, pytest.approx(0.12), 3.5)
    assert scan.angle_increment == pytest.approx(2.0 * math.pi / 360, rel=1e-7)


@pytest.mark.parametrize(
    ("fields", "message"),
    [
        ({"angle_increment": -2.0 * math.pi / 360}, "contradicts itself"),
        ({"ranges": [1.0] * 720}, "contradicts itself"),
        ({"intensities": [1.0] * 180}, "180 intensities for 360 ranges"),
        ({"range_min": 3.5}, "need range_min < range_max"),
    ],
)
def test_range_scan_from_message_refuses_a_layout_that_contradicts_itself(fields, message):
    with pytest.raises(ValueError, match=message):
        range_scan_from_message(lds01_message(**fields))
