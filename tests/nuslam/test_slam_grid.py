"""slam's occupancy grid (real rclpy): scans placed at slam's pose at their own stamps and the robot's
LiDAR mount, `map` and `map_metadata` latched for late subscribers, ~/save_map writing map_server's pair
beside the landmark map, localization publishing the saved grid, mapping continuing it over two sessions,
malformed grid files stopping the node,
scans past the grid's bound warned about and its memory in /diagnostics.

Expected grids come from turtlelib (`OccupancyGrid`, `ScanKeyframes`) fed the same scans at the TRUE
poses (noise-free wheels: slam's dead-reckoned pose is the true one), never from the node. The grid's
own properties are tested in tests/turtlelib/test_occupancy_grid.py.
"""

from __future__ import annotations

import json

import numpy as np
import pytest
from diagnostic_msgs.msg import DiagnosticStatus
from nav_msgs.msg import MapMetaData
from nav_msgs.msg import OccupancyGrid as OccupancyGridMsg
from rclpy.parameter import Parameter
from ros_test_messages import stamp
from sensor_msgs.msg import LaserScan
from test_slam_maps import call, diagnostics, diagnostics_values, good_document, stop
from test_slam_node import Arc, Rig, S

from nuslam.slam_node import MAP_QOS, SlamNode
from nuturtle_ros_common.conversions import range_scan_from_message
from rclpy_harness import refused_at_construction
from turtlelib import (
    GridConfig,
    KeyframeConfig,
    LidarConfig,
    OccupancyGrid,
    ScanKeyframes,
    Transform2D,
    arena_walls,
    simulate_scan,
)
from turtlelib.mapping.grid_map_file import load_grid_map, save_grid_map
from turtlelib.mapping.occupancy_grid import BYTES_PER_CELL

pytestmark = pytest.mark.ros

# a LiDAR far off the axle and turned, so that a grid ignoring the mount is metres off
MOUNT = {"lidar_x": 0.25, "lidar_y": -0.1, "lidar_yaw": 0.5}
T_BODY_SCAN = Transform2D(0.25, -0.1, 0.5)
LIDAR = LidarConfig(noise=0.01, resolution=0.01)
WALLS = arena_walls(3.0, 2.5)
CIRCLES = np.array([[0.8, 0.5, 0.1], [-0.7, -0.4, 0.1]])
SCANS = 7


def scan_message(T_map_body: Transform2D, t_ns: int, rng: np.random.Generator, walls=WALLS) -> LaserScan:
    msg = LaserScan(angle_min=LIDAR.angle_min, angle_increment=LIDAR.angle_increment)
    msg.angle_max = LIDAR.angle_min + (LIDAR.samples - 1) * LIDAR.angle_increment
    msg.range_min, msg.range_max = LIDAR.range_min, LIDAR.range_max
    msg.header.stamp, msg.header.frame_id = stamp(t_ns), "base_scan"
    msg.ranges = simulate_scan(T_map_body @ T_BODY_SCAN, CIRCLES, walls, LIDAR, rng).tolist()
    return msg


def drive_and_scan(
    rig: Rig, T_start: Transform2D | None = None, walls=WALLS
) -> list[tuple[int, Transform2D, LaserScan]]:
    """Drive an arc from ``T_start`` (slam's start pose) with joint_states every 0.2 s and a scan stamped
    half-way between two of them (slam must read its pose between samples) in the world of ``walls``;
    returns (stamp, true body pose, scan) of each."""
    arc = Arc(T_start or Transform2D(), S, vx=0.15, omega=0.8)
    rng = np.random.default_rng(5)
    scans = []
    rig.wheels(S, arc.angles(S))
    for k in range(1, SCANS + 1):
        t_ns = S + k * S // 5
        rig.wheels(t_ns, arc.angles(t_ns))
        t_scan = t_ns - S // 10
        msg = scan_message(arc.pose(t_scan), t_scan, rng, walls)
        rig.scans.publish(msg)
        scans.append((t_scan, arc.pose(t_scan), msg))
    return scans


def latched(rig: Rig, message_type, topic: str):
    """The message a subscriber created now (late) gets on ``topic`` (transient local)."""
    received = []
    rig.helper.create_subscription(message_type, topic, received.append, MAP_QOS)
    assert rig.ros.spin_until(lambda: received, 5.0), f"no {topic} for a late subscriber"
    return received[-1]


def assert_grid(msg: OccupancyGridMsg, expected) -> None:
    """``msg`` is ``expected`` (a turtlelib GridMap) in frame map."""
    assert msg.header.frame_id == "map"
    assert msg.info.resolution == pytest.approx(expected.resolution_m, rel=1e-7)
    assert (msg.info.width, msg.info.height) == (expected.width, expected.height)
    assert (msg.info.origin.position.x, msg.info.origin.position.y) == pytest.approx(
        (expected.origin.x, expected.origin.y), abs=1e-9
    )
    assert np.array_equal(np.array(msg.data, dtype=np.int8), expected.occupancy.ravel())


def test_scans_at_slams_pose_and_the_lidar_mount_make_the_latched_grid(ros):
    rig = Rig(ros, observation_timeout=100.0, **{"grid.publish_period_s": 0.3}, **MOUNT)
    published = []
    rig.helper.create_subscription(OccupancyGridMsg, "map", published.append, MAP_QOS)
    scans = drive_and_scan(rig)
    # the last scan's grid goes out: 0.3 s of scan time after the one before
    assert ros.spin_until(lambda: published and published[-1].header.stamp == stamp(scans[-1][0]), 5.0)
    expected = OccupancyGrid(GridConfig())
    for _, T_map_body, msg in scans:
        expected.insert_scan(range_scan_from_message(msg), T_map_body @ T_BODY_SCAN)
    grid = latched(rig, OccupancyGridMsg, "map")
    assert_grid(grid, expected.grid_map())
    assert [m.header.stamp for m in published] == [stamp(scans[k][0]) for k in (0, 2, 4, 6)], "every 0.3 s"
    assert latched(rig, MapMetaData, "map_metadata") == grid.info
    assert np.count_nonzero(np.array(grid.data) >= 65) > 100, "walls and cylinders"
    assert rig.warnings() == []


def test_scans_past_the_grids_bound_are_mapped_warned_about_and_its_memory_reported(ros):
    # a 2 m grid in a 3 m x 2.5 m arena seen up to 3.5 m: every scan reaches past it
    bound = {"grid.initial_size_m": 2.0, "grid.max_size_m": 2.0, "grid.publish_period_s": 0.3}
    rig = Rig(ros, observation_timeout=100.0, **bound, **MOUNT)
    published = []
    rig.helper.create_subscription(OccupancyGridMsg, "map", published.append, MAP_QOS)
    scans = drive_and_scan(rig)
    assert ros.spin_until(lambda: published and published[-1].header.stamp == stamp(scans[-1][0]), 5.0)
    expected = OccupancyGrid(GridConfig(initial_size_m=2.0, max_size_m=2.0))
    for _, T_map_body, msg in scans:
        assert expected.insert_scan(range_scan_from_message(msg), T_map_body @ T_BODY_SCAN)
    assert_grid(published[-1], expected.grid_map())
    warnings = rig.warnings(at_least=1)
    assert len(warnings) == 1 and "grid.max_size_m = 2.0 m: 1 since the last warning" in warnings[0], warnings
    values = diagnostics_values(rig, "slam: occupancy grid")
    assert (values["scans_mapped"], values["scans_past_bound"]) == (str(SCANS), str(SCANS))
    assert (values["cells"], values["bytes"]) == (str(expected.cells), str(expected.nbytes))
    assert (values["max_cells"], values["max_bytes"]) == ("1600", str(1600 * BYTES_PER_CELL))


def keyframes_grid(scans, base=None):
    """The grid a save renders of ``scans``' keyframes at their true poses, over the saved ``base``."""
    keyframes = ScanKeyframes(KeyframeConfig())
    for t_ns, T_map_body, msg in scans:
        keyframes.offer(t_ns, T_map_body, range_scan_from_message(msg))
    true_poses = {t_ns: T for t_ns, T, _ in scans}
    return keyframes.render(true_poses.get, T_BODY_SCAN, GridConfig(), base).grid_map()


def test_save_writes_the_grid_beside_the_map_and_localization_publishes_it(ros, tmp_path):
    path = tmp_path / "lab.json"
    rig = Rig(ros, observation_timeout=100.0, map_file=str(path), **MOUNT)
    scans = drive_and_scan(rig)
    response = call(rig, "save_map")
    assert response.success and f"to {tmp_path / 'lab.yaml'}" in response.message, response.message
    expected = keyframes_grid(scans)
    saved = load_grid_map(tmp_path / "lab.yaml")
    assert (tmp_path / "lab.pgm").is_file() and not list(tmp_path.glob("*.tmp"))
    assert saved.resolution_m == expected.resolution_m and saved.origin == expected.origin
    # trinary: occupied >= 65, free <= 19, the rest unknown
    trinary = np.where(
        expected.occupancy >= 65, 100, np.where((expected.occupancy >= 0) & (expected.occupancy <= 19), 0, -1)
    )
    assert np.array_equal(saved.occupancy, trinary)
    stop(ros, rig)
    rig = Rig(ros, observation_timeout=100.0, map_file=str(path), mode="localization", **MOUNT)
    assert not any(s.topic_name == "/scan" for s in rig.node.subscriptions), "localization maps no scan"
    assert_grid(latched(rig, OccupancyGridMsg, "map"), saved)


def test_mapping_from_a_saved_map_continues_its_grid_and_saves_both_sessions(ros, tmp_path):
    # a 12 m corridor seen up to 3.5 m: session 1 maps its west end, session 2 (a new node started at the
    # east end, same map_file) the east end
    path, corridor = tmp_path / "lab.json", arena_walls(12.0, 2.5)
    west, east = Transform2D(-4.0, 0.0, 0.0), Transform2D(4.0, 0.0, 0.0)
    rig = Rig(ros, observation_timeout=100.0, map_file=str(path), x0=west.x, **MOUNT)
    drive_and_scan(rig, west, corridor)
    assert call(rig, "save_map").success
    session_1 = load_grid_map(tmp_path / "lab.yaml")
    stop(ros, rig)
    rig = Rig(ros, observation_timeout=100.0, map_file=str(path), x0=east.x, **MOUNT)
    size = f"{session_1.width} x {session_1.height} cell grid"
    assert ros.spin_until(
        lambda: any(log.msg == f"continuing the {size} {tmp_path / 'lab.yaml'}" for log in rig.logs), 5.0
    )
    # published at once: the saved grid, free and occupied cells at the clamps
    start = latched(rig, OccupancyGridMsg, "map")
    assert_grid(start, OccupancyGrid.from_grid_map(session_1, GridConfig()).grid_map())
    second = drive_and_scan(rig, east, corridor)
    response = call(rig, "save_map")
    assert response.success and "over the continued one" in response.message, response.message
    saved = load_grid_map(tmp_path / "lab.yaml")
    save_grid_map(tmp_path / "expected.yaml", keyframes_grid(second, base=session_1))
    expected = load_grid_map(tmp_path / "expected.yaml")
    assert saved.origin == expected.origin and np.array_equal(saved.occupancy, expected.occupancy)
    # both ends: the cells only session 1 saw are as it saved them, session 2's as it mapped them
    res = saved.resolution_m
    west_end = slice(None), slice(0, round((-1.0 - saved.origin.x) / res))
    assert np.array_equal(saved.occupancy[west_end], session_1.occupancy[west_end])
    assert np.count_nonzero(saved.occupancy[west_end] == 100) > 100, "session 1's walls"
    session_2 = keyframes_grid(second)  # session 2's scans alone
    east_cells = session_2.occupancy >= 65
    assert np.count_nonzero(east_cells) > 100, "session 2's walls"
    offset = (
        round((session_2.origin.x - saved.origin.x) / res),
        round((session_2.origin.y - saved.origin.y) / res),
    )
    rows, cols = np.nonzero(east_cells)
    assert np.all(saved.occupancy[rows + offset[1], cols + offset[0]] == 100)


def test_a_grid_without_its_map_file_is_not_continued(ros, tmp_path):
    # a user who deletes the landmark file to map afresh: the grid left beside it is not continued either
    path, corridor = tmp_path / "lab.json", arena_walls(12.0, 2.5)
    rig = Rig(ros, observation_timeout=100.0, map_file=str(path), x0=-4.0, **MOUNT)
    drive_and_scan(rig, Transform2D(-4.0, 0.0, 0.0), corridor)
    assert call(rig, "save_map").success
    stop(ros, rig)
    path.unlink()
    rig = Rig(ros, observation_timeout=100.0, map_file=str(path), x0=4.0, **MOUNT)
    message = f"no map file {path}: the grid {tmp_path / 'lab.yaml'} is not continued"
    assert ros.spin_until(lambda: any(log.msg == message for log in rig.logs), 5.0)
    assert rig.node.grid.base is None


@pytest.mark.parametrize(
    ("edit", "mode", "message"),
    [
        (lambda text: text.replace("resolution: 0.05\n", ""), "localization", "resolution"),
        (lambda text: text.replace("image: lab.pgm", "image: missing.pgm"), "localization", "missing.pgm"),
        (lambda text: text.replace("origin: [", "origin: [nan, "), "localization", "origin"),
        (lambda text: text.replace("image: lab.pgm", "image: missing.pgm"), "mapping", "missing.pgm"),
        (
            lambda text: text.replace("resolution: 0.05", "resolution: 0.1"),
            "mapping",
            "cannot continue mapping it: the saved grid's resolution 0.1 m is not resolution_m = 0.05 m",
        ),
    ],
    ids=["no resolution", "no image", "bad origin", "mapping: no image", "mapping: another resolution"],
)
def test_a_malformed_grid_file_stops_the_node_at_start_up_with_the_reason(ros, tmp_path, edit, mode, message):
    path = tmp_path / "lab.json"
    path.write_text(json.dumps(good_document()))
    text = "image: lab.pgm\nmode: trinary\nresolution: 0.05\norigin: [0.0, 0.0, 0.0]\nnegate: 0\n"
    (tmp_path / "lab.yaml").write_text(edit(text + "occupied_thresh: 0.65\nfree_thresh: 0.196\n"))
    (tmp_path / "lab.pgm").write_bytes(b"P5\n2 1\n255\n\x00\xfe")
    overrides = [Parameter("map_file", value=str(path)), Parameter("mode", value=mode)]
    text = refused_at_construction(
        lambda: SlamNode(context=ros.context, parameter_overrides=overrides), message
    )
    assert str(tmp_path) in text, "the message names the file"


@pytest.mark.parametrize(
    ("name", "value", "message"),
    [
        ("map_file", "lab.yaml", "must not end in .yaml or .pgm"),
        ("map_file", "lab.pgm", "must not end in .yaml or .pgm"),
        ("grid.hit_probability", 0.3, "hit_probability"),
        ("grid.publish_period_s", 0.0, "publish_period_s"),
    ],
)
def test_a_map_file_named_like_the_grid_files_or_a_bad_grid_parameter_stops_the_node(
    ros, tmp_path, name, value, message
):
    value = str(tmp_path / value) if name == "map_file" else value
    overrides = [Parameter(name, value=value)]
    refused_at_construction(lambda: SlamNode(context=ros.context, parameter_overrides=overrides), message)


def test_a_scan_in_an_unknown_frame_is_skipped_with_a_warning(ros):
    rig = Rig(ros, observation_timeout=100.0)
    rig.wheels(S, (0.0, 0.0))
    msg = scan_message(Transform2D(), S // 2, np.random.default_rng(0))
    msg.header.frame_id = "camera"
    rig.scans.publish(msg)
    warnings = rig.warnings(at_least=1)
    assert len(warnings) == 1 and "frame 'camera'" in warnings[0]
    grid_status = diagnostics(rig, "slam: occupancy grid")
    assert grid_status.level == DiagnosticStatus.WARN and "1 skipped" in grid_status.message
    values = diagnostics_values(rig, "slam: occupancy grid")
    assert (values["scans_mapped"], values["scans_skipped"]) == ("0", "1")
