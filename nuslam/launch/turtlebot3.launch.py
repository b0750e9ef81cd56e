"""EKF SLAM on a stock TurtleBot3 (for a full ROS 2 install): landmarks and slam only.

The robot's own bringup (`ros2 launch turtlebot3_bringup robot.launch.py` on the robot) already runs
`turtlebot3_node`, which publishes `joint_states`, `odom` and the `odom -> base_footprint` transform and
takes `cmd_vel`, and `robot_state_publisher` (`base_footprint -> base_scan`), and the LDS driver (`scan`).
So nothing here drives the robot or duplicates its odometry: slam reads `joint_states` and the LiDAR
landmarks and broadcasts `map -> odom` against the robot's own `odom` (see docs/robot.md).

Arguments
    model:=burger|waffle|waffle_pi     the robot (default: $TURTLEBOT3_MODEL, as for the robot's own bringup,
                                       else burger): its wheels, motors and LiDAR mount
    motion_source:=joint_states|odom   the wheel angles (default) or the robot's odom as slam's motion
    mode:=mapping|localization         SLAM (default), or localization in the map of map_file
    map_file:=PATH                     the map loaded at start-up (if there) and written by slam/save_map
    use_sim_time:=false|true           true: every node on /clock (Gazebo, or `ros2 bag play --clock`)
    rviz:=false|true                   true: also RViz2 with nuslam's rviz/slam.rviz (fixed frame `map`)
    one_process:=false|true            true: landmarks and slam in one process (`slam_side`: one executor,
                                       one /clock subscription; less CPU and memory, docs/robot.md "CPU
                                       and memory"); false (default): one process each.
    managed:=false|true                true: `slam_managed` and `landmarks_managed`, the managed (lifecycle)
                                       variants, started unconfigured for a lifecycle manager (nav2's
                                       lifecycle_manager) to bring up with the rest of the stack
                                       (docs/robot.md "Managed nodes"), by launch_ros's plain `Node` action
                                       (the manager drives them over their lifecycle services; nothing here
                                       needs `LifecycleNode`'s launch-side events). Not with
                                       one_process:=true (slam_side runs plain nodes): the launch stops
                                       with that reason.
    namespace:=<name>                  the robot's namespace (default empty: none), e.g. tb3_0 for a robot
                                       whose bringup runs under /tb3_0 with its frames prefixed tb3_0/:
                                       landmarks and slam under /tb3_0, slam's frames tb3_0/odom,
                                       tb3_0/base_footprint, tb3_0/base_scan
    map_frame:=<frame>                 slam's map frame (default empty: tb3_0/map under a namespace, else
                                       map); map: one map frame shared by several robots

    ros2 launch nuslam turtlebot3.launch.py      # on the laptop, same ROS_DOMAIN_ID as the robot
    ros2 launch nuslam turtlebot3.launch.py rviz:=true
    ros2 launch nuslam turtlebot3.launch.py mode:=localization map_file:=$HOME/maps/lab.json
    ros2 launch nuslam turtlebot3.launch.py namespace:=tb3_0 rviz:=true

slam uses the LiDAR landmarks (association unknown: a real robot has no fake sensor).

Every node reads its own defaults from config/landmarks.yaml and config/slam.yaml, and slam the robot's
constants from its `model` (nuturtle_description/config/models.yaml; `nuslam.launch_nodes`).
"""

from launch import LaunchDescription
from launch.actions import OpaqueFunction
from launch.conditions import IfCondition
from launch.substitutions import LaunchConfiguration
from launch_ros.actions import Node

from nuslam.launch_nodes import (
    MANAGED_DESCRIPTION,
    MANAGED_ONE_PROCESS,
    SLAM_ARGUMENTS,
    landmarks_parameters,
    node_executable,
    rviz_arguments,
    slam_parameters,
    slam_side_parameters,
)
from nuturtle_description.launch_arguments import (
    declare_argument,
    in_namespace,
    launched_frames,
    model_argument,
    switch_argument,
)
from nuturtle_ros_common.launch_parameters import MAP_FRAME, NAMESPACE


def _nodes(context):
    arguments = {name: LaunchConfiguration(name).perform(context) for name in SLAM_ARGUMENTS}
    model = LaunchConfiguration("model").perform(context)
    use_sim_time = LaunchConfiguration("use_sim_time").perform(context) == "true"
    frames = launched_frames(context)
    arguments.update(frames.slam())
    rviz = Node(
        package="rviz2",
        executable="rviz2",
        arguments=rviz_arguments(frames),
        parameters=[{"use_sim_time": use_sim_time}],
        condition=IfCondition(LaunchConfiguration("rviz")),
        output="screen",
    )
    managed = LaunchConfiguration("managed").perform(context) == "true"
    if LaunchConfiguration("one_process").perform(context) == "true":
        if managed:
            raise ValueError(MANAGED_ONE_PROCESS)
        slam_side = Node(
            package="nuslam",
            executable="slam_side",
            parameters=slam_side_parameters("unknown", use_sim_time, model, **arguments),
            output="screen",
        )
        return in_namespace(frames, [rviz, slam_side])
    nodes = [
        rviz,
        Node(
            package="nuslam",
            executable=node_executable("landmarks", managed),
            parameters=landmarks_parameters(use_sim_time),
            output="screen",
        ),
        Node(
            package="nuslam",
            executable=node_executable("slam", managed),
            parameters=slam_parameters("unknown", use_sim_time, model, **arguments),
            output="screen",
        ),
    ]
    return in_namespace(frames, nodes)


def generate_launch_description() -> LaunchDescription:
    return LaunchDescription(
        [
            model_argument(),
            *[declare_argument(name, argument) for name, argument in SLAM_ARGUMENTS.items()],
            switch_argument(
                "use_sim_time",
                False,
                "true: every node on /clock (a simulated robot, or a bag played with --clock)",
            ),
            switch_argument("rviz", False, "true: also RViz2 (slam.rviz)"),
            switch_argument("one_process", False, "true: landmarks and slam in one process (slam_side)"),
            switch_argument("managed", False, MANAGED_DESCRIPTION),
            declare_argument("namespace", NAMESPACE),
            declare_argument("map_frame", MAP_FRAME),
            OpaqueFunction(function=_nodes),
        ]
    )
