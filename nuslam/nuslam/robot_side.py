"""`robot_side`: the robot-side nodes in one process: `turtle_control`, `odometry`, `slam` and, with slam's
`association: unknown`, `landmarks`, in one executor with one `/clock` subscription (the way ROS 2's
component containers run C++ nodes), instead of one process each.

Each node is the same node as its own executable: the same names, topics, parameters and services;
parameters reach each node as they would in its own process (a parameter file's `<node name>:` section
goes to that node, `/**` to all; a `-p` on the command line goes to every node that declares it). `ros2
launch nuslam slam.launch.py one_process:=true` starts this instead of the four processes. It saves about
a process's worth of memory per node and the per-process cost of every `/clock` message
(docs/benchmarks.md, "Robot-side nodes"); one slow callback now delays the others (they share one thread).

Parameters
    each node's own: `ros2 run nuturtle_control turtle_control --help`, `... odometry --help`,
    `ros2 run nuslam slam --help` and `ros2 run nuslam landmarks --help` list them; every node must
    agree on `use_sim_time` (one process, one clock), else it stops at start-up with the reason.
"""

from __future__ import annotations

import sys

from rclpy.node import Node

from nuslam.landmarks_node import LandmarksNode
from nuslam.slam_node import SlamNode
from nuturtle_control.odometry import OdometryNode
from nuturtle_control.turtle_control import TurtleControlNode
from nuturtle_ros_common.node_main import run_nodes
from nuturtle_ros_common.shared_clock import share_clock


def robot_side_nodes() -> list[Node]:
    """turtle_control, odometry, slam and (slam's association unknown) landmarks, on one shared clock; the
    ones already built are destroyed when one of them cannot be built."""
    nodes: list[Node] = []
    try:
        nodes += [TurtleControlNode(), OdometryNode()]
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


def main(args: list[str] | None = None) -> None:
    sys.exit(run_nodes(robot_side_nodes, "robot_side", __doc__, args))


if __name__ == "__main__":
    main()
