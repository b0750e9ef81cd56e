"""`robot_side`: the robot-side nodes in one process: `turtle_control`, `odometry`, `slam` and, with slam's
`association: unknown`, `landmarks`, in one executor with one `/clock` subscription (the way ROS 2's
component containers run C++ nodes), instead of one process each: `ros2 launch nuslam slam.launch.py
one_process:=true`. (`slam_side` is the same without turtle_control and odometry, for a stock TurtleBot3.)

Each node is the same node as its own executable: the same names, topics, parameters and services;
parameters reach each node as they would in its own process (a parameter file's `<node name>:` section
goes to that node, `/**` to all; a `-p` on the command line goes to every node that declares it). It saves
a process's memory per node and the per-process cost of every `/clock` message (docs/robot.md, "CPU and
memory"); the nodes share one thread, so one callback waits for another to end (a `cmd_vel` for
turtle_control while slam processes a scan).

Parameters
    each node's own: `ros2 run nuturtle_control turtle_control --help`, `... odometry --help`,
    `ros2 run nuslam slam --help` and `ros2 run nuslam landmarks --help` list them; every node must
    agree on `use_sim_time` (one process, one clock), else it stops at start-up with the reason.
"""

from __future__ import annotations

import sys

from rclpy.node import Node

from nuslam.slam_side import one_process
from nuturtle_control.odometry import OdometryNode
from nuturtle_control.turtle_control import TurtleControlNode
from nuturtle_ros_common.node_main import run_nodes


def robot_side_nodes() -> list[Node]:
    """turtle_control, odometry, slam and (association unknown) landmarks, on turtle_control's clock."""
    return one_process([TurtleControlNode, OdometryNode])


def main(args: list[str] | None = None) -> None:
    sys.exit(run_nodes(robot_side_nodes, "robot_side", __doc__, args))


if __name__ == "__main__":
    main()
