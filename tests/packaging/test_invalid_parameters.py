"""Every node, started as its executable with an invalid parameter, stops at start-up with exit code 1
and the reason, no traceback (run_node: invalid parameters are a clear message, not a crash)."""

from __future__ import annotations

import subprocess
import sys

import pytest

# module, an invalid parameter, the message it must give
CASES = [
    ("nusim.nusim_node", "arena_x_length:=-1.0", "arena_x_length must be finite and > 0, got -1.0"),
    (  # an unknown robot model: the choices
        "nuturtle_control.turtle_control",
        "model:=waffle3",
        "model must be one of ('burger', 'waffle', 'waffle_pi'), got 'waffle3'",
    ),
    ("nuturtle_control.odometry", "wheel_radius:=-1.0", "wheel_radius must be finite and > 0, got -1.0"),
    ("nuturtle_control.circle", "radius:=-1.0", "radius must be finite and > 0, got -1.0"),
    ("nuslam.landmarks_node", "min_points:=1", "detector min_points must be >= 3, got 1"),
    ("nuslam.slam_node", "association:=foo", "association must be one of ('known', 'unknown'), got 'foo'"),
]


@pytest.mark.parametrize(("module", "parameter", "message"), CASES, ids=[case[0] for case in CASES])
def test_executable_with_an_invalid_parameter_exits_1_with_the_reason(tmp_path, module, parameter, message):
    # cwd outside the repository: its package folders would shadow the installed packages
    result = subprocess.run(
        [sys.executable, "-m", module, "--ros-args", "-p", parameter],
        cwd=tmp_path,
        capture_output=True,
        text=True,
        timeout=60,
    )
    assert result.returncode == 1, result.stderr
    assert f"invalid configuration: {message}" in result.stderr
    assert "Traceback" not in result.stderr
