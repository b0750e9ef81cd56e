"""nuturtle_control's launch file refers to existing configs and executables (the config files themselves:
tests/packaging/test_config_files.py)."""

from __future__ import annotations

import ast
from pathlib import Path

PACKAGE = Path(__file__).resolve().parents[2] / "nuturtle_control"


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
