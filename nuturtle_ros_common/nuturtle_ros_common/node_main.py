"""The one `main` every node uses: init, log the effective parameters, spin, stop cleanly; invalid
parameters stop start-up with a message.
"""

from __future__ import annotations

from collections.abc import Callable, Sequence

import rclpy
from rclpy.executors import ExternalShutdownException
from rclpy.node import Node


def effective_parameters(node: Node) -> str:
    """``name=value`` of every parameter of ``node``, sorted by name, one line."""
    parameters = node.get_parameters_by_prefix("")
    return ", ".join(f"{name}={parameters[name].value}" for name in sorted(parameters))


def run_node(factory: Callable[[], Node], name: str, args: Sequence[str] | None = None) -> int:
    """Spin the node `factory()` builds until shutdown; returns the process exit code.

    A ValueError while building the node (an invalid parameter) is logged as fatal with its message and
    gives exit code 1, without a traceback. The node's effective parameters are logged at start-up. Use as
    `sys.exit(run_node(MyNode, "my_node"))`.
    """
    rclpy.init(args=args)
    node = None
    try:
        try:
            node = factory()
        except ValueError as error:
            rclpy.logging.get_logger(name).fatal(f"invalid configuration: {error}")
            return 1
        node.get_logger().info(f"parameters: {effective_parameters(node)}")
        rclpy.spin(node)
    except (KeyboardInterrupt, ExternalShutdownException):
        pass
    finally:
        if node is not None:
            node.destroy_node()
        rclpy.try_shutdown()
    return 0
