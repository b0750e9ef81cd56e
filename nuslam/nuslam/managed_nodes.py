"""`slam_managed` and `landmarks_managed`: `slam` and `landmarks` as managed (lifecycle) nodes, for a
lifecycle manager (nav2's `lifecycle_manager`, launch_ros's `LifecycleNode`) that brings them up with the
rest of a stack through the standard services `<node>/change_state`, `<node>/get_state`,
`<node>/get_available_transitions` (lifecycle_msgs). `slam` and `landmarks` stay plain nodes; these are
the same nodes (same names, topics, parameters, services, docs: `ros2 run nuslam slam --help`), started
unconfigured (`nuturtle_ros_common.managed_node`):

configure
    reads the parameters and builds the node (slam: its filter, map file, grid, registration), creating
    its topics and services; nothing is published and no input is taken yet. An invalid parameter fails
    the transition with the reason logged, and the node stays unconfigured (change the parameter, then
    configure again).
activate
    publishes and takes its input, as the plain node does.
deactivate
    stops publishing and stops taking input; the state is kept (slam: the estimate, the map, the grid),
    and slam's services (`~/save_map`, `~/reset`) still answer.
activate again
    goes on from the kept state. slam's motion input has been silent since the deactivation, and its
    first samples are judged as those after any silence (`turtlelib.motion.sample_gate`): within
    `max_bridged_gap` (10 s), once `restart_samples` of them agree, the motion made while inactive is
    applied as one step (bridged, with a warning: the wheels' or odometry's net change is measured, only
    its path is not); after a longer pause the motion stream restarts at the first sample with the
    estimate where the deactivation left it, so the robot should stand still while slam is inactive for
    longer (else `initialpose` or `~/reset`).
cleanup
    drops the state (slam: the estimate, map and grid; the map file is read again at the next configure).
shutdown
    from any state: drops the state, the node is finalized and the process exits with code 0.

nav2's bond (a heartbeat topic nav2's own nodes keep after activation) is not offered: manage these nodes
with a lifecycle manager whose `bond_timeout` is 0.0 (docs/robot.md, "Managed nodes").
"""

from __future__ import annotations

import sys
from typing import Any

from nuslam.landmarks_node import LandmarksNode
from nuslam.slam_node import SlamNode
from nuturtle_ros_common.managed_node import ManagedNode
from nuturtle_ros_common.node_main import run_node


class ManagedSlamNode(ManagedNode, SlamNode):
    """`slam` as a managed node: `SlamNode.build` runs at configure (module docstring)."""

    def __init__(self, **kwargs: Any) -> None:
        ManagedNode.__init__(self, "slam", **kwargs)


class ManagedLandmarksNode(ManagedNode, LandmarksNode):
    """`landmarks` as a managed node: `LandmarksNode.build` runs at configure (module docstring)."""

    def __init__(self, **kwargs: Any) -> None:
        ManagedNode.__init__(self, "landmarks", **kwargs)


def slam_main(args: list[str] | None = None) -> None:
    sys.exit(run_node(lambda: ManagedSlamNode(), "slam_managed", __doc__, args))


def landmarks_main(args: list[str] | None = None) -> None:
    sys.exit(run_node(lambda: ManagedLandmarksNode(), "landmarks_managed", __doc__, args))
