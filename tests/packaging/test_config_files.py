"""Every node's config file holds exactly what the node declares, with the node's defaults: running with it
is the same as running with no arguments. The robot's constants are declared from
nuturtle_description/config/diff_params.yaml, the one place they are written (real rclpy nodes)."""

from __future__ import annotations

import array
from pathlib import Path

import pytest

from nusim.nusim_node import NusimNode
from nuslam.landmarks_node import LandmarksNode
from nuslam.slam_node import SlamNode
from nuturtle_control.circle import CircleNode
from nuturtle_control.odometry import OdometryNode
from nuturtle_control.turtle_control import TurtleControlNode
from nuturtle_ros_common.ros_files import load_ros_parameters, load_ros_yaml

ROOT = Path(__file__).resolve().parents[2]
# parameters rclpy declares on every node
ROS_OWN = {"use_sim_time", "start_type_description_service"}
DIFF_PARAMS = ROOT / "nuturtle_description" / "config" / "diff_params.yaml"

# node class, its config file, whether it declares the robot's constants
NODES = {
    "nusim": (NusimNode, ROOT / "nusim" / "config" / "basic_world.yaml", True),
    "turtle_control": (TurtleControlNode, ROOT / "nuturtle_control" / "config" / "turtle_control.yaml", True),
    "odometry": (OdometryNode, ROOT / "nuturtle_control" / "config" / "odometry.yaml", True),
    "circle": (CircleNode, ROOT / "nuturtle_control" / "config" / "circle.yaml", False),
    "landmarks": (LandmarksNode, ROOT / "nuslam" / "config" / "landmarks.yaml", False),
    "slam": (SlamNode, ROOT / "nuslam" / "config" / "slam.yaml", True),
}


def comparable(value):
    if isinstance(value, (list, tuple, array.array)):
        return [float(v) for v in value]
    return value


@pytest.mark.parametrize("name", NODES)
def test_config_file_holds_exactly_the_declared_parameters_and_their_defaults(ros, name):
    cls, config_file, robot = NODES[name]
    node = ros.add(cls(context=ros.context))
    declared = {
        parameter: comparable(node.get_parameter(parameter).value)
        for parameter in node.list_parameters([], 0).names
        if parameter not in ROS_OWN
    }
    expected = {key: comparable(value) for key, value in load_ros_parameters(config_file).items()}
    if robot:
        robot_constants = load_ros_yaml(DIFF_PARAMS)
        assert not robot_constants.keys() & expected.keys(), "robot constants belong in diff_params.yaml"
        expected.update(robot_constants)
    assert declared.keys() == expected.keys()
    for parameter, value in expected.items():
        if isinstance(value, str | bool):
            assert declared[parameter] == value, parameter
        else:
            assert declared[parameter] == pytest.approx(value, rel=1e-9), parameter
