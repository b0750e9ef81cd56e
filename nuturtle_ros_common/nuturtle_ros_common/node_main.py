"""The one `main` every node uses: init, log the effective parameters, spin, stop cleanly; invalid
parameters stop start-up with a message, and no single message can stop a running node.
"""

from __future__ import annotations

import traceback
from collections.abc import Callable, Sequence

import rclpy
from rclpy.executors import Executor, ExternalShutdownException, SingleThreadedExecutor
from rclpy.impl.rcutils_logger import RcutilsLogger
from rclpy.node import Node

from .throttle import WARN_THROTTLE_S


def effective_parameters(node: Node) -> str:
    """``name=value`` of every parameter of ``node``, sorted by name, one line."""
    parameters = node.get_parameters_by_prefix("")
    return ", ".join(f"{name}={parameters[name].value}" for name in sorted(parameters))


def run_guarded(step: Callable[[], object], logger: RcutilsLogger) -> bool:
    """Run ``step()`` (a callback, or a spin step that runs one), surviving what it raises: an exception is
    logged as an error with its traceback (throttled) and False returned; True otherwise. Shutdown and
    Ctrl-C still propagate."""
    try:
        step()
    except (KeyboardInterrupt, ExternalShutdownException):
        raise
    except Exception as error:  # the point: no single message may stop the node
        logger.error(
            f"a callback raised {type(error).__name__}: {error}; the message is dropped and the node goes "
            f"on\n{traceback.format_exc()}",
            throttle_duration_sec=WARN_THROTTLE_S,
        )
        return False
    return True


def spin_once_guarded(executor: Executor, logger: RcutilsLogger, timeout_sec: float | None = None) -> bool:
    """``executor.spin_once(timeout_sec)``, surviving the callback it runs (:func:`run_guarded`: one of
    ours, or rclpy's own, e.g. its time source refusing a /clock with a negative ``sec``). Returns False
    when a callback raised."""
    return run_guarded(lambda: executor.spin_once(timeout_sec=timeout_sec), logger)


def spin_guarded(node: Node) -> None:
    """Spin ``node`` until its context shuts down, as ``rclpy.spin`` does, with every step guarded by
    :func:`spin_once_guarded`."""
    executor = SingleThreadedExecutor(context=node.context)
    executor.add_node(node)
    try:
        while node.context.ok():
            spin_once_guarded(executor, node.get_logger())
    finally:
        executor.shutdown()


def run_node(factory: Callable[[], Node], name: str, args: Sequence[str] | None = None) -> int:
    """Spin the node `factory()` builds until shutdown; returns the process exit code.

    A ValueError (an invalid parameter) or an OSError (something the node cannot have: a port in use)
    while building the node is logged as fatal with its message and gives exit code 1, without a
    traceback. The node's effective parameters are logged at start-up. An
    exception in a callback is logged and the node keeps spinning (:func:`spin_guarded`). Use as
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
        except OSError as error:
            rclpy.logging.get_logger(name).fatal(f"cannot start: {error}")
            return 1
        node.get_logger().info(f"parameters: {effective_parameters(node)}")
        spin_guarded(node)
    except (KeyboardInterrupt, ExternalShutdownException):
        pass
    finally:
        if node is not None:
            node.destroy_node()
        rclpy.try_shutdown()
    return 0
