"""The system as separate processes (each node started as `python -m <module>`), checked from an
independent subscriber process (flow_probe.py): scan, joint_states, odom and slam/odom flow with the
expected types and frames."""

import json
import subprocess
import sys
from pathlib import Path

import pytest

from nuturtle_demo.run import default_world

PROBE = Path(__file__).with_name("flow_probe.py")
SIM_TIME = ["-p", "use_sim_time:=true"]
NODES = {
    "nusim": ["nusim.nusim_node", "--params-file", str(default_world()), "-p", "realtime_factor:=2.0"],
    "turtle_control": ["nuturtle_control.turtle_control", *SIM_TIME],
    "odometry": ["nuturtle_control.odometry", *SIM_TIME],
    "landmarks": ["nuslam.landmarks_node", *SIM_TIME],
    "slam": ["nuslam.slam_node", *SIM_TIME],
    "driver": ["nuturtle_demo.driver", *SIM_TIME],
}


@pytest.mark.slow
@pytest.mark.ros
def test_nodes_as_processes_flow_with_expected_types_and_frames(tmp_path):
    processes = {}
    try:
        for name, (module, *ros_args) in NODES.items():
            log = open(tmp_path / f"{name}.log", "w")
            processes[name] = (
                subprocess.Popen(
                    [sys.executable, "-m", module, "--ros-args", *ros_args],
                    cwd=tmp_path, stdout=log, stderr=subprocess.STDOUT,
                ),
                log,
            )  # fmt: skip
        probe = subprocess.run(
            [sys.executable, str(PROBE), "60", "10"],
            cwd=tmp_path,
            capture_output=True,
            text=True,
            timeout=120,
        )
        for name, (process, _) in processes.items():
            assert process.poll() is None, f"{name} exited: {(tmp_path / f'{name}.log').read_text()}"
    finally:
        for process, _ in processes.values():
            process.terminate()
        for process, log in processes.values():
            try:
                process.wait(timeout=10)
            except subprocess.TimeoutExpired:
                process.kill()
                process.wait()
            log.close()
    assert probe.returncode == 0, probe.stderr
    for name, (process, _) in processes.items():
        log = (tmp_path / f"{name}.log").read_text()
        # SIGTERM on a busy system: each node stops cleanly (docs/robot.md, "Stopping a node")
        assert process.returncode == 0 and "Traceback" not in log, (
            f"{name} exited {process.returncode}: {log}"
        )
    seen = json.loads(probe.stdout.strip().splitlines()[-1])
    expected = {
        "/scan": ("sensor_msgs/msg/LaserScan", ["base_scan"]),
        "/joint_states": ("sensor_msgs/msg/JointState", ["wheel_left_joint,wheel_right_joint"]),
        "/odom": ("nav_msgs/msg/Odometry", ["odom->base_footprint"]),
        "/slam/odom": ("nav_msgs/msg/Odometry", ["map->base_footprint"]),
    }
    for topic, (type_name, frames) in expected.items():
        assert seen[topic]["count"] >= 10, (topic, seen[topic])
        assert seen[topic]["types"] == [type_name], (topic, seen[topic])
        assert seen[topic]["frames"] == frames, (topic, seen[topic])
