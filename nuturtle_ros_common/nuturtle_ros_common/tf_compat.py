"""Broadcast /tf where tf2_msgs exists (every real ROS install); carry on without it elsewhere.

tf2_msgs is not on PyPI, so on a wheels-only machine the poses are still on their nav_msgs topics and
this broadcaster says once that /tf is off.
"""

from __future__ import annotations

from geometry_msgs.msg import TransformStamped
from rclpy.node import Node
from rclpy.qos import DurabilityPolicy, QoSProfile


class OptionalTfBroadcaster:
    """`send(transform, ...)` publishes TFMessage on /tf (or /tf_static) when tf2_msgs is importable."""

    def __init__(self, node: Node, static: bool = False) -> None:
        try:
            from tf2_msgs.msg import TFMessage
        except ImportError:
            node.get_logger().info(
                "tf2_msgs is not installed: /tf is not broadcast (poses are on their topics)"
            )
            self._publisher = None
            return
        self._message_type = TFMessage
        if static:
            qos = QoSProfile(depth=1, durability=DurabilityPolicy.TRANSIENT_LOCAL)
            self._publisher = node.create_publisher(TFMessage, "/tf_static", qos)
        else:
            self._publisher = node.create_publisher(TFMessage, "/tf", 100)

    @property
    def available(self) -> bool:
        return self._publisher is not None

    def send(self, *transforms: TransformStamped) -> None:
        if self._publisher is not None:
            self._publisher.publish(self._message_type(transforms=list(transforms)))
