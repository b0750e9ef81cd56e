"""The parameter lists of nuturtle_control's launch file (plain functions: tests call them, launch cannot
run in CI): the robot's constants, the node's config/<node>.yaml, then the launch arguments, which win."""

from __future__ import annotations

from typing import Any

from nuturtle_description.robot_params import burger_params
from nuturtle_description.urdf import burger_urdf
from nuturtle_ros_common.launch_parameters import with_arguments
from nuturtle_ros_common.ros_files import share_file

CMD_SOURCES = ("none", "circle", "teleop")


def _robot_node(node: str, use_sim_time: bool) -> list[str | dict[str, Any]]:
    files = [
        share_file("nuturtle_description", "config", "diff_params.yaml"),
        share_file("nuturtle_control", "config", f"{node}.yaml"),
    ]
    return with_arguments(files, {"use_sim_time": use_sim_time})


def turtle_control_parameters(use_sim_time: bool) -> list[str | dict[str, Any]]:
    return _robot_node("turtle_control", use_sim_time)


def odometry_parameters(use_sim_time: bool) -> list[str | dict[str, Any]]:
    return _robot_node("odometry", use_sim_time)


def robot_state_publisher_parameters(use_sim_time: bool) -> list[dict[str, Any]]:
    """robot_state_publisher's: the Burger's URDF generated from diff_params.yaml (so `base_footprint ->
    base_scan` on /tf_static is the LiDAR mount slam uses) and ``use_sim_time``."""
    return [{"robot_description": burger_urdf(burger_params()), "use_sim_time": use_sim_time}]


def circle_parameters(use_sim_time: bool) -> list[str | dict[str, Any]]:
    return with_arguments(
        [share_file("nuturtle_control", "config", "circle.yaml")], {"use_sim_time": use_sim_time}
    )
