"""The parameter lists of nuturtle_control's launch file (plain functions: tests call them, launch cannot
run in CI): the node's config/<node>.yaml, then the launch arguments, which win. The robot's constants are
the defaults of the ``model`` argument, passed on as each node's ``model`` parameter. Under a namespace,
odometry's frame ids and robot_state_publisher's ``frame_prefix`` come from
``nuturtle_ros_common.launch_parameters.robot_frames``."""

from __future__ import annotations

from typing import Any

from nuturtle_description.robot_params import model_params
from nuturtle_description.urdf import robot_urdf
from nuturtle_ros_common.launch_parameters import LaunchArgument, with_arguments
from nuturtle_ros_common.ros_files import share_file

CMD_SRC = LaunchArgument(
    "none", ("none", "circle", "teleop"), "what publishes cmd_vel (none: nothing moves the robot until asked)"
)


def _robot_node(node: str, use_sim_time: bool, model: str, **frame_ids: str) -> list[str | dict[str, Any]]:
    files = [share_file("nuturtle_control", "config", f"{node}.yaml")]
    return with_arguments(files, {"use_sim_time": use_sim_time, "model": model, **frame_ids})


def turtle_control_parameters(use_sim_time: bool, model: str) -> list[str | dict[str, Any]]:
    return _robot_node("turtle_control", use_sim_time, model)


def odometry_parameters(use_sim_time: bool, model: str, **frame_ids: str) -> list[str | dict[str, Any]]:
    """odometry's list; ``frame_ids``: its ``odom_id`` and ``body_id`` of a namespaced robot."""
    return _robot_node("odometry", use_sim_time, model, **frame_ids)


def robot_state_publisher_parameters(
    use_sim_time: bool, model: str, frame_prefix: str = ""
) -> list[dict[str, Any]]:
    """robot_state_publisher's: the URDF of ``model`` generated from its constants (so `base_footprint ->
    base_scan` on /tf_static is the LiDAR mount slam uses), ``use_sim_time`` and, for a namespaced robot,
    its ``frame_prefix`` (``tb3_0/``: every frame it publishes gets it)."""
    values = {"robot_description": robot_urdf(model, model_params(model)), "use_sim_time": use_sim_time}
    return [{**values, "frame_prefix": frame_prefix} if frame_prefix else values]


def circle_parameters(use_sim_time: bool) -> list[str | dict[str, Any]]:
    return with_arguments(
        [share_file("nuturtle_control", "config", "circle.yaml")], {"use_sim_time": use_sim_time}
    )
