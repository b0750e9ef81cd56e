"""EKF SLAM (for a full ROS 2 install): nuturtle_control's start_robot.launch.py plus landmarks and slam.

Arguments
    model:=burger|waffle|waffle_pi  the robot (default: $TURTLEBOT3_MODEL, else burger): its constants are
                                  every node's defaults (nuturtle_description/config/models.yaml).
    association:=unknown|known    unknown (default): landmarks found in the LiDAR scan by the `landmarks`
                                  node; known: nusim's fake_sensor (simulator only).
    use_sim_time:=false|true      true against the simulator (every node on nusim's /clock).
    cmd_src:=none|circle|teleop   what drives the robot (see start_robot.launch.py; none by default: nothing
                                  moves until asked).
    motion_source:=joint_states|odom, mode:=mapping|localization, map_file:=PATH
                                  slam's motion input, localization in a saved map (see turtlebot3.launch.py).
    rviz:=false|true              true: also RViz2 with nuslam's rviz/slam.rviz (fixed frame `map`, on the
                                  same clock as the nodes).
    one_process:=false|true       true: turtle_control, odometry, slam and landmarks in one process
                                  (`robot_side`: one executor, one /clock subscription; less CPU and
                                  memory, docs/benchmarks.md "Robot-side nodes"); false (default): one
                                  process each.
    managed:=false|true           true: slam and landmarks as managed (lifecycle) nodes, `slam_managed` and
                                  `landmarks_managed`: started unconfigured, they wait for a lifecycle
                                  manager (nav2's lifecycle_manager, `ros2 lifecycle set`) to configure
                                  and activate them with the rest of the stack (docs/robot.md "Managed
                                  nodes"); turtle_control and odometry stay plain. Started by launch_ros's
                                  plain `Node` action: the manager drives them over their lifecycle
                                  services, and `LifecycleNode` would only add launch-side transition
                                  events, which nothing here uses. Not with one_process:=true (robot_side
                                  runs plain nodes): the launch stops with that reason.
    namespace:=<name>             the robot's namespace (default empty: none), e.g. tb3_0: every node here
                                  and in start_robot.launch.py under /tb3_0 (`/tb3_0/scan`,
                                  `/tb3_0/slam/odom`), its frames tb3_0/odom, tb3_0/base_footprint,
                                  tb3_0/base_scan (slam's and odometry's frame ids, robot_state_publisher's
                                  frame_prefix); /tf, /tf_static, /clock stay global.
    map_frame:=<frame>            slam's map frame (default empty: the robot's own, tb3_0/map under a
                                  namespace, else map); map: one map frame shared by several robots.

    ros2 launch nuslam slam.launch.py cmd_src:=teleop        # our control stack (wheel_cmd firmware)
    ros2 launch nuslam slam.launch.py rviz:=true             # ... and watch it in RViz2
    ros2 launch nuslam turtlebot3.launch.py                  # a stock TurtleBot3 (its own odom, TF, cmd_vel)
    ros2 launch nuturtle_demo nusim_slam.launch.py           # the same against the simulator
    ros2 launch nuslam slam.launch.py namespace:=tb3_0       # one of several robots (docs/robot.md)

Every node reads its own defaults from config/landmarks.yaml and config/slam.yaml and the robot's constants
from its `model`; the launch arguments come last, so they win (`nuslam.launch_nodes`).
RViz shows the wheel odometry's path (blue) and SLAM's pose with its covariance, path and map in `map`
(green), with the scan and the LiDAR landmarks; under a namespace, that robot's topics in its map frame.
"""

from launch import LaunchDescription
from launch.actions import IncludeLaunchDescription, OpaqueFunction
from launch.conditions import IfCondition
from launch.launch_description_sources import PythonLaunchDescriptionSource
from launch.substitutions import LaunchConfiguration
from launch_ros.actions import Node

from nuslam.launch_nodes import (
    ASSOCIATION,
    MANAGED_DESCRIPTION,
    MANAGED_ONE_PROCESS,
    SLAM_ARGUMENTS,
    landmarks_parameters,
    node_executable,
    robot_side_parameters,
    rviz_arguments,
    slam_parameters,
)
from nuturtle_control.launch_nodes import CMD_SRC
from nuturtle_description.launch_arguments import (
    declare_argument,
    in_namespace,
    launched_frames,
    model_argument,
    switch_argument,
)
from nuturtle_ros_common.launch_parameters import MAP_FRAME, NAMESPACE
from nuturtle_ros_common.ros_files import share_file


def _slam_nodes(context):
    association = LaunchConfiguration("association").perform(context)
    use_sim_time = LaunchConfiguration("use_sim_time").perform(context) == "true"
    arguments = {name: LaunchConfiguration(name).perform(context) for name in SLAM_ARGUMENTS}
    model = LaunchConfiguration("model").perform(context)
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
        robot_side = Node(
            package="nuslam",
            executable="robot_side",
            parameters=robot_side_parameters(association, use_sim_time, model, **arguments),
            output="screen",
        )
        return in_namespace(frames, [rviz, robot_side])
    nodes = [
        rviz,
        Node(
            package="nuslam",
            executable=node_executable("slam", managed),
            parameters=slam_parameters(association, use_sim_time, model, **arguments),
            output="screen",
        ),
    ]
    if association == "unknown":
        nodes.append(
            Node(
                package="nuslam",
                executable=node_executable("landmarks", managed),
                parameters=landmarks_parameters(use_sim_time),
                output="screen",
            )
        )
    return in_namespace(frames, nodes)


def generate_launch_description() -> LaunchDescription:
    return LaunchDescription(
        [
            model_argument(),
            declare_argument("association", ASSOCIATION),
            switch_argument("use_sim_time", False, "true: every node on /clock (the simulator)"),
            declare_argument("cmd_src", CMD_SRC),
            switch_argument("rviz", False, "true: also RViz2 (slam.rviz)"),
            switch_argument("one_process", False, "true: the robot-side nodes in one process (robot_side)"),
            switch_argument("managed", False, MANAGED_DESCRIPTION),
            declare_argument("namespace", NAMESPACE),
            declare_argument("map_frame", MAP_FRAME),
            *[declare_argument(name, argument) for name, argument in SLAM_ARGUMENTS.items()],
            IncludeLaunchDescription(
                PythonLaunchDescriptionSource(
                    str(share_file("nuturtle_control", "launch", "start_robot.launch.py"))
                ),
                launch_arguments={
                    "model": LaunchConfiguration("model"),
                    "use_sim_time": LaunchConfiguration("use_sim_time"),
                    "cmd_src": LaunchConfiguration("cmd_src"),
                    # with one_process, robot_side runs turtle_control and odometry
                    "one_process": LaunchConfiguration("one_process"),
                    "namespace": LaunchConfiguration("namespace"),
                }.items(),
            ),
            OpaqueFunction(function=_slam_nodes),
        ]
    )
