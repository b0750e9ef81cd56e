"""The one `main` every node uses: init, spin, stop cleanly; invalid parameters stop start-up with a
message.
"""

from __future__ import annotations

from collections.abc import Callable, Sequence

import rclpy
from rclpy.executors import ExternalShutdownException
from rclpy.node import Node


def run_node(factory: Callable[[], Node], name: str, args: Sequence[str] | None = None) -> int:
    """Spin the node `factory()` builds until shutdown; returns the process exit code.

    A ValueError while building the node (an invalid parameter) is logged as fatal with its message and
    gives exit code 1, without a traceback. Use as `sys.exit(run_node(MyNode, "my_node"))`.
    """
    rclpy.init(args=args)
    node = None
    try:
        try:
            node = factory()
        except ValueError as error:
            rclpy.logging.get_logger(name).fatal(f"invalid configuration: {error}")
            return 1
        rclpy.spin(node)
    except (KeyboardInterrupt, ExternalShutdownException):
        pass
    finally:
        if node is not None:
            node.destroy_node()
        rclpy.try_shutdown()
    return 0
