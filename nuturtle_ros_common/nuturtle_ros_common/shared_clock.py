"""One ``/clock`` subscription for all the nodes of one process.

rclpy gives every node its own ``TimeSource``: with ``use_sim_time`` each one subscribes ``/clock`` and
sets its node's clock from every message, so N nodes in one process take each ``/clock`` message N times
(N deliveries, N Python callbacks) for the same time. :func:`share_clock` attaches every node's clock to
the first node's ``TimeSource`` and removes the other nodes' ``/clock`` subscriptions: each clock then
follows the one subscription, exactly as its own would have, and since the first node's subscription is
its first one, an executor that spins that node first sets every clock before any other callback of a
step, as each node's own subscription did for it.
"""

from __future__ import annotations

from collections.abc import Sequence

from rclpy.node import Node
from rclpy.time_source import USE_SIM_TIME_NAME, TimeSource


def share_clock(nodes: Sequence[Node]) -> TimeSource:
    """Drive the clocks of ``nodes`` (one context, at least one) from the ``/clock`` subscription of
    ``nodes[0]``'s time source, which is returned. ValueError when the nodes disagree on
    ``use_sim_time``: one process runs on one clock."""
    if not nodes:
        raise ValueError("share_clock needs at least one node")
    sim_time = {node.get_name(): node.get_parameter(USE_SIM_TIME_NAME).value for node in nodes}
    if len(set(sim_time.values())) != 1:
        raise ValueError(f"the nodes of one process must agree on {USE_SIM_TIME_NAME}: {sim_time}")
    # rclpy has no public accessor for a node's own time source (Node.__init__ makes it and attaches the
    # node's clock to it); keeping the first node's keeps its subscription first among the node's
    time_source: TimeSource = nodes[0]._time_source
    for node in nodes[1:]:
        # its own /clock subscription only (a node may subscribe /clock for itself, e.g. a recorder)
        node._time_source.detach_node()
        time_source.attach_clock(node.get_clock())
    return time_source
