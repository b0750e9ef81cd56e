"""EKF SLAM (for a full ROS 2 install): nuturtle_control's start_robot.launch.py plus landmarks and slam.

Arguments
    association:=unknown|known    unknown (default): landmarks found in the LiDAR scan by the `landmarks`
                                  node; known: nusim's fake_sensor (simulator only).
    use_sim_time:=false|true      true against the simulator (every node on nusim's /clock).
    cmd_src:=circle|teleop|none   what drives the robot (see start_robot.launch.py).

    ros2 launch nuslam slam.launch.py cmd_src:=teleop        # on the robot (its bringup: joint_states, scan)
    ros2 launch nuturtle_demo nusim_slam.launch.py           # the same against the simulator

Every node reads the Burger's constants from nuturtle_description/config/diff_params.yaml and its own
defaults from config/landmarks.yaml and config/slam.yaml; the launch arguments come last, so they win.
RViz shows the wheel odometry `odom` (blue) and SLAM's pose, path and map in `map` (green).
"""

import os

from ament_index_python.packages import get_package_share_directory
from launch import LaunchDescription
from launch.actions import DeclareLaunchArgument, IncludeLaunchDescription, OpaqueFunction
from launch.launch_description_sources import PythonLaunchDescriptionSource
from launch.substitutions import LaunchConfiguration
from launch_ros.actions import Node


def _share(package, *parts):
    return os.path.join(get_package_share_directory(package), *parts)


def _slam_nodes(context):
    association = LaunchConfiguration("association").perform(context)
    clock = {"use_sim_time": LaunchConfiguration("use_sim_time").perform(context) == "true"}
    diff_params = _share("nuturtle_description", "config", "diff_params.yaml")
    nodes = [
        Node(
            package="nuslam",
            executable="slam",
            parameters=[
                diff_params,
                _share("nuslam", "config", "slam.yaml"),
                {"association": association, **clock},
            ],
            output="screen",
        ),
    ]
    if association == "unknown":
        nodes.append(
            Node(
                package="nuslam",
                executable="landmarks",
                parameters=[_share("nuslam", "config", "landmarks.yaml"), clock],
                output="screen",
            )
        )
    return nodes


def generate_launch_description() -> LaunchDescription:
    return LaunchDescription(
        [
            DeclareLaunchArgument("association", default_value="unknown", choices=["unknown", "known"]),
            DeclareLaunchArgument("use_sim_time", default_value="false", choices=["true", "false"]),
            DeclareLaunchArgument("cmd_src", default_value="circle", choices=["circle", "teleop", "none"]),
            IncludeLaunchDescription(
                PythonLaunchDescriptionSource(_share("nuturtle_control", "launch", "start_robot.launch.py")),
                launch_arguments={
                    "use_sim_time": LaunchConfiguration("use_sim_time"),
                    "cmd_src": LaunchConfiguration("cmd_src"),
                }.items(),
            ),
            OpaqueFunction(function=_slam_nodes),
        ]
    )
