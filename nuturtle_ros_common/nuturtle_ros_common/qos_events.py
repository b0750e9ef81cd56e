"""Nodes without rclpy's default QoS event handlers, for a process whose endpoints are all its own.

rclpy gives every publisher and subscription default event handlers (incompatible QoS, incompatible
message type: each logs a warning when a peer does not match), and rclpy's SingleThreadedExecutor adds
every handler to its wait set and asks it whether it is ready on each wait. In the demo (seven nodes in
one process, about 250 waitable entities, 140 of them these handlers) that was a third of its CPU:
0.49 -> 0.31 CPU-s per robot second without them, the runs unchanged (docs/benchmarks.md, "Demo CPU").

:func:`drop_qos_event_handlers` removes them where every endpoint's QoS is fixed by the code and tested
together (the demo, the replay). The robot-side nodes keep theirs: spun by the EventsExecutor
(``node_main``) they cost nothing per message, and they warn of a user's subscriber that cannot match.
"""

from __future__ import annotations

from rclpy.node import Node


def drop_qos_event_handlers(node: Node) -> int:
    """Destroy the QoS event handlers of every publisher and subscription ``node`` has now (endpoints
    created later keep theirs); the number destroyed. Messages flow as before."""
    destroyed = 0
    for endpoint in [*node.publishers, *node.subscriptions]:
        for handler in endpoint.event_handlers:
            node.remove_waitable(handler)
            handler.destroy()
            destroyed += 1
        # the endpoint's own destroy() and the node's destroy_* walk this list
        endpoint.event_handlers.clear()
    return destroyed
