"""nuslam's config files and launch file agree with the nodes' parameters."""

from __future__ import annotations

import ast
import dataclasses
from pathlib import Path

import pytest
from turtlelib import DetectorConfig, SlamConfig, TimelineConfig

from nuslam.slam_node import SlamNodeConfig
from nuturtle_control.path_trail import PathTrailConfig
from nuturtle_control.wheel_joints import WheelJoints
from nuturtle_description.robot_params import load_ros_yaml
from nuturtle_description.ros_params import field_defaults

PACKAGE = Path(__file__).resolve().parents[2] / "nuslam"

NODE_CONFIGS = {
    "landmarks": [DetectorConfig],
    "slam": [SlamNodeConfig, SlamConfig, TimelineConfig, WheelJoints, PathTrailConfig],
}


@pytest.mark.parametrize("node", NODE_CONFIGS)
def test_config_yaml_holds_exactly_the_node_defaults(node):
    """Running with config/<node>.yaml is the same as running with no arguments."""
    values = load_ros_yaml(PACKAGE / "config" / f"{node}.yaml")
    defaults = {}
    for cls in NODE_CONFIGS[node]:
        defaults.update(field_defaults(cls))
    assert values == defaults
    for cls in NODE_CONFIGS[node]:  # and the values build valid configs
        cls(**{field.name: values[field.name] for field in dataclasses.fields(cls)})


def test_node_configs_share_no_parameter_name():
    """The slam node declares every config under one namespace: a name in two configs would collide."""
    names = [field.name for cls in NODE_CONFIGS["slam"] for field in dataclasses.fields(cls)]
    assert len(names) == len(set(names))


def test_launch_file_parses_and_refers_to_existing_configs_and_executables():
    source = (PACKAGE / "launch" / "slam.launch.py").read_text()
    calls = [node for node in ast.walk(ast.parse(source)) if isinstance(node, ast.Call)]
    shared = {
        tuple(arg.value for arg in call.args)
        for call in calls
        if getattr(call.func, "id", None) == "_share"
    }
    root = PACKAGE.parent
    for package, *parts in shared:
        assert root.joinpath(package, *parts).is_file(), (package, parts)
    assert ("nuslam", "config", "slam.yaml") in shared
    assert ("nuturtle_control", "launch", "start_robot.launch.py") in shared
    executables = {kw.value.value for call in calls for kw in call.keywords if kw.arg == "executable"}
    assert executables == {"landmarks", "slam"}
    setup = (PACKAGE / "setup.py").read_text()
    assert "landmarks = nuslam.landmarks_node:main" in setup
    assert "slam = nuslam.slam_node:main" in setup
