"""Helpers for tests that run real rclpy nodes in process (no mocks), and the /rosout and matching checks
they share.

Each test gets its own rclpy Context and a single-threaded executor; `spin_until` spins it until a
predicate holds or a wall-clock timeout passes.
"""

from __future__ import annotations

import time
from collections.abc import Callable
from typing import Any

import rclpy
from rcl_interfaces.msg import Log
from rclpy.context import Context
from rclpy.executors import SingleThreadedExecutor
from rclpy.node import Node
from rclpy.publisher import Publisher
from rclpy.qos import DurabilityPolicy, QoSProfile, ReliabilityPolicy
from rclpy.subscription import Subscription


class RosHarness:
    """A private rclpy context + executor; nodes added with `add` are spun together."""

    def __init__(self) -> None:
        self.context = Context()
        rclpy.init(context=self.context)
        self.executor = SingleThreadedExecutor(context=self.context)
        self.nodes: list[Node] = []

    def add(self, node: Node) -> Node:
        self.nodes.append(node)
        self.executor.add_node(node)
        return node

    def node(self, name: str, **kwargs: Any) -> Node:
        """A plain helper node (publishers/subscribers for the test) in this context."""
        return self.add(Node(name, context=self.context, **kwargs))

    def spin_until(self, predicate: Callable[[], bool], timeout_s: float = 10.0) -> bool:
        deadline = time.monotonic() + timeout_s
        while time.monotonic() < deadline:
            if predicate():
                return True
            self.executor.spin_once(timeout_sec=0.02)
        return predicate()

    def spin_for(self, duration_s: float) -> None:
        deadline = time.monotonic() + duration_s
        while time.monotonic() < deadline:
            self.executor.spin_once(timeout_sec=0.02)

    def shutdown(self) -> None:
        for node in self.nodes:
            self.executor.remove_node(node)
            node.destroy_node()
        self.executor.shutdown()
        rclpy.try_shutdown(context=self.context)


def record_rosout(helper: Node) -> list[Log]:
    """Every /rosout message from now on (transient local: also the ones sent before matching)."""
    logs: list[Log] = []
    qos = QoSProfile(
        depth=1000, reliability=ReliabilityPolicy.RELIABLE, durability=DurabilityPolicy.TRANSIENT_LOCAL
    )
    helper.create_subscription(Log, "/rosout", logs.append, qos)
    return logs


def warnings_of(logs: list[Log], logger_name: str) -> list[str]:
    """The texts of the WARN messages of ``logger_name`` and its child loggers (``slam.fake_sensor``)."""
    return [
        log.msg
        for log in logs
        if (log.name == logger_name or log.name.startswith(logger_name + ".")) and log.level == Log.WARN
    ]


def matched(*endpoints: Publisher | Subscription) -> bool:
    """True once every publisher has a subscriber and every subscription a publisher."""
    return all(
        (e.get_subscription_count() if isinstance(e, Publisher) else e.get_publisher_count()) > 0
        for e in endpoints
    )
