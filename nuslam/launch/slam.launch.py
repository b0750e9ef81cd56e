"""EKF SLAM (for a full ROS 2 install): nuturtle_control's start_robot.launch.py plus landmarks and slam.

Arguments
    robot:=nusim|localhost        nusim (default): the simulator and every node on its /clock; localhost:
                                  on the real robot (its bringup publishes joint_states and scan).
    association:=unknown|known    unknown (default): landmarks found in the LiDAR scan by the `landmarks`
                                  node; known: nusim's fake_sensor (simulator only).
    cmd_src:=circle|teleop        what drives the robot (see start_robot.launch.py).

    ros2 launch nuslam slam.launch.py                       # SLAM against nusim, unknown association
    ros2 launch nuslam slam.launch.py association:=known    # SLAM against nusim, known association
    ros2 launch nuslam slam.launch.py robot:=localhost cmd_src:=teleop   # on the robot

Every node reads the Burger's constants from nuturtle_description/config/diff_params.yaml and its own
defaults from config/landmarks.yaml and config/slam.yaml. RViz shows nusim's ground truth in
`nusim/world` (red), the wheel odometry `odom` (blue) and SLAM's pose, path and map in `map` (green).
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
    robot = LaunchConfiguration("robot").perform(context)
    association = LaunchConfiguration("association").perform(context)
    if association == "known" and robot != "nusim":
        raise RuntimeError("association:=known needs nusim's fake_sensor: use robot:=nusim")
    clock = {"use_sim_time": robot == "nusim"}
    diff_params = _share("nuturtle_description", "config", "diff_params.yaml")
    return [
        Node(
            package="nuslam",
            executable="landmarks",
            parameters=[_share("nuslam", "config", "landmarks.yaml"), clock],
            output="screen",
        ),
        Node(
            package="nuslam",
            executable="slam",
            parameters=[diff_params, _share("nuslam", "config", "slam.yaml"), {"association": association}, clock],
            output="screen",
        ),
    ]


def generate_launch_description() -> LaunchDescription:
    return LaunchDescription(
        [
            DeclareLaunchArgument("robot", default_value="nusim", choices=["nusim", "localhost"]),
            DeclareLaunchArgument("association", default_value="unknown", choices=["unknown", "known"]),
            DeclareLaunchArgument("cmd_src", default_value="circle", choices=["circle", "teleop"]),
            IncludeLaunchDescription(
                PythonLaunchDescriptionSource(_share("nuturtle_control", "launch", "start_robot.launch.py")),
                launch_arguments={
                    "robot": LaunchConfiguration("robot"),
                    "cmd_src": LaunchConfiguration("cmd_src"),
                }.items(),
            ),
            OpaqueFunction(function=_slam_nodes),
        ]
    )
