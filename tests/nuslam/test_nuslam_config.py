"""nuslam's launch file refers to existing configs and executables (the config files themselves:
tests/packaging/test_config_files.py)."""

from __future__ import annotations

import ast
from pathlib import Path

PACKAGE = Path(__file__).resolve().parents[2] / "nuslam"


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
