"""Shared pieces of the nuturtle_control node tests: a /rosout recorder and endpoint matching."""

from __future__ import annotations

from rcl_interfaces.msg import Log
from rclpy.node import Node
from rclpy.publisher import Publisher
from rclpy.qos import DurabilityPolicy, QoSProfile, ReliabilityPolicy
from rclpy.subscription import Subscription


def record_rosout(helper: Node) -> list[Log]:
    """Every /rosout message from now on (transient local: also the ones sent before matching)."""
    logs: list[Log] = []
    qos = QoSProfile(
        depth=1000, reliability=ReliabilityPolicy.RELIABLE, durability=DurabilityPolicy.TRANSIENT_LOCAL
    )
    helper.create_subscription(Log, "/rosout", logs.append, qos)
    return logs


def warnings_of(logs: list[Log], node_name: str) -> list[str]:
    """The texts of the WARN messages logged by `node_name`."""
    return [log.msg for log in logs if log.name == node_name and log.level == Log.WARN]


def matched(*endpoints: Publisher | Subscription) -> bool:
    """True once every publisher has a subscriber and every subscription a publisher."""
    return all(
        (e.get_subscription_count() if isinstance(e, Publisher) else e.get_publisher_count()) > 0
        for e in endpoints
    )
