"""Shared pieces of the nuslam node tests: stamps, marker arrays, input matching (the /rosout recording and
endpoint matching are rclpy_harness's)."""

from __future__ import annotations

from collections.abc import Iterable

from builtin_interfaces.msg import Time
from rclpy.node import Node
from visualization_msgs.msg import Marker, MarkerArray


def stamp(t_ns: int) -> Time:
    """The stamp of an integer time in nanoseconds (exact, also for epoch-sized times)."""
    return Time(sec=t_ns // 1_000_000_000, nanosec=t_ns % 1_000_000_000)


def stamp_ns(time: Time) -> int:
    return time.sec * 1_000_000_000 + time.nanosec


def cylinder_array(frame_id: str, t_ns: int, points: Iterable[tuple[int, float, float]]) -> MarkerArray:
    """A landmark MarkerArray as nusim / the landmarks node send it: a DELETEALL, then one CYLINDER (ADD)
    per ``(id, x, y)``, all in ``frame_id`` stamped ``t_ns``. Built by hand (not with the markers module
    under test)."""
    header_stamp = stamp(t_ns)
    delete_all = Marker(action=Marker.DELETEALL)
    delete_all.header.frame_id = frame_id
    delete_all.header.stamp = header_stamp
    markers = [delete_all]
    for marker_id, x, y in points:
        marker = Marker(ns="landmarks", id=int(marker_id), type=Marker.CYLINDER, action=Marker.ADD)
        marker.header.frame_id = frame_id
        marker.header.stamp = header_stamp
        marker.pose.position.x, marker.pose.position.y, marker.pose.position.z = float(x), float(y), 0.125
        marker.pose.orientation.w = 1.0
        marker.scale.x = marker.scale.y = 0.076
        marker.scale.z = 0.25
        marker.color.g = marker.color.a = 1.0
        markers.append(marker)
    return MarkerArray(markers=markers)


def node_inputs_matched(node: Node) -> bool:
    """True once every subscription of ``node`` (the node under test) has matched a publisher: the
    reader side has discovered the test's writers too, so no first message is lost."""
    return all(
        subscription.get_publisher_count() > 0
        for subscription in node.subscriptions
        if subscription.topic_name != "/parameter_events"
    )
