"""Messages the node tests send, built by hand (never with the modules under test): stamps, landmark
marker arrays, LDS-01 scans, and input matching (the /rosout recording and endpoint matching are
rclpy_harness's). Imported as a top-level helper (see conftest.py) by the node, reliability and fuzz tests.
"""

from __future__ import annotations

import array
from collections.abc import Iterable

import numpy as np
from builtin_interfaces.msg import Time
from rclpy.node import Node
from sensor_msgs.msg import LaserScan
from visualization_msgs.msg import Marker, MarkerArray

from turtlelib import LidarConfig, Transform2D

NS_PER_S = 1_000_000_000
INT32_MIN, INT32_MAX = -(2**31), 2**31 - 1
LDS01 = LidarConfig()  # 360 beams of 1 deg, 0.12 - 3.5 m


def stamp(t_ns: int) -> Time:
    """The stamp of an integer time in nanoseconds (exact, also for epoch-sized times; saturated at the
    ends of Time's range, for hostile stamps)."""
    sec, nanosec = divmod(int(t_ns), NS_PER_S)
    if sec > INT32_MAX:
        return Time(sec=INT32_MAX, nanosec=NS_PER_S - 1)
    if sec < INT32_MIN:
        return Time(sec=INT32_MIN, nanosec=0)
    return Time(sec=sec, nanosec=nanosec)


def stamp_ns(time: Time) -> int:
    return time.sec * NS_PER_S + time.nanosec


def cylinder_array(
    frame_id: str, t_ns: int, points: Iterable[tuple[int, float, float]], header_stamp: Time | None = None
) -> MarkerArray:
    """A landmark MarkerArray as nusim / the landmarks node send it: a DELETEALL, then one CYLINDER (ADD)
    per ``(id, x, y)``, all in ``frame_id`` stamped ``t_ns`` (or ``header_stamp``, e.g. an invalid one)."""
    header_stamp = stamp(t_ns) if header_stamp is None else header_stamp
    delete_all = Marker(action=Marker.DELETEALL)
    delete_all.header.frame_id = frame_id
    delete_all.header.stamp = header_stamp
    markers = [delete_all]
    for marker_id, x, y in points:
        markers.append(cylinder_marker(frame_id, header_stamp, int(marker_id), float(x), float(y)))
    return MarkerArray(markers=markers)


def cylinder_marker(frame_id: str, header_stamp: Time, marker_id: int, x: float, y: float) -> Marker:
    """One landmark CYLINDER (ADD) of an array, centre ``(x, y)`` (m) in ``frame_id``, radius 3.8 cm."""
    marker = Marker(ns="landmarks", id=marker_id, type=Marker.CYLINDER, action=Marker.ADD)
    marker.header.frame_id = frame_id
    marker.header.stamp = header_stamp
    marker.pose.position.x, marker.pose.position.y, marker.pose.position.z = x, y, 0.125
    marker.pose.orientation.w = 1.0
    marker.scale.x = marker.scale.y = 0.076
    marker.scale.z = 0.25
    marker.color.g = marker.color.a = 1.0
    return marker


def relative(
    T_world_frame: Transform2D, landmarks: dict[int, tuple[float, float]]
) -> list[tuple[int, float, float]]:
    """``(id, x, y)`` of the landmarks in a frame at ``T_world_frame``: ``T_frame_world @ p_world``."""
    ids = list(landmarks)
    xy = T_world_frame.inverse() @ np.array([landmarks[i] for i in ids])
    return [(i, float(x), float(y)) for i, (x, y) in zip(ids, xy, strict=True)]


def float32_array(values) -> array.array:
    """``array('f')`` of any floats (a float beyond float32 becomes +-inf, as it would on the wire)."""
    with np.errstate(over="ignore"):
        return array.array("f", np.asarray(values, dtype=np.float64).astype(np.float32).tobytes())


def scan_message(t_ns: int, ranges, frame_id: str = "base_scan", **layout) -> LaserScan:
    """An LDS-01 LaserScan of ``ranges``; ``layout`` overrides angle_min, angle_increment, range_min, ..."""
    msg = LaserScan()
    msg.header.stamp = stamp(t_ns)
    msg.header.frame_id = frame_id
    msg.angle_min = LDS01.angle_min
    msg.angle_max = LDS01.angle_min + (LDS01.samples - 1) * LDS01.angle_increment
    msg.angle_increment = LDS01.angle_increment
    msg.time_increment = 0.2 / 360
    msg.scan_time = 0.2
    msg.range_min = LDS01.range_min
    msg.range_max = LDS01.range_max
    for name, value in layout.items():
        setattr(msg, name, value)
    msg.ranges = float32_array(ranges)
    return msg


def node_inputs_matched(node: Node) -> bool:
    """True once every subscription of ``node`` (the node under test) has matched a publisher: the
    reader side has discovered the test's writers too, so no first message is lost."""
    return all(
        subscription.get_publisher_count() > 0
        for subscription in node.subscriptions
        if subscription.topic_name != "/parameter_events"
    )
