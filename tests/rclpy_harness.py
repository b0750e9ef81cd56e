"""Helpers for tests that run real rclpy nodes in process (no mocks), and the /rosout and matching checks
they share.

Each test gets its own rclpy Context and a single-threaded executor; `spin_until` spins it until a
predicate holds or a wall-clock timeout passes. `spin_guarded_until` / `spin_guarded_for` spin as the nodes'
own `run_node` does (`nuturtle_ros_common.node_main.spin_once_guarded`): an exception a callback raises is
logged and counted in `callback_failures` instead of ending the test, so that fuzz tests can count them.
"""

from __future__ import annotations

import gc
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

from nuturtle_ros_common.node_main import spin_once_guarded


class RosHarness:
    """A private rclpy context + executor; nodes added with `add` are spun together."""

    def __init__(self) -> None:
        self.context = Context()
        rclpy.init(context=self.context)
        self.executor = SingleThreadedExecutor(context=self.context)
        self.nodes: list[Node] = []
        # callbacks that raised while spinning with spin_guarded_until / spin_guarded_for
        self.callback_failures = 0
        self._logger = rclpy.logging.get_logger("rclpy_harness")

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

    def spin_guarded_until(self, predicate: Callable[[], bool], timeout_s: float = 10.0) -> bool:
        """`spin_until`, each step through `spin_once_guarded`: a callback's exception is logged and counted
        in `callback_failures`, and the spinning goes on."""
        deadline = time.monotonic() + timeout_s
        while time.monotonic() < deadline:
            if predicate():
                return True
            if not spin_once_guarded(self.executor, self._logger, timeout_sec=0.02):
                self.callback_failures += 1
        return predicate()

    def remove(self, node: Node) -> None:
        """Stop spinning ``node`` and destroy it (a test that builds nodes one after the other)."""
        self.nodes.remove(node)
        self.executor.remove_node(node)
        node.destroy_node()

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


def refused_at_construction(build: Callable[[], Node], message: str) -> str:
    """The ValueError ``build()`` raises (matching ``message``), as text. The half-built node is then
    collected at once: left to a later garbage collection, inside another test, its finalization
    unregisters its logger name from /rosout under that test's node of the same name, whose warnings then
    vanish (a slam test lost its warning that way)."""
    import pytest

    with pytest.raises(ValueError, match=message) as error:
        build()
    text = str(error.value)
    del error
    gc.collect()
    return text


def rcl_parameters(
    context: Context, node_name: str, arguments: list[str], namespace: str = ""
) -> dict[str, Any]:
    """The parameter values rcl gives node ``node_name`` (in ``namespace``) for command-line ``arguments``
    (its own merge of parameter files and ``-p`` values), read from a bare node that declares whatever it
    is given."""
    node = Node(
        node_name,
        namespace=namespace,
        context=context,
        cli_args=arguments,
        automatically_declare_parameters_from_overrides=True,
    )
    try:
        return {name: parameter.value for name, parameter in node.get_parameters_by_prefix("").items()}
    finally:
        node.destroy_node()


def served_parameters(harness: RosHarness, node: Node, names: list[str]) -> dict[str, Any]:
    """The values of ``names`` as ``node`` serves them on its ``~/get_parameters`` service, asked by a
    parameter client in ``harness`` (what ``ros2 param get`` does)."""
    from rclpy.parameter import parameter_value_to_python
    from rclpy.parameter_client import AsyncParameterClient

    client = AsyncParameterClient(
        harness.node(f"parameter_reader_{len(harness.nodes)}"), node.get_fully_qualified_name()
    )
    assert harness.spin_until(client.services_are_ready), "the parameter services did not appear"
    future = client.get_parameters(names)
    assert harness.spin_until(future.done), "get_parameters did not answer"
    values = future.result().values
    return {name: parameter_value_to_python(value) for name, value in zip(names, values, strict=True)}


def rosout_matched(helper: Node) -> bool:
    """True once ``helper``'s /rosout subscriptions (:func:`record_rosout`) have matched every /rosout
    publisher of the graph: under load discovery can take longer than a test's wait for a warning."""
    subscriptions = [s for s in helper.subscriptions if s.topic_name == "/rosout"]
    publishers = helper.count_publishers("/rosout")
    return bool(subscriptions) and all(s.get_publisher_count() >= publishers for s in subscriptions)


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
