"""slam's ``map -> odom`` on /tf (REP 105: the localizer publishes ``map -> odom``, the odometry source
``odom -> base_footprint``).

At each pose slam publishes, ``T_map_odom = T_map_body(t) T_odom_body(t)^-1`` with ``T_odom_body(t)`` the
transform the odometry source broadcasts at the same stamp (read from its `odom` topic, interpolated
between its samples by `turtlelib.geometry.pose_buffer.PoseBuffer`), so that composing the two transforms
on /tf gives slam's pose exactly, however late slam started. A pose whose stamp odom does not cover yet
waits for the odom sample that does (the newest one only); after a restart of the odometry source its
frame is another, so the kept samples go. A pose at the stamp of the transform sent last (slam publishes a
pose again when a late scan corrects it) waits for the next stamp: tf2 drops a transform whose stamp it
holds already, with a TF_REPEATED_DATA warning. Nothing is sent where tf2_msgs is not installed.
"""

from __future__ import annotations

from builtin_interfaces.msg import Time
from rclpy.node import Node

from nuturtle_ros_common.conversions import transform_stamped
from nuturtle_ros_common.tf_compat import OptionalTfBroadcaster
from turtlelib import Transform2D
from turtlelib.geometry.pose_buffer import PoseBuffer

# odom samples kept to pair with slam's poses (10 s at the odometry node's 20 Hz)
ODOM_BUFFER_SAMPLES = 200


class MapToOdom:
    """Broadcasts ``map_id -> odom_id`` from slam's poses and the odometry source's (module docstring)."""

    def __init__(self, node: Node, map_id: str, odom_id: str) -> None:
        self._tf = OptionalTfBroadcaster(node)
        self._frames = map_id, odom_id
        self._odom_poses = PoseBuffer(ODOM_BUFFER_SAMPLES)
        # the newest pose not yet paired with odom: (t_ns, T_map_body, stamp)
        self._pending: tuple[int, Transform2D, Time] | None = None
        self._sent_ns: int | None = None

    def odom(self, samples: list[tuple[int, tuple[float, float, float]]], restarted: bool) -> None:
        """The odometry source's plausible samples ``(t_ns, (x, y, theta))`` (``restarted``: its frame is
        another, the kept ones go); sends the waiting transform if they now cover its stamp."""
        if restarted:
            self._odom_poses.clear()
        for t_ns, (x, y, theta) in samples:
            self._odom_poses.add(t_ns, Transform2D(x, y, theta))
        self._send()

    def pose(self, t_ns: int, T_map_body: Transform2D, stamp: Time) -> None:
        """slam's pose at ``t_ns``: its transform is sent once odom covers the stamp."""
        if self._tf.available and t_ns != self._sent_ns:
            self._pending = (t_ns, T_map_body, stamp)
            self._send()

    def _send(self) -> None:
        if self._pending is None:
            return
        t_ns, T_map_body, stamp = self._pending
        T_odom_body = self._odom_poses.at(t_ns)
        if T_odom_body is None:
            return
        # T_map_odom = T_map_body T_odom_body^-1
        self._tf.send(transform_stamped(T_map_body @ T_odom_body.inverse(), *self._frames, stamp))
        self._pending, self._sent_ns = None, t_ns
