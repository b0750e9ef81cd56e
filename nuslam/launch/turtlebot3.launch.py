"""EKF SLAM on a stock TurtleBot3 Burger (for a full ROS 2 install): landmarks and slam only.

The robot's own bringup (`ros2 launch turtlebot3_bringup robot.launch.py` on the robot) already runs
`turtlebot3_node`, which publishes `joint_states`, `odom` and the `odom -> base_footprint` transform and
takes `cmd_vel`, and `robot_state_publisher` (`base_footprint -> base_scan`), and the LDS driver (`scan`).
So nothing here drives the robot or duplicates its odometry: slam reads `joint_states` and the LiDAR
landmarks and broadcasts `map -> odom` against the robot's own `odom` (see docs/robot.md).

Arguments
    association:=unknown          the LiDAR landmarks (the only choice on a real robot: no fake sensor)

    ros2 launch nuslam turtlebot3.launch.py      # on the laptop, same ROS_DOMAIN_ID as the robot

Every node reads the Burger's constants from nuturtle_description/config/diff_params.yaml and its own
defaults from config/landmarks.yaml and config/slam.yaml (`nuslam.launch_nodes`).
"""

from launch import LaunchDescription
from launch_ros.actions import Node

from nuslam.launch_nodes import landmarks_parameters, slam_parameters


def generate_launch_description() -> LaunchDescription:
    return LaunchDescription(
        [
            Node(
                package="nuslam",
                executable="landmarks",
                parameters=landmarks_parameters(use_sim_time=False),
                output="screen",
            ),
            Node(
                package="nuslam",
                executable="slam",
                parameters=slam_parameters("unknown", use_sim_time=False),
                output="screen",
            ),
        ]
    )
