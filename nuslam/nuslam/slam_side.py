"""`slam_side`: `slam` and, with slam's `association: unknown`, `landmarks` in one process, in one executor
with one `/clock` subscription (the way ROS 2's component containers run C++ nodes), instead of one
process each: what a stock TurtleBot3 adds to its own bringup (`ros2 launch nuslam turtlebot3.launch.py
one_process:=true`). `robot_side` runs these with this suite's `turtle_control` and `odometry`.

Each node is the same node as its own executable: the same names, topics, parameters and services;
parameters reach each node as they would in its own process (a parameter file's `<node name>:` section
goes to that node, `/**` to all; a `-p` on the command line goes to every node that declares it). It saves
a process's memory and the per-process cost of every `/clock` message (docs/robot.md, "CPU and memory");
the nodes share one thread, so one callback waits for another to end.

Parameters
    each node's own: `ros2 run nuslam slam --help` and `ros2 run nuslam landmarks --help` list them; the
    nodes must agree on `use_sim_time` (one process, one clock), else it stops at start-up with the reason.
"""

from __future__ import annotations

import sys
from collections.abc import Callable

from rclpy.node import Node

from nuslam.landmarks_node import LandmarksNode
from nuslam.slam_node import SlamNode
from nuturtle_ros_common.node_main import run_nodes
from nuturtle_ros_common.shared_clock import share_clock


def one_process(others: list[Callable[[], Node]]) -> list[Node]:
    """The nodes ``others`` build, then slam and (slam's association unknown) landmarks, on the first
    one's clock; the ones already built are destroyed when one of them cannot be built."""
    nodes: list[Node] = []
    try:
        nodes += [build() for build in others]
        slam = SlamNode()
        nodes.append(slam)
        if slam.node_config.association == "unknown":
            nodes.append(LandmarksNode())
        share_clock(nodes)
    except BaseException:
        for node in nodes:
            node.destroy_node()
        raise
    return nodes


def slam_side_nodes() -> list[Node]:
    """slam and (association unknown) landmarks, on slam's clock."""
    return one_process([])


def main(args: list[str] | None = None) -> None:
    sys.exit(run_nodes(slam_side_nodes, "slam_side", __doc__, args))


if __name__ == "__main__":
    main()
