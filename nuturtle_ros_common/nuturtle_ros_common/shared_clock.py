"""One ``/clock`` subscription for all the nodes of one process.

rclpy gives every node its own ``TimeSource``: with ``use_sim_time`` each one subscribes ``/clock`` and
sets its node's clock from every message, so N nodes in one process take each ``/clock`` message N times
(N deliveries, N Python callbacks) for the same time. On a 100 Hz ``/clock`` that is ~0.03 CPU-s per
second per subscription (docs/benchmarks.md, "Robot-side nodes"). :func:`share_clock` gives the nodes one
``TimeSource`` (rclpy's public class) on the first node and removes their own ``/clock`` subscriptions:
every node's clock then follows the one subscription, exactly as its own would have.
"""

from __future__ import annotations

from collections.abc import Sequence

from rclpy.node import Node
from rclpy.time_source import CLOCK_TOPIC, USE_SIM_TIME_NAME, TimeSource


def share_clock(nodes: Sequence[Node]) -> TimeSource:
    """Drive the clocks of ``nodes`` (one context, at least one) from one ``/clock`` subscription, held by
    the returned ``TimeSource`` on ``nodes[0]`` (it follows that node's ``use_sim_time``). ValueError when
    the nodes disagree on ``use_sim_time``: one process runs on one clock."""
    if not nodes:
        raise ValueError("share_clock needs at least one node")
    sim_time = {node.get_name(): node.get_parameter(USE_SIM_TIME_NAME).value for node in nodes}
    if len(set(sim_time.values())) != 1:
        raise ValueError(f"the nodes of one process must agree on {USE_SIM_TIME_NAME}: {sim_time}")
    time_source = TimeSource(node=nodes[0])
    clock_topic = nodes[0].resolve_topic_name(CLOCK_TOPIC)
    for node in nodes:
        for subscription in [s for s in node.subscriptions if s.topic_name == clock_topic]:
            if subscription.callback != time_source.clock_callback:
                node.destroy_subscription(subscription)
        time_source.attach_clock(node.get_clock())
    return time_source
