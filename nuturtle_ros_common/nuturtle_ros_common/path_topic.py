"""A node's ``~/path`` (nav_msgs/Path): its pose trail, decimated and bounded by
:class:`turtlelib.geometry.path_trail.PathTrail`, published whole at most once per ``path_period`` of the
poses' time (the parameters of :class:`~turtlelib.geometry.path_trail.PathTrailConfig`, declared on the
node)."""

from __future__ import annotations

from geometry_msgs.msg import PoseStamped
from nav_msgs.msg import Odometry, Path
from rclpy.node import Node

from turtlelib import Transform2D
from turtlelib.geometry.path_trail import PathTrail, PathTrailConfig

from .conversions import stamp_nanoseconds
from .ros_params import declare_dataclass


class PathTopic:
    """``~/path`` (or ``topic``) of ``node``, in the frame and with the stamp of the odometry it is given;
    ``config``: the trail's parameters when the node has declared them already (several paths of one
    node), else they are declared here."""

    def __init__(self, node: Node, topic: str = "~/path", config: PathTrailConfig | None = None) -> None:
        if config is None:
            config = declare_dataclass(node, PathTrailConfig)
        self.config = config
        self.trail: PathTrail[PoseStamped] = PathTrail(config)
        self._publisher = node.create_publisher(Path, topic, 10)

    def add(self, T_frame_body: Transform2D, odom: Odometry) -> None:
        """Offer the pose ``T_frame_body`` of ``odom`` to the trail; publish the trail when it is due."""
        self.trail.offer(T_frame_body, PoseStamped(header=odom.header, pose=odom.pose.pose))
        if self.trail.publish_due(stamp_nanoseconds(odom.header.stamp)):
            self._publisher.publish(Path(header=odom.header, poses=list(self.trail.items)))

    def clear(self) -> None:
        self.trail.clear()
