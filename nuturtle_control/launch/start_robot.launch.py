"""Drive the Burger (for a full ROS 2 install): turtle_control + odometry, a command source, and nusim.

Arguments
    robot:=nusim|localhost   nusim (default): start the simulator (nusim/config/basic_world.yaml) and run
                             every node on its /clock; localhost: the real robot (its bringup publishes
                             joint_states and takes wheel_cmd), no simulator, wall-clock time.
    cmd_src:=circle|teleop   circle (default): the `circle` node publishes cmd_vel (config/circle.yaml);
                             teleop: teleop_twist_keyboard in its own terminal (xterm).

Every node gets the Burger's constants from nuturtle_description/config/diff_params.yaml and its own
defaults from this package's config/<node>.yaml.
"""

import os

from ament_index_python.packages import get_package_share_directory
from launch import LaunchDescription
from launch.actions import DeclareLaunchArgument, OpaqueFunction
from launch.substitutions import LaunchConfiguration
from launch_ros.actions import Node


def _config(package, name):
    return os.path.join(get_package_share_directory(package), "config", name)


def _nodes(context):
    robot = LaunchConfiguration("robot").perform(context)
    cmd_src = LaunchConfiguration("cmd_src").perform(context)
    simulated = robot == "nusim"
    diff_params = _config("nuturtle_description", "diff_params.yaml")
    clock = {"use_sim_time": simulated}
    nodes = [
        Node(
            package="nuturtle_control",
            executable="turtle_control",
            parameters=[diff_params, _config("nuturtle_control", "turtle_control.yaml"), clock],
            output="screen",
        ),
        Node(
            package="nuturtle_control",
            executable="odometry",
            parameters=[diff_params, _config("nuturtle_control", "odometry.yaml"), clock],
            output="screen",
        ),
    ]
    if simulated:
        nodes.append(
            Node(
                package="nusim",
                executable="nusim",
                parameters=[diff_params, _config("nusim", "basic_world.yaml")],
                output="screen",
            )
        )
    if cmd_src == "circle":
        nodes.append(
            Node(
                package="nuturtle_control",
                executable="circle",
                parameters=[_config("nuturtle_control", "circle.yaml"), clock],
                output="screen",
            )
        )
    else:
        nodes.append(
            Node(
                package="teleop_twist_keyboard",
                executable="teleop_twist_keyboard",
                prefix="xterm -e",
                parameters=[clock],
                output="screen",
            )
        )
    return nodes


def generate_launch_description() -> LaunchDescription:
    return LaunchDescription(
        [
            DeclareLaunchArgument(
                "robot",
                default_value="nusim",
                choices=["nusim", "localhost"],
                description="nusim: simulated robot; localhost: the real robot this runs on",
            ),
            DeclareLaunchArgument(
                "cmd_src",
                default_value="circle",
                choices=["circle", "teleop"],
                description="what publishes cmd_vel",
            ),
            OpaqueFunction(function=_nodes),
        ]
    )
