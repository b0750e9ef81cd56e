"""Lockstep: the demo's physics steps and its callbacks in one fixed order, whatever the machine's speed.

One executor cycle per physics step (:func:`run_cycle`): one wait of the executor, then every callback it
found ready, in the executor's order (node by node), with nusim's physics step (nusim built with
``stepped_by_owner``) where its node comes, before nusim's own callbacks (a `wheel_cmd` that was ready
counts from the next step). A message published in a callback is ready at the next cycle: the nodes of one
rclpy context hand each other a message within ``publish`` (Fast DDS delivers it in the publishing
thread), so nothing is in flight when a wait runs. Cycles come no faster than one per ``period_s`` of
wall time (:class:`Pace`: ``1 / (rate * realtime_factor)``).

This is what the demo did when nusim ran on a steady timer and the executor was slower than that timer
(each wait found the timer ready again), but it no longer depends on it: a seed gives the same run on
any machine, under any load and however fast the callbacks are. With the timer, a cycle shorter than the
timer's period (a cheaper callback, a faster executor) let a message hop without a physics step between,
which changed the route the robot drove from run to run.
"""

from __future__ import annotations

import time
from collections.abc import Callable

from rclpy.executors import ShutdownException, SingleThreadedExecutor, TimeoutException
from rclpy.impl.rcutils_logger import RcutilsLogger
from rclpy.node import Node
from rclpy.task import Task

from nuturtle_ros_common.node_main import run_guarded


def _run(handler: Task) -> None:
    """Run one ready callback as ``SingleThreadedExecutor.spin_once`` does, raising what it raised."""
    handler()
    if handler.exception() is not None:
        raise handler.exception()
    handler.result()


def run_cycle(
    executor: SingleThreadedExecutor, stepped_node: Node, step: Callable[[], object], logger: RcutilsLogger
) -> int:
    """One cycle (module docstring): one wait, its ready callbacks, and ``step()`` where ``stepped_node``'s
    turn comes (at the end if none of its callbacks is ready); the number of callbacks run. A callback (or
    the step) that raises is logged and the rest go on (:func:`nuturtle_ros_common.node_main.run_guarded`)."""
    ran = 0
    stepped = False
    try:
        while True:
            # the ready callbacks of one wait, one by one; TimeoutException once they are done
            handler, _, node = executor.wait_for_ready_callbacks(timeout_sec=0.0)
            if node is stepped_node and not stepped:
                run_guarded(step, logger)
                stepped = True
            run_guarded(lambda handler=handler: _run(handler), logger)
            ran += 1
    except TimeoutException:
        pass
    except ShutdownException:
        return ran
    if not stepped:
        run_guarded(step, logger)
    return ran


class Pace:
    """Cycles on a grid of ``period_s`` (> 0) of wall time: :meth:`wait` returns at the next grid point, at
    once when it is past (a cycle late by less than a period is caught up on the next); when more than a
    period behind, the grid starts again from now (a slow stretch is not made up by running faster)."""

    def __init__(self, period_s: float) -> None:
        if not period_s > 0.0:
            raise ValueError(f"period_s must be > 0, got {period_s!r}")
        self.period_s = period_s
        self._next_s = time.monotonic()

    def wait(self) -> None:
        now_s = time.monotonic()
        if now_s < self._next_s:
            time.sleep(self._next_s - now_s)
        elif now_s - self._next_s > self.period_s:
            self._next_s = now_s
        self._next_s += self.period_s
