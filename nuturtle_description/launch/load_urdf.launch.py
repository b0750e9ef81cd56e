"""Show a TurtleBot3 (for a full ROS 2 install): robot_state_publisher (+ joint_state_publisher, RViz).

Arguments: model (burger|waffle|waffle_pi; default $TURTLEBOT3_MODEL, else burger), color
(red|green|blue|purple, also the frame prefix `<color>/`), use_jsp (true|false), use_rviz (true|false). The
URDF is generated from the model's constants in config/models.yaml by nuturtle_description.urdf.
"""

from launch import LaunchDescription
from launch.actions import DeclareLaunchArgument, OpaqueFunction
from launch.conditions import IfCondition
from launch.substitutions import LaunchConfiguration
from launch_ros.actions import Node

from nuturtle_description.launch_arguments import model_argument, switch_argument
from nuturtle_description.robot_params import model_params
from nuturtle_description.urdf import robot_urdf


def _nodes(context):
    color = LaunchConfiguration("color").perform(context)
    model = LaunchConfiguration("model").perform(context)
    return [
        Node(
            package="robot_state_publisher",
            executable="robot_state_publisher",
            namespace=color,
            parameters=[
                {
                    "robot_description": robot_urdf(model, model_params(model), color),
                    "frame_prefix": f"{color}/",
                }
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
            model_argument(),
            DeclareLaunchArgument(
                "color",
                default_value="purple",
                choices=["red", "green", "blue", "purple"],
                description="the robot's colour, also its frame prefix <color>/",
            ),
            switch_argument("use_jsp", True, "true: joint_state_publisher publishes the wheel joints"),
            switch_argument("use_rviz", False, "true: also RViz2 showing the model"),
            OpaqueFunction(function=_nodes),
        ]
    )
