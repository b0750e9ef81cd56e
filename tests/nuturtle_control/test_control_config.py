"""nuturtle_control's config files and launch file agree with the nodes' parameters."""

from __future__ import annotations

import ast
import dataclasses
from pathlib import Path

import pytest

from nuturtle_control.circle import CircleConfig
from nuturtle_control.odometry import OdometryFrames
from nuturtle_control.path_trail import PathTrailConfig
from nuturtle_control.wheel_joints import WheelJoints
from nuturtle_description.robot_params import load_ros_yaml
from nuturtle_description.ros_params import field_defaults

PACKAGE = Path(__file__).resolve().parents[2] / "nuturtle_control"

NODE_CONFIGS = {
    "turtle_control": [WheelJoints],
    "odometry": [WheelJoints, OdometryFrames, PathTrailConfig],
    "circle": [CircleConfig],
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


def test_launch_file_parses_and_refers_to_existing_configs_and_executables():
    source = (PACKAGE / "launch" / "start_robot.launch.py").read_text()
    tree = ast.parse(source)
    calls = [node for node in ast.walk(tree) if isinstance(node, ast.Call)]
    configs = {
        (call.args[0].value, call.args[1].value)
        for call in calls
        if getattr(call.func, "id", None) == "_config"
    }
    assert ("nuturtle_description", "diff_params.yaml") in configs
    assert ("nusim", "basic_world.yaml") in configs
    root = PACKAGE.parent
    for package, name in configs:
        if package != "nusim":  # written by another engineer
            assert (root / package / "config" / name).is_file(), (package, name)
    executables = {
        keyword.value.value
        for call in calls
        for keyword in call.keywords
        if keyword.arg == "executable"
    }
    assert {"turtle_control", "odometry", "circle", "nusim", "teleop_twist_keyboard"} <= executables
    setup = (PACKAGE / "setup.py").read_text()
    for executable in ("turtle_control", "odometry", "circle"):
        assert f"{executable} = nuturtle_control.{executable}:main" in setup
