"""The bag replay (nuturtle_tools.replay) with real rclpy nodes, no mocks: a short demo run recorded by the
demo's own recorder (an MCAP bag with ground truth), the same recording written again by rosbags' Writer
into a sqlite3 bag, and a bag without ground truth whose scan is on another topic, each replayed into the
real landmarks and slam nodes.

Every scan of the bag must be played and its landmarks applied by slam (counted against the bag's own
message count), and the replay's SLAM accuracy must be the live run's within 20 % (a replay is the same
input in the same order, so in practice it is the same).
"""

from __future__ import annotations

import json
import socket
import threading
from dataclasses import dataclass
from pathlib import Path

import numpy as np
import pytest
import yaml
from rosbags.rosbag2 import Reader, StoragePlugin, Writer
from rosbags.typesys import Stores, get_typestore

from bag_reading import read_bag
from foxglove_client import FoxgloveClient
from nuturtle_demo.run import BAG_NAME, DemoOptions, run_demo
from nuturtle_eval.metrics import PoseSeries
from nuturtle_tools.bag_source import BagError, BagSource
from nuturtle_tools.foxglove_relay import tf2_msgs_installed
from nuturtle_tools.replay import main
from nuturtle_tools.replay_run import (
    ReplayOptions,
    cut_scan,
    node_parameters_from_file,
    run_replay,
    truth_pose_at,
)
from rclpy_harness import rcl_parameters
from turtlelib import Transform2D
from turtlelib.mapping.grid_map_file import load_grid_map
from turtlelib.mapping.landmark_map import load_map
from turtlelib.mapping.occupancy_grid import BYTES_PER_CELL

pytestmark = [pytest.mark.ros, pytest.mark.slow]

DURATION_S = 12.0
PNG_MAGIC = b"\x89PNG\r\n\x1a\n"
ACCURACY_KEYS = (
    "final_position_error_slam_m", "final_heading_error_slam_rad", "ate_rmse_slam_m", "ate_rmse_odom_m",
    "final_position_error_odom_m", "landmark_rmse_m", "nees_pose_within_95_fraction", "landmarks_mapped",
)  # fmt: skip
# what the Foxglove client watches of the live run
WATCHED = ["/scan", "/slam/odom", "/slam/map"]
# compared with the live run: within 20 % (or 1 mm / 1 mrad, whichever is larger: the errors are mm)
COMPARED = ("final_position_error_slam_m", "ate_rmse_slam_m", "landmark_rmse_m")


def copy_bag(src, dst, storage, rename=None, drop=(), until_ns=None):
    """Write the bag ``src`` again with rosbags' Writer into ``dst`` (``storage``), topics renamed by
    ``rename``, those in ``drop`` left out, messages logged before ``until_ns`` only."""
    rename = rename or {}
    typestore = get_typestore(Stores.ROS2_JAZZY)
    with Reader(src) as reader, Writer(dst, version=9, storage_plugin=storage) as writer:
        out = {}
        for connection in reader.connections:
            if connection.topic in drop:
                continue
            out[connection.id] = writer.add_connection(
                rename.get(connection.topic, connection.topic),
                connection.msgtype,
                typestore=typestore,
                offered_qos_profiles=connection.ext.offered_qos_profiles,
            )
        for connection, t_ns, data in reader.messages():
            if connection.id in out and (until_ns is None or t_ns < until_ns):
                writer.write(out[connection.id], t_ns, data)
    return dst


def bag_count(path, topic):
    with BagSource(path) as source:
        return source.topics[topic].message_count


@dataclass(frozen=True)
class LiveRun:
    out: Path
    metrics: dict
    # a Foxglove client that watched the run (subscribed to WATCHED) until the demo's relay stopped
    client: FoxgloveClient


@pytest.fixture(scope="module")
def live(tmp_path_factory) -> LiveRun:
    """A short demo run, watched live through its Foxglove relay: its output folder (run/ bag,
    config.yaml), its metrics and the client that watched it."""
    out = tmp_path_factory.mktemp("live")
    url: list[str] = []
    started = threading.Event()

    def on_progress(system, sim_time_s):
        if not started.is_set():
            url.append(system.relay.url)
            started.set()

    options = DemoOptions(duration_s=DURATION_S, out_dir=out, progress=False, foxglove=("127.0.0.1", 0))
    results: list = []

    def run() -> None:
        try:
            results.append(run_demo(options, on_progress))
        finally:
            started.set()

    demo = threading.Thread(target=run)
    demo.start()
    try:
        assert started.wait(60.0) and url, "the demo did not start"
        client = FoxgloveClient(url[0])
        assert client.wait_for(lambda: set(WATCHED) <= set(client.channels))
        client.subscribe(WATCHED)
        client.wait_for(lambda: False, timeout_s=120.0)  # until the demo ends and the server goes
    finally:
        demo.join(180.0)
    assert client.closed and results, "the demo did not finish"
    return LiveRun(out, results[0].metrics.as_dict(), client)


@pytest.mark.parametrize("form", ["mcap directory", "sqlite3 directory"])
def test_replay_applies_every_scan_and_matches_the_live_accuracy(live, tmp_path, form):
    live_out, live_metrics = live.out, live.metrics
    bag = {
        "mcap directory": lambda: live_out / BAG_NAME,
        "sqlite3 directory": lambda: copy_bag(
            live_out / BAG_NAME, tmp_path / "sqlite", StoragePlugin.SQLITE3
        ),
    }[form]()
    out = tmp_path / "replay"
    result = run_replay(ReplayOptions(bag=bag, out_dir=out, params=live_out / "config.yaml", progress=False))

    metrics = json.loads((out / "metrics.json").read_text())
    assert metrics == json.loads(json.dumps(result.metrics))
    assert metrics["storage"] == ("sqlite3" if form.startswith("sqlite3") else "mcap")
    scans = bag_count(bag, "/scan")
    assert scans >= 0.95 * 5 * DURATION_S
    assert metrics["scans_played"] == metrics["messages_played"]["/scan"] == scans
    assert metrics["observation_arrays_received"] == metrics["observation_arrays_applied"] == scans
    assert metrics["observation_arrays_skipped"] == metrics["observation_arrays_pending"] == 0
    for topic in ("/joint_states", "/odom", "/nusim/ground_truth"):
        assert metrics["messages_played"][topic] == bag_count(bag, topic), topic
    # the recorded SLAM outputs of the input were not played: the new ones are slam's own, one per scan
    assert "/landmarks" not in metrics["messages_played"]
    assert metrics["slam_outputs_recorded"]["/landmarks"] == scans
    # one pose per joint_states, and again at the newest one for each scan registered after it (a LiDAR's
    # messages come after the wheels')
    poses = metrics["slam_outputs_recorded"]["/slam/odom"]
    assert bag_count(bag, "/joint_states") <= poses <= bag_count(bag, "/joint_states") + scans
    # slam's grid: its memory at the end, well inside its bound in the demo's 5 m world
    assert metrics["slam_grid_bytes"] == metrics["slam_grid_cells"] * BYTES_PER_CELL > 0
    assert metrics["slam_grid_max_bytes"] == 2000**2 * BYTES_PER_CELL
    assert metrics["slam_grid_scans_past_bound"] == 0

    assert result.accuracy
    for key in ACCURACY_KEYS:
        assert key in metrics, key
    for key in COMPARED:
        assert metrics[key] == pytest.approx(live_metrics[key], rel=0.2, abs=1e-3), key
    assert metrics["final_heading_error_slam_rad"] == pytest.approx(
        live_metrics["final_heading_error_slam_rad"], rel=0.2, abs=1e-3
    )
    assert metrics["landmarks_mapped"] == live_metrics["landmarks_mapped"]
    assert metrics["landmarks_duplicate"] == metrics["landmarks_spurious"] == 0

    for name in ("trajectory.png", "errors.png", "covariance.png", "grid.png"):
        assert (out / name).read_bytes().startswith(PNG_MAGIC), name
    for name in ("estimate.tum", "odometry.tum", "reference.tum"):
        rows = np.loadtxt(out / name, comments="#")
        assert rows.shape[1] == 8 and rows.shape[0] > 10 and np.all(np.diff(rows[:, 0]) > 0), name
    # slam's grid against the scans at the true poses: the arena's walls and cylinders, found
    assert metrics["grid_found_fraction"] > 0.95 and metrics["grid_unexplained_fraction"] < 0.05
    assert metrics["rpe_pairs"] > 0 and metrics["rpe_translation_slam_m"] < metrics["rpe_translation_odom_m"]
    assert np.count_nonzero(load_grid_map(out / "map.yaml").occupancy == 100) > 100, "map_server's pair"
    assert load_map(out / "map.json").n_landmarks == metrics["landmarks_mapped"], "a map slam can load"
    with BagSource(out / "slam") as outputs:
        assert outputs.storage == "mcap"
        assert {"/landmarks", "/slam/odom", "/slam/path", "/slam/map"} <= set(outputs.topics)
        assert not {"/scan", "/joint_states", "/odom", "/clock"} & set(outputs.topics)
        assert outputs.topics["/landmarks"].message_count == scans


def test_a_cut_scan_reads_no_return_beyond_the_shorter_range():
    from sensor_msgs.msg import LaserScan

    msg = cut_scan(LaserScan(range_max=40.0, ranges=[1.0, 3.4, 3.6, 80.0]), 3.5)
    assert msg.range_max == 3.5 and list(msg.ranges) == [1.0, pytest.approx(3.4), np.inf, np.inf]
    assert list(cut_scan(msg, 10.0).ranges) == list(msg.ranges) and msg.range_max == 3.5
    with pytest.raises(ValueError, match="max_range_m"):
        ReplayOptions(bag=Path("bag"), max_range_m=0.0)


def test_a_truth_that_starts_after_the_motion_is_moved_back_to_it_by_the_odometry():
    """A reference made at the scans (Radish's) starts after the robot has moved: slam's start pose is the
    truth's first pose moved back by the odometry's motion since the first motion sample."""
    truth = PoseSeries(np.array([10.0, 11.0]), np.array([[1.0, 2.0, 0.5], [1.5, 2.0, 0.5]]))
    # the odometry (its own frame) drives 1 m along its x and turns by 0.2 rad from t = 2 s to t = 10 s
    odom = PoseSeries(
        np.array([2.0, 6.0, 14.0]), np.array([[0.0, 0.0, 0.0], [0.5, 0.0, 0.1], [1.5, 0.0, 0.3]])
    )
    # at t = 10 s the odometry reads (1.0, 0, 0.2): the truth there, (1, 2, 0.5), minus that motion
    expected = Transform2D(1.0, 2.0, 0.5) @ Transform2D(1.0, 0.0, 0.2).inverse()
    np.testing.assert_allclose(
        truth_pose_at(truth, 2_000_000_000, odom).as_array(), expected.as_array(), atol=1e-12
    )
    # inside the truth's span, or without odometry covering the gap: the truth, clamped to its span
    np.testing.assert_allclose(truth_pose_at(truth, 10_500_000_000, odom).as_array(), [1.25, 2.0, 0.5])
    np.testing.assert_allclose(truth_pose_at(truth, 1_000_000_000, odom).as_array(), [1.0, 2.0, 0.5])
    np.testing.assert_allclose(truth_pose_at(truth, 2_000_000_000).as_array(), [1.0, 2.0, 0.5])


def test_a_bag_directory_and_its_single_mcap_file_read_the_same(live):
    """The replay reads its input through BagSource alone: the demo's run/ and its run.mcap without
    metadata.yaml give the same topics and the same messages in the same order."""
    directory = live.out / BAG_NAME
    with BagSource(directory) as whole, BagSource(directory / f"{BAG_NAME}.mcap") as single:
        assert whole.storage == single.storage == "mcap"
        assert whole.topics == single.topics
        assert (whole.start_ns, whole.end_ns) == (single.start_ns, single.end_ns)
        assert list(whole.messages()) == list(single.messages())


@pytest.mark.parametrize("storage", [StoragePlugin.MCAP, StoragePlugin.SQLITE3])
def test_a_bag_directory_named_like_a_ros1_file_reads_as_the_rosbag2_directory_it_is(live, tmp_path, storage):
    """rosbags' AnyReader takes a path ending in .bag for a ROS 1 file; a rosbag2 directory so named reads
    as any other (a ROS 1 .bag file is still read as ROS 1: test_an_unreadable_path_is_a_clear_error)."""
    until_ns = int(2e9)
    named = copy_bag(live.out / BAG_NAME, tmp_path / "x.bag", storage, until_ns=until_ns)
    with BagSource(live.out / BAG_NAME) as original, BagSource(named) as source:
        assert source.storage == storage.name.lower()
        expected = [message for message in original.messages() if message.log_time_ns < until_ns]
        assert list(source.messages()) == expected
        assert {name: topic.message_count for name, topic in source.topics.items()} == {
            name: sum(message.topic == name for message in expected) for name in original.topics
        }


def test_remapped_scan_without_ground_truth_gives_counts_but_no_accuracy(live, tmp_path, capsys):
    """The CLI as a user runs it: the scan recorded as /lidar/scan (played as scan), no ground truth."""
    live_out = live.out
    bag = copy_bag(
        live_out / BAG_NAME, tmp_path / "renamed", StoragePlugin.MCAP, rename={"/scan": "/lidar/scan"},
        drop=("/nusim/ground_truth", "/landmarks", "/slam/odom"), until_ns=int(6e9),
    )  # fmt: skip
    out = tmp_path / "replay"
    code = main([str(bag), "--out", str(out), "--scan-topic", "/lidar/scan", "--no-progress"])
    stdout = capsys.readouterr().out
    assert code == 0, stdout
    metrics = json.loads((out / "metrics.json").read_text())
    scans = bag_count(bag, "/lidar/scan")
    assert scans >= 25
    assert metrics["messages_played"]["/lidar/scan"] == metrics["scans_played"] == scans
    assert metrics["observation_arrays_applied"] == scans
    assert "/nusim/ground_truth" not in metrics["messages_played"]
    for key in ACCURACY_KEYS:
        assert key not in metrics, key
    assert (out / "trajectory.png").read_bytes().startswith(PNG_MAGIC)
    assert not (out / "errors.png").exists()
    assert f"| messages played, /lidar/scan | {scans} |" in stdout
    # what slam made of it, though nothing judges it: its mode, its map (the saved file's landmarks), the
    # loops it closed, its slip recovery; no landmark called spurious
    mapped = len(load_map(out / "map.json").ids)
    assert metrics["slam_mode"] == "mapping" and metrics["map_landmarks"] == mapped > 0
    held, relocalized = (metrics[f"slam_{k}"] for k in ("scans_held", "relocalizations"))
    assert "slam_loops_closed" not in metrics  # loop closure is off by default
    assert (
        f"slam: mapping, {mapped} landmarks mapped, loop closure off, {relocalized} relocalizations "
        f"after slip, {held} scans held"
    ) in stdout
    assert "spurious" not in stdout
    written = sorted(p.name + ("/" if p.is_dir() else "") for p in out.iterdir())
    assert f"outputs in {out}/: {' '.join(written)}" in stdout.splitlines()

    # without --scan-topic the bag has no /scan: a clear error, exit code 2
    code = main([str(bag), "--out", str(tmp_path / "again"), "--no-progress"])
    error = capsys.readouterr().err
    assert code == 2
    assert "no topic /scan" in error and "--scan-topic" in error


@pytest.mark.parametrize(
    "kind", ["missing", "folder without metadata.yaml", "not a bag", "corrupt .mcap", "corrupt ROS 1 .bag"]
)
def test_an_unreadable_path_is_a_clear_error(tmp_path, capsys, kind):
    path = {
        "missing": tmp_path / "nowhere",
        "folder without metadata.yaml": tmp_path,
        "not a bag": tmp_path / "notes.txt",
        "corrupt .mcap": tmp_path / "broken.mcap",
        "corrupt ROS 1 .bag": tmp_path / "broken.bag",
    }[kind]
    if kind == "not a bag":
        path.write_text("hello")
    if kind == "corrupt .mcap":
        path.write_bytes(b"\x89MCAP0\r\n" + b"\x00" * 64)
    if kind == "corrupt ROS 1 .bag":
        path.write_bytes(b"#ROSBAG V2.0\n" + b"\x00" * 64)
    with pytest.raises(BagError):
        BagSource(path).open()
    code = main([str(path), "--out", str(tmp_path / "out"), "--no-progress"])
    error = capsys.readouterr().err
    assert code == 2
    assert error.startswith("error: ") and str(path) in error
    assert not (tmp_path / "out").exists()


def test_smoothing_without_the_slam_node_is_a_clear_error(live, tmp_path, capsys):
    argv = [
        str(live.out / BAG_NAME),
        "--out",
        str(tmp_path / "out"),
        "--no-progress",
        "--play-only",
        "--smooth",
    ]
    assert main(argv) == 2
    assert "smoothing needs the slam node" in capsys.readouterr().err
    assert not (tmp_path / "out").exists()


def test_play_only_feeds_nodes_in_another_process(live, tmp_path, ros):
    """--play-only: just the player, here in a child process, heard over DDS by a node of this one: every
    reliable joint_states message arrives (acknowledged before the next), with /clock."""
    import subprocess
    import sys

    from nav_msgs.msg import Odometry
    from rclpy.qos import qos_profile_sensor_data
    from rosgraph_msgs.msg import Clock
    from sensor_msgs.msg import JointState, LaserScan

    live_out = live.out
    bag = copy_bag(live_out / BAG_NAME, tmp_path / "short", StoragePlugin.MCAP, until_ns=int(4e9))
    listener = ros.node("listener")
    received = {"joint_states": 0, "clock": 0}
    listener.create_subscription(JointState, "joint_states", lambda _: received.__setitem__(
        "joint_states", received["joint_states"] + 1), 1000)  # fmt: skip
    listener.create_subscription(Clock, "/clock", lambda _: received.__setitem__(
        "clock", received["clock"] + 1), 1000)  # fmt: skip
    # a subscriber on every played topic: the player starts once they all match
    listener.create_subscription(LaserScan, "scan", lambda _: None, qos_profile_sensor_data)
    for topic in ("odom", "nusim/ground_truth"):
        listener.create_subscription(Odometry, topic, lambda _: None, 1000)
    player = subprocess.Popen(
        [sys.executable, "-P", "-m", "nuturtle_tools.replay", str(bag), "--play-only", "--rate", "4",
         "--out", str(tmp_path / "out"), "--no-progress"],
        stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True,
    )  # fmt: skip
    try:
        ros.spin_until(lambda: player.poll() is not None, timeout_s=60.0)
        ros.spin_for(0.3)
    finally:
        player.kill() if player.poll() is None else None
    output = player.stdout.read()
    assert player.returncode == 0, output
    metrics = json.loads((tmp_path / "out" / "metrics.json").read_text())
    played = metrics["messages_played"]["/joint_states"]
    assert played == bag_count(bag, "/joint_states") >= 70
    assert received["joint_states"] == played
    assert received["clock"] >= played
    assert "observation_arrays_applied" not in metrics


def test_a_demo_recording_is_replayed_with_the_parameters_of_its_run(tmp_path):
    from nuturtle_tools.replay import recording_params

    bag = tmp_path / "out" / "run"
    bag.mkdir(parents=True)
    (bag / "run.mcap").write_bytes(b"")
    assert recording_params(bag) is None and recording_params(bag / "run.mcap") is None
    (tmp_path / "out" / "config.yaml").write_text("slam:\n  ros__parameters: {}\n")
    assert recording_params(bag) == tmp_path / "out" / "config.yaml"
    assert recording_params(bag / "run.mcap") == tmp_path / "out" / "config.yaml"


def free_port() -> int:
    with socket.socket() as probe:
        probe.bind(("127.0.0.1", 0))
        return probe.getsockname()[1]


def test_a_replay_is_watched_live_with_the_played_topics_and_the_new_outputs(live, tmp_path):
    """`--foxglove` on the replay: the played inputs (the bag's own bytes) and slam's new outputs are
    relayed, and the live error against the played ground truth is there for the plots."""
    live_out = live.out
    bag = copy_bag(live_out / BAG_NAME, tmp_path / "short", StoragePlugin.MCAP, until_ns=int(5e9))
    port = free_port()
    code: list[int] = []
    replay = threading.Thread(
        target=lambda: code.append(
            main(
                [
                    str(bag),
                    "--out",
                    str(tmp_path / "out"),
                    "--params",
                    str(live_out / "config.yaml"),
                    "--rate",
                    "2",
                    "--foxglove",
                    f"127.0.0.1:{port}",
                    "--no-progress",
                ]
            )
        )  # fmt: skip
    )
    replay.start()
    try:
        client = FoxgloveClient(f"ws://127.0.0.1:{port}", timeout_s=60.0)
        watched = ["/scan", "/slam/odom", "/demo_monitor/slam_error"]
        assert client.wait_for(lambda: set(watched) <= set(client.channels), timeout_s=30.0)
        client.subscribe(watched)
        client.wait_for(lambda: False, timeout_s=60.0)  # until the replay ends and the server goes
    finally:
        replay.join(120.0)
    assert code == [0] and client.closed
    assert {"/clock", "/joint_states", "/odom", "/nusim/ground_truth", "/landmarks", "/slam/map"} <= set(
        client.channels
    )
    with BagSource(bag) as source:
        played_scans = {message.data for message in source.messages(["/scan"])}
    assert len(client.messages["/scan"]) >= 5
    assert all(received.data in played_scans for received in client.messages["/scan"])
    assert client.decode(client.messages["/slam/odom"][-1]).header.frame_id == "map"
    errors = [client.decode(received).data for received in client.messages["/demo_monitor/slam_error"]]
    assert len(errors) >= 20
    assert all(0.0 <= e[0] < 0.05 and abs(e[1]) < 0.05 for e in errors)


def test_a_running_demo_is_watched_live_and_the_messages_are_the_recorded_ones(live):
    """Connect to the demo's relay, list the channels, subscribe to /scan, /slam/odom and /slam/map and
    decode what arrives: each one is, byte for byte, a message the demo's recorder wrote, and decodes
    (rosbags, from the channel's schema) to the values rclpy decodes from the recording."""
    client = live.client
    watched = WATCHED
    if not tf2_msgs_installed():
        # the 3D view's transforms, from what the demo knows
        assert {"/tf", "/tf_static"} <= set(client.channels)
    bag = read_bag(live.out / BAG_NAME)
    # the recording's topics are all advertised, with the recording's schema text
    recorded = set(bag.channels) - {"/parameter_events", "/rosout"}
    assert recorded <= set(client.channels)
    for topic in watched:
        assert client.channels[topic]["schema"] == bag.schemas[bag.channel_types[topic]].data.decode()
    assert client.server_info["capabilities"] == ["time"]
    for topic in watched:
        relayed = client.messages[topic]
        assert len(relayed) >= 5, topic
        # what the recorder heard, decoded by rclpy, by its CDR bytes
        recorded = {r.data: m for r, m in zip(bag.topic_records(topic), bag.decoded(topic), strict=True)}
        for received in relayed:
            assert received.data in recorded, f"{topic}: a message the recorder never heard"
            _assert_same(topic, client.decode(received), recorded[received.data])
    # log times in simulation time: within the run, never decreasing
    log_times = [m.log_time_ns for m in client.messages["/slam/odom"]]
    assert log_times == sorted(log_times) and 0 < log_times[-1] <= (DURATION_S + 1) * 10**9


def _assert_same(topic: str, relayed, recorded) -> None:
    if topic == "/scan":
        np.testing.assert_array_equal(relayed.ranges, np.asarray(recorded.ranges))
        assert (relayed.header.frame_id, relayed.header.stamp.sec, relayed.header.stamp.nanosec) == (
            recorded.header.frame_id, recorded.header.stamp.sec, recorded.header.stamp.nanosec,
        )  # fmt: skip
    elif topic == "/slam/odom":
        p, q = relayed.pose.pose.position, recorded.pose.pose.position
        assert (p.x, p.y) == (q.x, q.y)
        np.testing.assert_array_equal(relayed.pose.covariance, np.asarray(recorded.pose.covariance))
    else:
        assert [(m.ns, m.id, m.pose.position.x, m.pose.position.y) for m in relayed.markers] == [
            (m.ns, m.id, m.pose.position.x, m.pose.position.y) for m in recorded.markers
        ]


def test_the_model_option_reaches_slam_and_an_unknown_one_is_refused(live, tmp_path, capsys):
    """--model waffle on a recording without its run's parameters: slam runs the Waffle's constants."""
    bag = copy_bag(live.out / BAG_NAME, tmp_path / "short", StoragePlugin.MCAP, until_ns=int(3e9))
    out = tmp_path / "replay"
    assert main([str(bag), "--out", str(out), "--model", "waffle", "--no-progress"]) == 0
    slam = yaml.safe_load((out / "config.yaml").read_text())["slam"]["ros__parameters"]
    assert (slam["model"], slam["track_width"], slam["lidar_x"]) == ("waffle", 0.287, -0.064)
    capsys.readouterr()
    with pytest.raises(SystemExit) as exit_info:
        main([str(bag), "--out", str(tmp_path / "again"), "--model", "burgr"])
    assert exit_info.value.code == 2
    errors = [line for line in capsys.readouterr().err.splitlines() if "error:" in line]
    assert errors == [
        "python -m nuturtle_tools.replay: error: argument --model: invalid choice: 'burgr' "
        "(choose from 'burger', 'waffle', 'waffle_pi')"
    ]


@pytest.mark.ros
def test_the_replay_reads_a_params_file_as_rcl_gives_it_to_each_node(ros, tmp_path):
    """The replay's own reading of a params file against rcl's: wildcard and namespaced keys, in any
    namespace (the nodes' config files are keyed ``/**/slam``)."""
    entries = {
        "/**": {"a": 1, "b": 1},
        "/**/slam": {"b": 2, "c": 2},
        "slam": {"c": 3, "d": 3},
        "tb3_0/slam": {"d": 4, "e": 4},
        "/tb3_0/*": {"e": 5, "f": 5},
        "/other/slam": {"g": 6},
        "landmarks": {"h": 7},
    }
    path = tmp_path / "params.yaml"
    path.write_text(yaml.safe_dump({key: {"ros__parameters": values} for key, values in entries.items()}))
    for namespace in ("", "tb3_0", "fleet/tb3_1"):
        rcl = rcl_parameters(ros.context, "slam", ["--ros-args", "--params-file", str(path)], namespace)
        for own in ("use_sim_time", "start_type_description_service"):  # every node's, none from the file
            rcl.pop(own, None)
        assert node_parameters_from_file(path, "slam", namespace) == rcl, namespace
    assert set(node_parameters_from_file(path, "slam", "tb3_0")) == {"a", "b", "c", "d", "e", "f"}
