"""Show the Burger (for a full ROS 2 install): robot_state_publisher (+ joint_state_publisher, RViz).

Arguments: color (red|green|blue|purple, also the frame prefix `<color>/`), use_jsp (true|false),
use_rviz (true|false). The URDF is generated from config/diff_params.yaml by nuturtle_description.urdf.
"""

from launch import LaunchDescription
from launch.actions import DeclareLaunchArgument, OpaqueFunction
from launch.conditions import IfCondition
from launch.substitutions import LaunchConfiguration
from launch_ros.actions import Node

from nuturtle_description.robot_params import burger_params
from nuturtle_description.urdf import burger_urdf


def _nodes(context):
    color = LaunchConfiguration("color").perform(context)
    return [
        Node(
            package="robot_state_publisher",
            executable="robot_state_publisher",
            namespace=color,
            parameters=[
                {"robot_description": burger_urdf(burger_params(), color), "frame_prefix": f"{color}/"}
            ],
        ),
        Node(
            package="joint_state_publisher",
            executable="joint_state_publisher",
            namespace=color,
            condition=IfCondition(LaunchConfiguration("use_jsp")),
        ),
        Node(
            package="rviz2",
            executable="rviz2",
            arguments=["-f", f"{color}/base_footprint"],
            condition=IfCondition(LaunchConfiguration("use_rviz")),
        ),
    ]


def generate_launch_description() -> LaunchDescription:
    return LaunchDescription(
        [
            DeclareLaunchArgument(
                "color", default_value="purple", choices=["red", "green", "blue", "purple"]
            ),
            DeclareLaunchArgument("use_jsp", default_value="true"),
            DeclareLaunchArgument("use_rviz", default_value="false"),
            OpaqueFunction(function=_nodes),
        ]
    )
