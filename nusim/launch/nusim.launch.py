"""Start the simulator (for a full ROS 2 install): nusim in the default world, optionally RViz.

Arguments
    model:=burger|waffle|waffle_pi   the simulated robot (default: $TURTLEBOT3_MODEL, else burger)
    world:=<path>            the world (default: this package's config/basic_world.yaml)
    rviz:=true|false         RViz with fixed frame nusim/world, on nusim's /clock (default false)
    namespace:=<ns>          nusim under the namespace <ns> (e.g. tb3_0: /tb3_0/scan, /tb3_0/nusim/...)
                             with the frame prefix <ns>/ (tb3_0/base_footprint); default empty: as
                             before. /clock and /tf stay global.

nusim gets the world, then `model`, whose constants (nuturtle_description/config/models.yaml) are its
robot's defaults, and `frame_prefix`.
"""

import os

from ament_index_python.packages import get_package_share_directory
from launch import LaunchDescription
from launch.actions import DeclareLaunchArgument
from launch.conditions import IfCondition
from launch.substitutions import LaunchConfiguration, PythonExpression
from launch_ros.actions import Node
from launch_ros.parameter_descriptions import ParameterValue

from nuturtle_description.launch_arguments import model_argument, switch_argument


def _share(package, *parts):
    return os.path.join(get_package_share_directory(package), *parts)


def generate_launch_description() -> LaunchDescription:
    basic_world = _share("nusim", "config", "basic_world.yaml")
    namespace = LaunchConfiguration("namespace")
    # "<ns>/" under a namespace, "" without one (a string as it is: an empty one is not read as YAML's null)
    frame_prefix = ParameterValue(
        PythonExpression(["'", namespace, "/' if '", namespace, "' else ''"]), value_type=str
    )
    return LaunchDescription(
        [
            model_argument(),
            DeclareLaunchArgument(
                "world", default_value=basic_world, description="nusim's parameter file (the world)"
            ),
            switch_argument("rviz", False, "true: also RViz2 in nusim/world"),
            DeclareLaunchArgument(
                "namespace", default_value="", description="nusim's namespace (its frame prefix <ns>/)"
            ),
            Node(
                package="nusim",
                executable="nusim",
                namespace=namespace,
                parameters=[
                    LaunchConfiguration("world"),
                    {"model": LaunchConfiguration("model"), "frame_prefix": frame_prefix},
                ],
                output="screen",
            ),
            Node(
                package="rviz2",
                executable="rviz2",
                arguments=["-f", "nusim/world"],
                parameters=[{"use_sim_time": True}],
                condition=IfCondition(LaunchConfiguration("rviz")),
            ),
        ]
    )
