"""Every node's config/<node>.yaml holds exactly the node's defaults: running with it is the same as
running with no arguments (the robot's constants live in nuturtle_description/config/diff_params.yaml)."""

from __future__ import annotations

import dataclasses
from pathlib import Path

import pytest
from turtlelib import DetectorConfig, SlamConfig, TimelineConfig

from nuslam.slam_node import SlamNodeConfig
from nuturtle_control.circle import CircleConfig
from nuturtle_control.odometry import OdometryFrames
from nuturtle_control.path_trail import PathTrailConfig
from nuturtle_control.wheel_joints import WheelJoints
from nuturtle_description.robot_params import load_ros_yaml
from nuturtle_description.ros_params import field_defaults

ROOT = Path(__file__).resolve().parents[2]

NODE_CONFIGS = {
    ("nuturtle_control", "turtle_control"): [WheelJoints],
    ("nuturtle_control", "odometry"): [WheelJoints, OdometryFrames, PathTrailConfig],
    ("nuturtle_control", "circle"): [CircleConfig],
    ("nuslam", "landmarks"): [DetectorConfig],
    ("nuslam", "slam"): [SlamNodeConfig, SlamConfig, TimelineConfig, WheelJoints, PathTrailConfig],
}


@pytest.mark.parametrize(("package", "node"), NODE_CONFIGS)
def test_config_yaml_holds_exactly_the_node_defaults(package, node):
    values = load_ros_yaml(ROOT / package / "config" / f"{node}.yaml")
    configs = NODE_CONFIGS[package, node]
    defaults = {}
    for cls in configs:
        defaults.update(field_defaults(cls))
    assert values == defaults
    for cls in configs:  # and the values build valid configs
        cls(**{field.name: values[field.name] for field in dataclasses.fields(cls)})


@pytest.mark.parametrize(("package", "node"), NODE_CONFIGS)
def test_a_node_declares_no_parameter_name_twice(package, node):
    """A node declares its configs in one namespace: a field name in two of them would collide."""
    names = [field.name for cls in NODE_CONFIGS[package, node] for field in dataclasses.fields(cls)]
    assert len(names) == len(set(names))
