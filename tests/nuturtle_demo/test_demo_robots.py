"""Two robots in the demo, in process (run_demo): each robot's SLAM meets its targets while the other drives
around it, its scans see the other robot, and the outputs are a folder per robot and the summary. A short
run (docs/demo.md has the two-minute figures of two and three robots in both worlds). Its bag is then
replayed for one robot (the replay's ``--namespace``): the real two-robot recording, at no extra run."""

import json
from pathlib import Path

import numpy as np
import pytest
import yaml

from bag_reading import read_bag
from nuturtle_demo.cli import report
from nuturtle_demo.robot_stack import landmark_radius_window
from nuturtle_demo.run import DemoOptions, run_demo
from nuturtle_description.robot_params import burger_params
from nuturtle_ros_common.conversions import stamp_seconds, yaw_from_quaternion
from nuturtle_tools.replay import main as replay_main
from nuturtle_tools.replay_run import ReplayOptions, run_replay
from turtlelib import Transform2D

DURATION_S = 20.0
# a beam ends on the other robot's disc: within the LiDAR's noise and resolution (1 cm each) of its edge
ON_DISC_M = 0.05


def test_the_landmark_radius_window_leaves_out_the_robots_radius():
    # the default world's 0.038 m cylinders and the Burger's 0.11 m: up to halfway
    assert landmark_radius_window([0.038, 0.038], 0.11) == {"max_radius": pytest.approx(0.074)}
    # turtlebot3_world's 0.15 m cylinders: from halfway; never past the detector's own window (0.02 to
    # 0.25 m): posts beyond it are not detected anyway
    assert landmark_radius_window([0.15], 0.11) == {"min_radius": pytest.approx(0.13)}
    assert landmark_radius_window([0.3], 0.22) == {}
    assert landmark_radius_window([0.05], 0.6) == {"max_radius": 0.25}
    # cylinders on both sides of the robot's radius, or none: nothing to tell them apart by
    assert landmark_radius_window([0.05, 0.15], 0.11) == {} and landmark_radius_window([], 0.11) == {}


def scan_points(scan, T_world_scan: Transform2D) -> np.ndarray:
    """The scan's returns (n, 2) in nusim/world."""
    ranges = np.asarray(scan.ranges)
    angles = scan.angle_min + scan.angle_increment * np.arange(ranges.size)
    hit = ranges > scan.range_min
    p_scan = np.column_stack([ranges * np.cos(angles), ranges * np.sin(angles)])[hit]
    return T_world_scan @ p_scan


def truth_by_stamp(bag, name: str) -> dict[float, Transform2D]:
    poses = {}
    for odom in bag.decoded(f"/{name}/nusim/ground_truth"):
        pose = odom.pose.pose
        theta = yaw_from_quaternion(pose.orientation)
        poses[stamp_seconds(odom.header.stamp)] = Transform2D(pose.position.x, pose.position.y, theta)
    return poses


@pytest.fixture(scope="module")
def two_robots(tmp_path_factory) -> tuple[Path, object]:
    """A two-robot demo run: its output folder and its result."""
    out = tmp_path_factory.mktemp("two") / "out"
    return out, run_demo(DemoOptions(duration_s=DURATION_S, out_dir=out, robots=2, progress=False))


@pytest.mark.slow
@pytest.mark.ros
def test_two_robots_each_map_within_their_targets_and_see_each_other(two_robots):
    out, result = two_robots
    assert [robot.name for robot in result.robots] == ["tb3_0", "tb3_1"]
    # several robots map once (no map file to continue): no --route-start hint in the report
    options = DemoOptions(duration_s=DURATION_S, out_dir=out, robots=2, progress=False)
    assert "route: stopped" not in report(result, options)
    assert sorted(p.name for p in out.iterdir()) == ["config.yaml", "run", "summary.md", "tb3_0", "tb3_1"]
    summary = (out / "summary.md").read_text()
    for robot in result.robots:
        assert robot.out_dir == out / robot.name
        metrics = json.loads((robot.out_dir / "metrics.json").read_text())
        assert metrics["robot"] == robot.name and metrics["complete"]
        # SLAM within its targets while the other robot drives
        assert (
            metrics["final_position_error_slam_m"] <= 0.02 and metrics["final_heading_error_slam_rad"] <= 0.02
        )
        assert metrics["ate_rmse_slam_m"] <= 0.02
        assert metrics["ate_rmse_odom_m"] >= 3 * metrics["ate_rmse_slam_m"]
        assert metrics["landmark_rmse_m"] <= 0.02
        assert metrics["landmarks_in_range"] >= 3 and metrics["landmarks_in_range_unmapped"] == 0
        # the other robot is never mapped (the landmark radius window leaves its radius out)
        assert metrics["landmarks_duplicate"] == 0 and metrics["landmarks_spurious"] == 0
        assert (robot.out_dir / "trajectory.png").is_file() and (robot.out_dir / "map.yaml").is_file()
        assert f"| {robot.name} | " in summary

    # each robot's scans, placed at its true pose, end on the other robot's disc (collision radius)
    bag = read_bag(out / "run")
    robot = burger_params()
    truth = {name: truth_by_stamp(bag, name) for name in ("tb3_0", "tb3_1")}
    for name, other in (("tb3_0", "tb3_1"), ("tb3_1", "tb3_0")):
        seen = 0
        scans = bag.decoded(f"/{name}/scan")
        assert len(scans) >= 0.95 * 5 * DURATION_S
        for scan in scans:
            t_s = stamp_seconds(scan.header.stamp)
            assert scan.header.frame_id == f"{name}/base_scan"
            p_world = scan_points(scan, truth[name][t_s] @ robot.T_body_scan)
            gap_m = np.abs(np.hypot(*(p_world - truth[other][t_s].translation).T) - robot.collision_radius)
            seen += bool(np.any(gap_m <= ON_DISC_M))
        assert seen >= 0.5 * len(scans), f"{name} saw {other} in {seen} of {len(scans)} scans"


@pytest.mark.slow
@pytest.mark.ros
def test_one_robot_of_the_two_robot_bag_replays_under_its_namespace(two_robots, tmp_path, capsys):
    out, _ = two_robots
    # without --namespace the bag has none of the default topics: the error names its robots
    assert replay_main([str(out / "run"), "--out", str(tmp_path / "refused"), "--no-progress"]) == 2
    error = capsys.readouterr().err
    assert "under the namespaces tb3_0, tb3_1: replay one robot with --namespace tb3_0" in error
    assert not (tmp_path / "refused").exists()

    replayed = tmp_path / "tb3_1"
    options = ReplayOptions(
        bag=out / "run", out_dir=replayed, params=out / "config.yaml", namespace="tb3_1", progress=False
    )
    result = run_replay(options)
    metrics = result.metrics
    bag = read_bag(out / "run")
    # that robot's topics played, every scan's landmarks applied by its slam
    inputs = ("scan", "joint_states", "odom", "nusim/ground_truth")
    assert metrics["messages_played"] == {
        f"/tb3_1/{name}": len(bag.topic_records(f"/tb3_1/{name}")) for name in inputs
    }
    assert metrics["observation_arrays_applied"] == metrics["scans_played"] >= 0.95 * 5 * DURATION_S
    # its estimate against its own truth, as the live run judged it (the same input in the same order)
    live = json.loads((out / "tb3_1" / "metrics.json").read_text())
    assert result.accuracy and metrics["nusim_recording"]
    for key in ("final_position_error_slam_m", "ate_rmse_slam_m", "landmark_rmse_m"):
        assert metrics[key] == pytest.approx(live[key], rel=0.2, abs=1e-3), key
    assert metrics["landmarks_mapped"] == live["landmarks_mapped"] >= 3
    # slam ran under /tb3_1 with the robot's frames (its own map frame: no --map-frame)
    slam = yaml.safe_load((replayed / "config.yaml").read_text())["tb3_1/slam"]["ros__parameters"]
    frames = ("map_id", "odom_id", "body_id", "sensor_id")
    assert [slam[k] for k in frames] == ["tb3_1/map", "tb3_1/odom", "tb3_1/base_footprint", "tb3_1/base_scan"]
    outputs = read_bag(replayed / "slam")
    poses = outputs.decoded("/tb3_1/slam/odom")
    assert poses and {(m.header.frame_id, m.child_frame_id) for m in poses} == {
        ("tb3_1/map", "tb3_1/base_footprint")
    }
    assert len(outputs.topic_records("/tb3_1/landmarks")) == metrics["scans_played"]
