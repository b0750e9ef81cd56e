"""Every node's config file holds exactly what the node declares, with the node's defaults: running with it
is the same as running with no arguments. The robot's constants (and slam's odom_* twist noise, made from
them) are not in these files: they are the defaults of the node's `model` parameter, written once in
nuturtle_description/config/models.yaml (real rclpy nodes)."""

from __future__ import annotations

import array
from pathlib import Path

import pytest

from nusim.nusim_node import NusimNode
from nuslam.landmarks_node import LandmarksNode
from nuslam.slam_node import WHEEL_NOISE, SlamNode
from nuturtle_control.circle import CircleNode
from nuturtle_control.odometry import OdometryNode
from nuturtle_control.turtle_control import TurtleControlNode
from nuturtle_description.robot_params import burger_params
from nuturtle_ros_common.ros_files import load_ros_parameters
from turtlelib import TwistNoise

ROOT = Path(__file__).resolve().parents[2]
# parameters rclpy declares on every node
ROS_OWN = {"use_sim_time", "start_type_description_service"}

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
    if robot:  # the Burger's: no TURTLEBOT3_MODEL in the tests' environment
        model_defaults = {"model": "burger", **vars(burger_params())}
        if name == "slam":
            noise = TwistNoise.from_wheel_slip(burger_params().diff_drive(), WHEEL_NOISE)
            model_defaults.update({f"odom_{key}": value for key, value in vars(noise).items()})
        assert not model_defaults.keys() & expected.keys(), "the model's defaults belong in models.yaml"
        expected.update(model_defaults)
    assert declared.keys() == expected.keys()
    for parameter, value in expected.items():
        if isinstance(value, str | bool):
            assert declared[parameter] == value, parameter
        else:
            assert declared[parameter] == pytest.approx(value, rel=1e-9), parameter
