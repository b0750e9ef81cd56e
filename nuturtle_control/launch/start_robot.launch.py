"""Drive a TurtleBot3 (for a full ROS 2 install): turtle_control + odometry and a command source.

Arguments
    model:=burger|waffle|waffle_pi  the robot (default: $TURTLEBOT3_MODEL, else burger): its constants are
                                  every node's defaults and robot_state_publisher's URDF.
    use_sim_time:=false|true      true when the robot is simulated (every node on nusim's /clock).
    cmd_src:=none|circle|teleop   none (default): nothing drives until asked (another node, `ros2 topic
                                  pub`, or `ros2 run nuturtle_control circle`); circle: the `circle` node
                                  publishes cmd_vel (config/circle.yaml); teleop: teleop_twist_keyboard in
                                  its own terminal (xterm).
    one_process:=false|true       true: turtle_control and odometry are not started here: they run in
                                  nuslam's robot_side process with slam and landmarks (what
                                  slam.launch.py one_process:=true starts).
    namespace:=<name>             the robot's namespace (default empty: none), e.g. tb3_0: every node and
                                  topic under /tb3_0 (`/tb3_0/cmd_vel`, `/tb3_0/odom`), odometry's frames
                                  tb3_0/odom -> tb3_0/base_footprint and robot_state_publisher's
                                  frame_prefix tb3_0/ (TurtleBot3's convention for several robots).

The simulator is not started here (this package installs on the robot without it): the simulated system
is `ros2 launch nuturtle_demo nusim_slam.launch.py`. Every node gets its own defaults from this package's
config/<node>.yaml, then the launch arguments (last, so they win: `nuturtle_control.launch_nodes`), `model`
among them: the model's constants (nuturtle_description/config/models.yaml) are the nodes' defaults.
robot_state_publisher publishes the URDF generated from them: `base_footprint -> base_scan` on /tf_static
(the LiDAR mount slam uses) and the wheels' TF from joint_states. turtle_control stops the
wheels `cmd_timeout` (0.5 s) after the last cmd_vel.
"""

from launch import LaunchDescription
from launch.actions import OpaqueFunction
from launch.substitutions import LaunchConfiguration
from launch_ros.actions import Node

from nuturtle_control.launch_nodes import (
    CMD_SRC,
    circle_parameters,
    odometry_parameters,
    robot_state_publisher_parameters,
    turtle_control_parameters,
)
from nuturtle_description.launch_arguments import (
    declare_argument,
    in_namespace,
    launched_frames,
    model_argument,
    switch_argument,
)
from nuturtle_ros_common.launch_parameters import NAMESPACE


def _nodes(context):
    cmd_src = LaunchConfiguration("cmd_src").perform(context)
    use_sim_time = LaunchConfiguration("use_sim_time").perform(context) == "true"
    model = LaunchConfiguration("model").perform(context)
    frames = launched_frames(context)
    nodes = [
        # the one owner of base_footprint -> base_scan (and the wheel joints' TF)
        Node(
            package="robot_state_publisher",
            executable="robot_state_publisher",
            parameters=robot_state_publisher_parameters(use_sim_time, model, frames.prefix),
            output="screen",
        ),
    ]
    if LaunchConfiguration("one_process").perform(context) == "false":
        nodes += [
            Node(
                package="nuturtle_control",
                executable="turtle_control",
                parameters=turtle_control_parameters(use_sim_time, model),
                output="screen",
            ),
            Node(
                package="nuturtle_control",
                executable="odometry",
                parameters=odometry_parameters(use_sim_time, model, **frames.odometry()),
                output="screen",
            ),
        ]
    if cmd_src == "circle":
        nodes.append(
            Node(
                package="nuturtle_control",
                executable="circle",
                parameters=circle_parameters(use_sim_time),
                output="screen",
            )
        )
    elif cmd_src == "teleop":
        nodes.append(
            Node(
                package="teleop_twist_keyboard",
                executable="teleop_twist_keyboard",
                prefix="xterm -e",
                parameters=[{"use_sim_time": use_sim_time}],
                output="screen",
            )
        )
    return in_namespace(frames, nodes)


def generate_launch_description() -> LaunchDescription:
    return LaunchDescription(
        [
            model_argument(),
            switch_argument("use_sim_time", False, "true: run on /clock (simulated robot)"),
            declare_argument("cmd_src", CMD_SRC),
            declare_argument("namespace", NAMESPACE),
            switch_argument(
                "one_process", False, "true: turtle_control and odometry run in nuslam's robot_side instead"
            ),
            OpaqueFunction(function=_nodes),
        ]
    )
