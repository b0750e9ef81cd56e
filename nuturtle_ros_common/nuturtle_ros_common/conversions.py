"""Conversions between turtlelib values and standard ROS messages (planar, REP 103 units and frames)."""

from __future__ import annotations

import math
from collections.abc import Mapping

import numpy as np
from builtin_interfaces.msg import Time
from geometry_msgs.msg import Pose, Quaternion, TransformStamped
from nav_msgs.msg import Odometry
from numpy.typing import NDArray
from sensor_msgs.msg import LaserScan

from turtlelib import RangeScan, Transform2D, Twist2D, check_scan_layout
from turtlelib.util.timebase import NS_PER_S
from turtlelib.util.validation import covariance

# A quaternion whose norm differs from 1 by more than this is refused: not a rotation someone meant (a
# zero, a sum of two, a corrupt message); a typed one such as (0, 0, 0.7, 0.7) is within it
QUATERNION_NORM_TOLERANCE = 0.05


def quaternion_from_yaw(yaw_rad: float) -> Quaternion:
    """Rotation about +z by yaw: q = (0, 0, sin(yaw/2), cos(yaw/2))."""
    return Quaternion(x=0.0, y=0.0, z=math.sin(yaw_rad / 2.0), w=math.cos(yaw_rad / 2.0))


def yaw_from_quaternion(q: Quaternion) -> float:
    """Yaw of a unit quaternion (rotation about z of its ZYX Euler decomposition).

    yaw = atan2(2 (w z + x y), w^2 + x^2 - y^2 - z^2): both arguments scale with |q|^2, so a quaternion
    a little off unit norm (rounding, one typed by hand) gives the yaw it means. ValueError for a
    non-finite quaternion or one whose norm is off 1 by more than ``QUATERNION_NORM_TOLERANCE`` (a zero
    quaternion has no yaw at all).
    """
    norm = math.sqrt(q.x * q.x + q.y * q.y + q.z * q.z + q.w * q.w)
    if not abs(norm - 1.0) <= QUATERNION_NORM_TOLERANCE:  # also NaN and inf
        raise ValueError(
            f"quaternion ({q.x}, {q.y}, {q.z}, {q.w}) has norm {norm:.6g}, not 1 "
            f"(within {QUATERNION_NORM_TOLERANCE}): not a rotation"
        )
    return math.atan2(2.0 * (q.w * q.z + q.x * q.y), q.w * q.w + q.x * q.x - q.y * q.y - q.z * q.z)


def pose_from_transform(T: Transform2D) -> Pose:
    pose = Pose()
    pose.position.x = T.x
    pose.position.y = T.y
    pose.orientation = quaternion_from_yaw(T.theta)
    return pose


def transform_from_pose(pose: Pose) -> Transform2D:
    """The planar part of a 3D pose (x, y, yaw); ValueError when non-finite or its quaternion is not a
    rotation (:func:`yaw_from_quaternion`)."""
    return Transform2D(pose.position.x, pose.position.y, yaw_from_quaternion(pose.orientation))


def transform_stamped(T_parent_child: Transform2D, parent: str, child: str, stamp: Time) -> TransformStamped:
    msg = TransformStamped()
    msg.header.stamp = stamp
    msg.header.frame_id = parent
    msg.child_frame_id = child
    msg.transform.translation.x = T_parent_child.x
    msg.transform.translation.y = T_parent_child.y
    msg.transform.rotation = quaternion_from_yaw(T_parent_child.theta)
    return msg


def planar_covariance_6x6(P_xyt: NDArray[np.float64]) -> list[float]:
    """Embed a (3, 3) covariance of (x, y, yaw) into ROS's row-major 6x6 (x, y, z, roll, pitch, yaw)."""
    P6 = np.zeros((6, 6))
    index = [0, 1, 5]
    P6[np.ix_(index, index)] = P_xyt
    return P6.ravel().tolist()


def covariance_from_6x6(values) -> NDArray[np.float64]:
    """The (x, y, yaw) block of a ROS 6x6 covariance."""
    P6 = np.asarray(values, dtype=float).reshape(6, 6)
    index = [0, 1, 5]
    return P6[np.ix_(index, index)]


def positive_definite_pose_covariance(values) -> NDArray[np.float64]:
    """The (x, y, yaw) block of a ROS 6x6 covariance, checked finite, symmetric and positive definite
    (:func:`turtlelib.util.validation.covariance`; ValueError otherwise: a pose estimate must say how
    uncertain it is, and a zero variance would claim certainty)."""
    return covariance("its (x, y, yaw) covariance", covariance_from_6x6(values), (3, 3), definite=True)


def odometry_message(
    T_parent_child: Transform2D,
    V_child: Twist2D,
    parent: str,
    child: str,
    stamp: Time,
    P_xyt: NDArray[np.float64] | None = None,
) -> Odometry:
    """nav_msgs/Odometry: the pose ``T_parent_child`` (in ``parent``), the body twist ``V_child``
    (rad/s, m/s, in ``child``, as REP 105 says) and, when given, the (3, 3) covariance ``P_xyt`` of
    (x, y, yaw) in the 6x6 (the rest zero; no covariance given: all zero, "not estimated")."""
    odom = Odometry(child_frame_id=child)
    odom.header.stamp = stamp
    odom.header.frame_id = parent
    odom.pose.pose = pose_from_transform(T_parent_child)
    if P_xyt is not None:
        odom.pose.covariance = planar_covariance_6x6(P_xyt)
    odom.twist.twist.linear.x = V_child.vx
    odom.twist.twist.linear.y = V_child.vy
    odom.twist.twist.angular.z = V_child.omega
    return odom


def stamp_seconds(stamp: Time) -> float:
    """The stamp in s (float); ValueError for an invalid stamp (:func:`stamp_nanoseconds`)."""
    stamp_nanoseconds(stamp)
    return stamp.sec + stamp.nanosec * 1e-9


def stamp_nanoseconds(stamp: Time) -> int:
    """The stamp as integer ns, exactly. ValueError for a stamp no ROS clock gives: ``sec < 0`` (before
    the epoch, which rclpy's Time refuses too) or ``nanosec >= 1e9`` (not normalised)."""
    if stamp.sec < 0 or stamp.nanosec >= NS_PER_S:
        raise ValueError(
            f"invalid stamp sec = {stamp.sec}, nanosec = {stamp.nanosec} (need sec >= 0, nanosec < 1e9)"
        )
    return stamp.sec * NS_PER_S + stamp.nanosec


def stamp_from_nanoseconds(t_ns: int) -> Time:
    """The stamp of integer ns ``t_ns`` (0 <= nanosec < 1e9), exactly."""
    sec, nanosec = divmod(int(t_ns), NS_PER_S)
    return Time(sec=sec, nanosec=nanosec)


def stamp_from_seconds(seconds: float) -> Time:
    """The stamp nearest to `seconds` (rounded to the nanosecond; 0 <= nanosec < 1e9)."""
    sec = math.floor(seconds)
    # the fraction (exact) in ns; one that rounds up to 1e9 carries into sec
    carry, nanosec = divmod(round((seconds - sec) * 1e9), 1_000_000_000)
    return Time(sec=int(sec + carry), nanosec=int(nanosec))


def range_scan_from_message(msg: LaserScan) -> RangeScan:
    """The scan of a sensor_msgs/LaserScan: ``ranges`` (m) on beams ``angle_min + b angle_increment`` (rad,
    the header's frame), returns in ``[range_min, range_max]``.

    ValueError (with the reason) for a layout that contradicts itself (:func:`turtlelib.check_scan_layout`:
    angle_min, angle_max, angle_increment and the number of ranges disagree), intensities neither empty nor
    one per range, or what :class:`turtlelib.RangeScan` refuses (non-finite angles, ``range_min >=
    range_max``, ...).
    """
    ranges = np.asarray(msg.ranges, dtype=np.float64)  # array.array('f'): through the buffer protocol
    check_scan_layout(len(ranges), msg.angle_min, msg.angle_max, msg.angle_increment)
    if len(msg.intensities) not in (0, len(ranges)):
        raise ValueError(f"{len(msg.intensities)} intensities for {len(ranges)} ranges")
    return RangeScan(ranges, msg.angle_min, msg.angle_increment, msg.range_min, msg.range_max)


def mounted_range_scan(
    msg: LaserScan, T_body_from: Mapping[str, Transform2D]
) -> tuple[int, RangeScan, Transform2D]:
    """``(stamp_ns, scan, T_body_frame)`` of a LaserScan in one of the frames of ``T_body_from`` (frame id ->
    the LiDAR's mount in the body frame); ValueError for another frame or what
    :func:`range_scan_from_message` refuses."""
    T_body_frame = T_body_from.get(msg.header.frame_id)
    if T_body_frame is None:
        raise ValueError(f"it is in frame {msg.header.frame_id!r}, expected one of {sorted(T_body_from)}")
    return stamp_nanoseconds(msg.header.stamp), range_scan_from_message(msg), T_body_frame
