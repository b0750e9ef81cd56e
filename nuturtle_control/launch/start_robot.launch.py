"""Drive the Burger (for a full ROS 2 install): turtle_control + odometry and a command source.

Arguments
    use_sim_time:=false|true      true when the robot is simulated (every node on nusim's /clock).
    cmd_src:=circle|teleop|none   circle (default): the `circle` node publishes cmd_vel (config/circle.yaml);
                                  teleop: teleop_twist_keyboard in its own terminal (xterm); none: nothing
                                  (another node or `ros2 topic pub` drives).

The simulator is not started here (this package installs on the robot without it): the simulated system
is `ros2 launch nuturtle_demo nusim_slam.launch.py`. Every node gets the Burger's constants from
nuturtle_description/config/diff_params.yaml and its own defaults from this package's config/<node>.yaml.
"""

import os

from ament_index_python.packages import get_package_share_directory
from launch import LaunchDescription
from launch.actions import DeclareLaunchArgument, OpaqueFunction
from launch.substitutions import LaunchConfiguration
from launch_ros.actions import Node


def _share(package, *parts):
    return os.path.join(get_package_share_directory(package), *parts)


def _nodes(context):
    cmd_src = LaunchConfiguration("cmd_src").perform(context)
    clock = {"use_sim_time": LaunchConfiguration("use_sim_time").perform(context) == "true"}
    diff_params = _share("nuturtle_description", "config", "diff_params.yaml")
    nodes = [
        Node(
            package="nuturtle_control",
            executable="turtle_control",
            parameters=[diff_params, _share("nuturtle_control", "config", "turtle_control.yaml"), clock],
            output="screen",
        ),
        Node(
            package="nuturtle_control",
            executable="odometry",
            parameters=[diff_params, _share("nuturtle_control", "config", "odometry.yaml"), clock],
            output="screen",
        ),
    ]
    if cmd_src == "circle":
        nodes.append(
            Node(
                package="nuturtle_control",
                executable="circle",
                parameters=[_share("nuturtle_control", "config", "circle.yaml"), clock],
                output="screen",
            )
        )
    elif cmd_src == "teleop":
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
                "use_sim_time",
                default_value="false",
                choices=["true", "false"],
                description="true: run on /clock (simulated robot)",
            ),
            DeclareLaunchArgument(
                "cmd_src",
                default_value="circle",
                choices=["circle", "teleop", "none"],
                description="what publishes cmd_vel",
            ),
            OpaqueFunction(function=_nodes),
        ]
    )
