"""The one `main` every node uses: ``--help``, init, log the effective parameters, spin, stop cleanly;
invalid parameters stop start-up with a message, and no single message can stop a running node.

Stopping: SIGINT (Ctrl-C), SIGTERM (launch after its ``sigterm_timeout``, ``timeout``, systemd, docker)
and SIGHUP (the terminal closed) each end the node the same way, with exit code 0 and no traceback. A
signal only records the request (:mod:`~nuturtle_ros_common.stop_signals`); the spin loop sees it within
``SPIN_PERIOD_S``, then, in the main thread and with the context still up, a node that commands something
(:class:`SafeStop`) publishes its safe command (zero wheel speeds) and waits up to ``FLUSH_TIMEOUT_S`` for
its subscribers to acknowledge it, and only then are the node and the context shut down. rclpy's own
handlers are not installed: they shut the context down from a second thread while a callback may still be
running (a callback then fails on a dead context), and re-raise SIGINT as a ``KeyboardInterrupt`` wherever
the main thread is (a traceback and exit code -2 when a second SIGINT lands in the shutdown). A second
signal while the node stops is ignored, and every stop signal once it has stopped; a signal whose
disposition is SIG_IGN at start-up (``nohup``, a background job of a script) stays ignored. Exit codes: 0
stopped (a signal, the context shut down, or a managed node's lifecycle shutdown: :func:`all_finalized`),
1 could not start (an invalid parameter, a port in use) or could not stop (below), 2 a bad command line
(argparse's usage error).

Bounded: from the moment a node starts stopping, the process is gone within ``STOP_DEADLINE_S`` (or the
seconds the environment variable ``NUTURTLE_STOP_DEADLINE_S`` gives, for a launch or container whose own
SIGKILL comes at another time; an invalid value stops the process at start-up), before launch or docker
would SIGKILL it. A stop normally takes well under 2 s; past the deadline (a ``stop()`` that
blocks, or the middleware's teardown deadlocking: once seen in CI, turtle_control still there 10 s after its
SIGTERM) :mod:`faulthandler` prints where every thread is and ends the process with exit code 1. Its
watchdog is a C thread: it fires even while the main thread is blocked inside C++ holding the GIL, and it
covers the interpreter's exit too, where rclpy's context and with it the DDS participant are finalized.
``run_node`` is therefore a process's ``main``: nothing may run after it but the exit.

Spinning: rclpy's EventsExecutor (``rclpy.experimental``, C++), not the SingleThreadedExecutor, which
rebuilds and scans a wait set of every subscription, timer, service and QoS event handler for each
callback it runs: fed a recorded demo at real time on sim time, the four robot-side nodes used 0.50
CPU-s per robot second with it and 0.22 with the EventsExecutor (docs/benchmarks.md, "Robot-side
nodes"). A callback's exception still comes out of ``spin_once``, so guarding works the same.

Several nodes in one process (:func:`run_nodes`, e.g. ``nuslam``'s ``robot_side``) share the one
executor, as ROS 2's component containers do in C++.
"""

from __future__ import annotations

import argparse
import faulthandler
import math
import os
import sys
import time
import traceback
from collections.abc import Callable, Sequence
from typing import Protocol, runtime_checkable

import rclpy
from rclpy.duration import Duration
from rclpy.executors import Executor, ExternalShutdownException
from rclpy.experimental import EventsExecutor
from rclpy.impl.implementation_singleton import rclpy_implementation
from rclpy.impl.rcutils_logger import RcutilsLogger
from rclpy.node import Node
from rclpy.signals import SignalHandlerOptions
from rclpy.utilities import remove_ros_args

from .stop_signals import StopSignals, ignore_stop_signals
from .throttle import WARN_THROTTLE_S

# The longest one spin step waits (s): a stop signal is acted on within this time
SPIN_PERIOD_S = 0.1
# The longest a stopping node waits for its last messages to be acknowledged (s)
FLUSH_TIMEOUT_S = 0.5
# From the start of a stop to the process's end at the latest (s): launch SIGKILLs a node 10 s after its
# SIGINT (sigterm_timeout + sigkill_timeout), docker 10 s after its SIGTERM
STOP_DEADLINE_S = 8.0
# The environment variable that sets another deadline (s, finite, > 0)
STOP_DEADLINE_ENV = "NUTURTLE_STOP_DEADLINE_S"
ROS_ARGUMENTS_HELP = """\
ROS arguments come after --ros-args: -p NAME:=VALUE sets a parameter, --params-file FILE loads a YAML
file of them, -r FROM:=TO remaps a name (docs/robot.md, "Parameters", says which value wins).
`ros2 param describe /NODE NAME` describes a parameter of the running node.

Stops on SIGINT (Ctrl-C), SIGTERM or SIGHUP with exit code 0 (docs/robot.md, "Stopping a node");
exit code 1: it could not start (an invalid parameter: the message says which) or its stop took over 8 s
(the stack of every thread is printed), 2: a bad command line.
"""


@runtime_checkable
class SafeStop(Protocol):
    """A node that commands something and has a safe command to leave behind when it stops."""

    def stop(self) -> None:
        """Publish the safe command (e.g. zero wheel speeds) and publish nothing more; called once by
        :func:`run_node`, while the context is still up."""


def all_finalized(nodes: Sequence[Node]) -> bool:
    """True when every node of ``nodes`` has ended its own life: its ``finalized`` property is True (a
    managed node after its lifecycle shutdown; a node without the property never is). Read at every spin,
    so an attribute lookup, not a runtime protocol check."""
    return all(getattr(node, "finalized", False) is True for node in nodes)


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


def spin_guarded(nodes: Sequence[Node], stop: StopSignals) -> None:
    """Spin ``nodes`` (one context) in one EventsExecutor until the context shuts down, ``stop`` has
    received a signal or every node is finalized (:func:`all_finalized`), every step guarded by
    :func:`spin_once_guarded` (logging on the first node's logger) and waiting at most ``SPIN_PERIOD_S``."""
    context = nodes[0].context
    executor = EventsExecutor(context=context)
    for node in nodes:
        executor.add_node(node)
    try:
        while context.ok() and stop.received is None and not all_finalized(nodes):
            spin_once_guarded(executor, nodes[0].get_logger(), timeout_sec=SPIN_PERIOD_S)
    finally:
        executor.shutdown()


def check_command_line(name: str, description: str, args: Sequence[str]) -> None:
    """``-h`` / ``--help``: print ``description`` (the node's module docstring) and how ROS arguments and
    stopping work, and exit 0; an argument that is neither ROS's nor ``--help``, malformed ROS arguments
    or a parameter file rcl cannot open or parse: a usage error, exit 2. Never starts anything."""
    parser = argparse.ArgumentParser(
        prog=name,
        usage="%(prog)s [-h] [--ros-args ...]",
        description=description,
        epilog=ROS_ARGUMENTS_HELP,
        formatter_class=argparse.RawDescriptionHelpFormatter,
    )
    try:
        user_args = remove_ros_args(args=list(args))[1:]
    except rclpy_implementation.RCLError as error:  # malformed ROS arguments, an unreadable params file
        parser.error(str(error))
    parser.parse_args(user_args)


def run_node(
    factory: Callable[[], Node], name: str, description: str, args: Sequence[str] | None = None
) -> int:
    """Spin the node `factory()` builds until a stop signal or shutdown; returns the process exit code
    (module docstring: 0 stopped, 1 could not start; ``--help`` and a bad command line exit here).
    Use as `sys.exit(run_node(MyNode, "my_node", __doc__))`; :func:`run_nodes` for several."""
    return run_nodes(lambda: [factory()], name, description, args)


def run_nodes(
    factory: Callable[[], Sequence[Node]], name: str, description: str, args: Sequence[str] | None = None
) -> int:
    """:func:`run_node` for the nodes `factory()` builds (one process, one executor): the process exit
    code (module docstring: 0 stopped, 1 could not start; ``--help`` and a bad command line exit here).
    The process's ``main``: once the nodes stop, the process must exit within ``STOP_DEADLINE_S``.

    A ValueError (an invalid parameter) or an OSError (something the node cannot have: a port in use)
    while building the node is logged as fatal with its message and gives exit code 1, without a
    traceback; ``factory`` destroys the nodes it built before it raises. Each node's effective
    parameters are logged at start-up. An exception in a callback is logged and the nodes keep spinning
    (:func:`spin_guarded`). Each :class:`SafeStop` node's ``stop()`` runs before the nodes are destroyed.
    """
    check_command_line(name, description, sys.argv if args is None else args)
    try:
        deadline_s = stop_deadline_s()
    except ValueError as error:
        print(f"{name}: {error}", file=sys.stderr)
        return 1
    try:
        with StopSignals(second="ignore") as stop:
            return spin_until_stopped(factory, name, args, stop, deadline_s)
    finally:
        # the node is gone, the process exits: a late signal must not end it with its default action
        ignore_stop_signals()


def stop_deadline_s() -> float:
    """The stop deadline (s): ``NUTURTLE_STOP_DEADLINE_S`` if set (finite, > 0; ValueError otherwise), else
    ``STOP_DEADLINE_S``."""
    text = os.environ.get(STOP_DEADLINE_ENV)
    if text is None:
        return STOP_DEADLINE_S
    try:
        value = float(text)
    except ValueError:
        value = math.nan
    if not (math.isfinite(value) and value > 0.0):
        raise ValueError(f"{STOP_DEADLINE_ENV} must be a number of seconds > 0, got {text!r}")
    return value


def spin_until_stopped(
    factory: Callable[[], Sequence[Node]],
    name: str,
    args: Sequence[str] | None,
    stop: StopSignals,
    deadline_s: float,
) -> int:
    """:func:`run_nodes` once the command line is checked, with ``stop`` handling the stop signals and the
    process gone within ``deadline_s`` of the start of its stop."""
    rclpy.init(args=args, signal_handler_options=SignalHandlerOptions.NO)
    nodes: Sequence[Node] = ()
    try:
        try:
            nodes = factory()
        except ValueError as error:
            rclpy.logging.get_logger(name).fatal(f"invalid configuration: {error}")
            return 1
        except OSError as error:
            rclpy.logging.get_logger(name).fatal(f"cannot start: {error}")
            return 1
        if stop.received is None:
            for node in nodes:
                node.get_logger().info(f"parameters: {effective_parameters(node)}")
            spin_guarded(nodes, stop)
    except ExternalShutdownException:
        pass
    finally:
        # from here on the process only stops, and is gone within the deadline (module docstring)
        faulthandler.dump_traceback_later(deadline_s, exit=True)
        try:
            for node in nodes:
                if stop.received is not None:
                    node.get_logger().info(f"{stop.received}: stopping")
                if isinstance(node, SafeStop) and node.context.ok():
                    node.stop()
                    flush(node, FLUSH_TIMEOUT_S)
        finally:
            for node in nodes:
                node.destroy_node()
            rclpy.try_shutdown()
    return 0


def flush(node: Node, timeout_s: float) -> None:
    """Wait until every reliable subscriber has acknowledged what ``node`` published, at most
    ``timeout_s`` in all (best-effort publishers return at once)."""
    deadline = time.monotonic() + timeout_s
    for publisher in node.publishers:
        remaining_s = max(deadline - time.monotonic(), 0.0)
        publisher.wait_for_all_acked(Duration(nanoseconds=round(remaining_s * 1e9)))
