"""The simulated system (for a full ROS 2 install): nusim, then control, odometry, landmarks and slam on
its /clock (nuslam's slam.launch.py with use_sim_time:=true).

Arguments
    model:=burger|waffle|waffle_pi  the simulated robot and every node's (default: $TURTLEBOT3_MODEL, else
                                  burger).
    association:=unknown|known    unknown (default): LiDAR landmarks; known: nusim's fake_sensor.
    cmd_src:=none|circle|teleop   what drives the robot (see nuturtle_control's start_robot.launch.py); none
                                  (default): nothing until asked, e.g. `ros2 run nuturtle_control circle
                                  --ros-args -p use_sim_time:=true` once everything is up.
    world:=<path>                 nusim's world (default: nusim/config/basic_world.yaml).
    rviz:=false|true              true: also RViz2 with nuslam's rviz/slam.rviz on the simulator's clock
                                  (passed on to slam.launch.py, which starts it; nusim.launch.py's RViz
                                  stays off: one RViz).
    use_sim_time:=true            always true (declared so that --show-args says so).
    namespace:=<name>             the robot's namespace (default empty: none), e.g. tb3_0: passed on to
                                  nusim.launch.py (nusim under /tb3_0 with its robot's frames prefixed
                                  tb3_0/) and slam.launch.py (every node under /tb3_0, frames tb3_0/odom,
                                  tb3_0/base_footprint, tb3_0/base_scan); the static transform is then
                                  `nusim/world -> tb3_0/map` (or `-> map_frame`).
    map_frame:=<frame>            slam's map frame (see slam.launch.py).

slam.launch.py's motion_source, mode and map_file reach slam as given here.

    ros2 launch nuturtle_demo nusim_slam.launch.py association:=known
    ros2 launch nuturtle_demo nusim_slam.launch.py rviz:=true cmd_src:=circle
    ros2 launch nuturtle_demo nusim_slam.launch.py namespace:=tb3_0 rviz:=true

RViz shows nusim's ground truth in `nusim/world` (red), the wheel odometry `odom` (blue) and SLAM's pose,
path and map in `map` (green); a static `nusim/world -> map` (the world file's start pose, where slam's map
starts) joins the two trees.
"""

import os

from ament_index_python.packages import get_package_share_directory
from launch import LaunchDescription
from launch.actions import DeclareLaunchArgument, IncludeLaunchDescription, OpaqueFunction
from launch.launch_description_sources import PythonLaunchDescriptionSource
from launch.substitutions import LaunchConfiguration
from launch_ros.actions import Node

from nuslam.launch_nodes import ASSOCIATION
from nuturtle_control.launch_nodes import CMD_SRC
from nuturtle_demo.launch_nodes import world_to_map_arguments
from nuturtle_description.launch_arguments import (
    declare_argument,
    in_namespace,
    launched_frames,
    model_argument,
    switch_argument,
)
from nuturtle_ros_common.launch_parameters import MAP_FRAME, NAMESPACE


def _share(package, *parts):
    return os.path.join(get_package_share_directory(package), *parts)


def _world_to_map(context):
    world = LaunchConfiguration("world").perform(context)
    frames = launched_frames(context)
    node = Node(
        package="tf2_ros",
        executable="static_transform_publisher",
        arguments=world_to_map_arguments(world, frames.map_id),
        parameters=[{"use_sim_time": LaunchConfiguration("use_sim_time").perform(context) == "true"}],
        output="screen",
    )
    return in_namespace(frames, [node])


def generate_launch_description() -> LaunchDescription:
    return LaunchDescription(
        [
            model_argument(),
            declare_argument("association", ASSOCIATION),
            # none: the robot stays still until asked, so every node is up (and slam at the true start) first
            declare_argument("cmd_src", CMD_SRC),
            DeclareLaunchArgument(
                "world",
                default_value=_share("nusim", "config", "basic_world.yaml"),
                description="nusim's parameter file (the world)",
            ),
            switch_argument("rviz", False, "true: one RViz2 (slam.rviz) on the simulator's clock"),
            # declared here so that --show-args offers what this file does with it: always true
            DeclareLaunchArgument(
                "use_sim_time",
                default_value="true",
                choices=["true"],
                description="always true: every node runs on nusim's /clock",
            ),
            declare_argument("namespace", NAMESPACE),
            declare_argument("map_frame", MAP_FRAME),
            IncludeLaunchDescription(
                PythonLaunchDescriptionSource(_share("nusim", "launch", "nusim.launch.py")),
                launch_arguments={
                    "world": LaunchConfiguration("world"),
                    "model": LaunchConfiguration("model"),
                    "rviz": "false",  # the one RViz is slam.launch.py's
                    "namespace": LaunchConfiguration("namespace"),
                }.items(),
            ),
            OpaqueFunction(function=_world_to_map),
            IncludeLaunchDescription(
                PythonLaunchDescriptionSource(_share("nuslam", "launch", "slam.launch.py")),
                launch_arguments={
                    "model": LaunchConfiguration("model"),
                    "association": LaunchConfiguration("association"),
                    "cmd_src": LaunchConfiguration("cmd_src"),
                    "rviz": LaunchConfiguration("rviz"),
                    "use_sim_time": LaunchConfiguration("use_sim_time"),
                    "namespace": LaunchConfiguration("namespace"),
                    "map_frame": LaunchConfiguration("map_frame"),
                }.items(),
            ),
        ]
    )
