"""The parameter lists of nuturtle_control's launch file (plain functions: tests call them, launch cannot
run in CI): the node's config/<node>.yaml, then the launch arguments, which win. The robot's constants are
the defaults of the ``model`` argument, passed on as each node's ``model`` parameter."""

from __future__ import annotations

from typing import Any

from nuturtle_description.robot_params import model_params
from nuturtle_description.urdf import robot_urdf
from nuturtle_ros_common.launch_parameters import LaunchArgument, with_arguments
from nuturtle_ros_common.ros_files import share_file

CMD_SRC = LaunchArgument(
    "none", ("none", "circle", "teleop"), "what publishes cmd_vel (none: nothing moves the robot until asked)"
)


def _robot_node(node: str, use_sim_time: bool, model: str) -> list[str | dict[str, Any]]:
    files = [share_file("nuturtle_control", "config", f"{node}.yaml")]
    return with_arguments(files, {"use_sim_time": use_sim_time, "model": model})


def turtle_control_parameters(use_sim_time: bool, model: str) -> list[str | dict[str, Any]]:
    return _robot_node("turtle_control", use_sim_time, model)


def odometry_parameters(use_sim_time: bool, model: str) -> list[str | dict[str, Any]]:
    return _robot_node("odometry", use_sim_time, model)


def robot_state_publisher_parameters(use_sim_time: bool, model: str) -> list[dict[str, Any]]:
    """robot_state_publisher's: the URDF of ``model`` generated from its constants (so `base_footprint ->
    base_scan` on /tf_static is the LiDAR mount slam uses) and ``use_sim_time``."""
    return [{"robot_description": robot_urdf(model, model_params(model)), "use_sim_time": use_sim_time}]


def circle_parameters(use_sim_time: bool) -> list[str | dict[str, Any]]:
    return with_arguments(
        [share_file("nuturtle_control", "config", "circle.yaml")], {"use_sim_time": use_sim_time}
    )
