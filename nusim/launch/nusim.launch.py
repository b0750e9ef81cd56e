"""Start the simulator (for a full ROS 2 install): nusim in the default world, optionally RViz.

Arguments
    config_file:=<path>      the world (default: this package's config/basic_world.yaml)
    use_rviz:=true|false     RViz with fixed frame nusim/world, on nusim's /clock (default false)

nusim gets the Burger's constants from nuturtle_description/config/diff_params.yaml, then the world.
"""

import os

from ament_index_python.packages import get_package_share_directory
from launch import LaunchDescription
from launch.actions import DeclareLaunchArgument
from launch.conditions import IfCondition
from launch.substitutions import LaunchConfiguration
from launch_ros.actions import Node


def _share(package, *parts):
    return os.path.join(get_package_share_directory(package), *parts)


def generate_launch_description() -> LaunchDescription:
    diff_params = _share("nuturtle_description", "config", "diff_params.yaml")
    basic_world = _share("nusim", "config", "basic_world.yaml")
    return LaunchDescription(
        [
            DeclareLaunchArgument(
                "config_file", default_value=basic_world, description="nusim parameter file (the world)"
            ),
            DeclareLaunchArgument(
                "use_rviz", default_value="false", choices=["true", "false"], description="start RViz"
            ),
            Node(
                package="nusim",
                executable="nusim",
                parameters=[diff_params, LaunchConfiguration("config_file")],
                output="screen",
            ),
            Node(
                package="rviz2",
                executable="rviz2",
                arguments=["-f", "nusim/world"],
                parameters=[{"use_sim_time": True}],
                condition=IfCondition(LaunchConfiguration("use_rviz")),
            ),
        ]
    )
