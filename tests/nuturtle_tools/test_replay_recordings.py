"""The bag replay on a real third-party recording: a TurtleBot3 Burger in ROBOTIS' Gazebo `turtlebot3_world`
(tests/data/tb3_gazebo_burger, tests/data/README.md), replayed into the real landmarks and slam nodes, as a
rosbag2 bag and as a ROS 1 bag written from it by rosbags' own converter (rosbag1 writer) and read by
rosbags' rosbag1 reader.

What a TurtleBot3 user does with such a recording: the Burger's defaults, wheel motion from /joint_states
and Gazebo's /odom (the model's true pose) as the truth, or the odometry as the motion, on bags with both
topics or only /odom. The true cylinders come from nusim's model of the same world
(nusim/config/turtlebot3_world.yaml).
"""

from __future__ import annotations

import json
from pathlib import Path

import pytest
from rosbags.convert import convert
from rosbags.rosbag2 import StoragePlugin, Writer
from rosbags.typesys import Stores, get_typestore

from nuturtle_tools.bag_source import BagSource
from nuturtle_tools.replay import main, motion_gate_warning, no_landmarks_hint
from turtlelib.mapping.grid_map_file import load_grid_map
from turtlelib.mapping.landmark_map import load_map

pytestmark = [pytest.mark.ros, pytest.mark.slow]

ROOT = Path(__file__).resolve().parents[2]
RECORDING = Path(__file__).resolve().parents[1] / "data" / "tb3_gazebo_burger"
WORLD = ROOT / "nusim" / "config" / "turtlebot3_world.yaml"
SCANS = 138
ODOMS = 810


def to_ros1(src: Path, dst: Path) -> Path:
    """The bag ``src`` written as the ROS 1 bag ``dst`` by rosbags' converter (its rosbag1 Writer)."""
    convert(
        [src], dst, dst_storage="sqlite3", dst_version=8, compress=None, compress_mode="file",
        default_typestore=None, typestore=None, exclude_topics=[], include_topics=[], exclude_msgtypes=[],
        include_msgtypes=[],
    )  # fmt: skip
    return dst


def rewrite(src: Path, dst: Path, drop=(), until_ns=None, change=None) -> Path:
    """The bag ``src`` written again by rosbags' Writer (MCAP): the topics in ``drop`` left out, messages
    logged before ``until_ns`` only, and ``change(topic, msg)`` (if given) applied to each message."""
    typestore = get_typestore(Stores.ROS2_JAZZY)
    with BagSource(src) as source, Writer(dst, version=9, storage_plugin=StoragePlugin.MCAP) as writer:
        out = {
            name: writer.add_connection(
                name, topic.type_name, typestore=typestore, offered_qos_profiles=list(topic.offered_qos)
            )
            for name, topic in source.topics.items()
            if name not in drop
        }
        start_ns = source.start_ns
        for message in source.messages(out):
            if until_ns is not None and message.log_time_ns - start_ns >= until_ns:
                break
            data = message.data
            if change is not None:
                msg = typestore.deserialize_cdr(data, message.type_name)
                change(message.topic, msg)
                data = typestore.serialize_cdr(msg, message.type_name)
            writer.write(out[message.topic], message.log_time_ns, data)
    return dst


def replay(capsys, bag: Path, out: Path, *options: str) -> tuple[int, dict, str, str]:
    code = main([str(bag), "--out", str(out), "--no-progress", *options])
    captured = capsys.readouterr()
    metrics = json.loads((out / "metrics.json").read_text()) if code == 0 else {}
    return code, metrics, captured.out, captured.err


def test_a_ros1_bag_reads_as_the_rosbag2_recording_it_was_written_from(tmp_path):
    """rosbags' rosbag1 reader and ROS 1 -> ROS 2 conversion give back, byte for byte, the CDR of every
    message of the recording the .bag was written from, in the same order."""
    ros1 = to_ros1(RECORDING, tmp_path / "burger.bag")
    with BagSource(ros1) as bag1, BagSource(RECORDING) as bag2:
        assert (bag1.storage, bag2.storage) == ("rosbag1", "mcap")
        assert {n: (t.type_name, t.message_count) for n, t in bag1.topics.items()} == {
            n: (t.type_name, t.message_count) for n, t in bag2.topics.items()
        }
        assert list(bag1.messages()) == list(bag2.messages())


def test_a_gazebo_recording_maps_every_cylinder_in_range_against_its_odom_truth(tmp_path, capsys):
    """The Burger's defaults, joint_states motion, /odom played as both odometry and truth (one bag topic,
    two roles): every cylinder that came within range (and in sight) mapped once, none spurious,
    ATE <= 2 cm; the table without the demo's targets (not a nusim recording). Smoothed at the end
    (--smooth): the same landmarks, the map a file slam loads, no worse than the filter."""
    code, metrics, stdout, err = replay(
        capsys, RECORDING, tmp_path / "out", "--truth-topic", "/odom", "--params", str(WORLD), "--smooth"
    )
    assert code == 0, err
    assert metrics["messages_played"] == {"/joint_states": ODOMS, "/odom": ODOMS, "/scan": SCANS}
    assert metrics["scans_received_by_landmarks"] == SCANS
    assert metrics["scans_refused_by_landmarks"] == 0
    assert metrics["observation_arrays_applied"] == SCANS
    # the odometry role was played too: its metrics are there (Gazebo's /odom is the truth itself)
    assert metrics["final_position_error_odom_m"] == pytest.approx(0.0, abs=1e-9)
    assert metrics["landmarks_true"] == 9
    assert metrics["landmarks_in_range"] >= 3
    assert metrics["landmarks_mapped"] == metrics["landmarks_in_range"]
    assert metrics["landmarks_in_range_unmapped"] == 0
    assert metrics["landmarks_duplicate"] == metrics["landmarks_spurious"] == 0
    assert metrics["ate_rmse_slam_m"] <= 0.02
    assert not metrics["nusim_recording"]
    assert "✓" not in stdout and "✗" not in stdout
    assert "the demo's targets do not apply" in stdout
    assert "no landmarks" not in stdout
    smoothed = metrics["smoothed"]
    assert smoothed["landmarks_mapped"] == metrics["landmarks_mapped"]
    assert smoothed["landmarks_duplicate"] == smoothed["landmarks_spurious"] == 0
    assert smoothed["ate_rmse_slam_m"] <= metrics["ate_rmse_slam_m"]
    assert smoothed["landmark_rmse_m"] <= metrics["landmark_rmse_m"]
    assert smoothed["nees_pose_mean"] is None, "smoothed poses have no covariance"
    assert smoothed["landmarks_merged_by_smoother"] == smoothed["landmarks_created_by_smoother"] == 0
    saved = load_map(tmp_path / "out" / "smoothed" / "map.json")
    assert saved.n_landmarks == metrics["landmarks_mapped"] and saved.parameters["smooth_saved_map"] is True
    for name in ("trajectory.png", "errors.png", "covariance.png", "grid.png"):
        assert (tmp_path / "out" / "smoothed" / name).read_bytes()[:4] == b"\x89PNG", name
    # the grid of the same keyframes at the smoothed poses: the same size of map
    filtered, smoothed_grid = (load_grid_map(tmp_path / "out" / d / "map.yaml") for d in (".", "smoothed"))
    assert abs(smoothed_grid.width - filtered.width) <= 2 and abs(smoothed_grid.height - filtered.height) <= 2
    assert "| ATE RMSE (m) |" in stdout and "smoothed/" in stdout


@pytest.mark.parametrize("topics", ["joint_states and odom", "odom only, ROS 1 .bag"])
def test_odom_motion_replays_bags_with_and_without_joint_states(tmp_path, capsys, topics):
    """--motion-source odom: slam moves on the recorded odometry; nothing waits for a joint_states
    subscriber, and a bag without /joint_states plays (its first 10 s here), also as a ROS 1 bag."""
    drop = ("/joint_states",) if topics.startswith("odom only") else ()
    bag = rewrite(RECORDING, tmp_path / "bag", drop=drop, until_ns=10 * 10**9)
    if topics.endswith("ROS 1 .bag"):
        bag = to_ros1(bag, tmp_path / "odom_only.bag")
    with BagSource(bag) as source:
        scans = source.topics["/scan"].message_count
    code, metrics, stdout, err = replay(capsys, bag, tmp_path / "out", "--motion-source", "odom")
    assert code == 0, err
    assert metrics["motion_source"] == "odom"
    assert "/joint_states" not in metrics["messages_played"]
    assert metrics["observation_arrays_applied"] == metrics["scans_played"] == scans >= 45
    assert metrics["map_landmarks"] >= 2
    assert "motion from odom" in stdout
    assert metrics["storage"] == ("rosbag1" if topics.endswith("ROS 1 .bag") else "mcap")


def test_a_bag_without_joint_states_names_the_odom_motion_source(tmp_path, capsys):
    bag = rewrite(RECORDING, tmp_path / "bag", drop=("/joint_states",), until_ns=2 * 10**9)
    code, _, _, err = replay(capsys, bag, tmp_path / "out")
    assert code == 2
    assert "no topic /joint_states" in err and "--motion-source odom" in err


def test_odom_as_both_motion_and_truth_says_so(tmp_path, capsys):
    """The same topic as the motion and the truth is played (both roles), with a note that the accuracy
    then compares slam with its own input."""
    bag = rewrite(RECORDING, tmp_path / "bag", until_ns=3 * 10**9)
    code, metrics, stdout, err = replay(
        capsys, bag, tmp_path / "out", "--motion-source", "odom", "--truth-topic", "/odom"
    )
    assert code == 0, err
    assert "ate_rmse_slam_m" in metrics
    assert any("also slam's motion" in note for note in metrics["notes"])
    assert "note: the truth topic /odom is also slam's motion" in stdout


def test_scans_the_landmarks_node_refuses_are_named_as_the_reason_for_no_landmarks(tmp_path, capsys):
    """The recording with every scan's layout made self-contradicting (angle_max short of what the beams
    span): the landmarks node refuses each, and the summary says so instead of blaming a missing node."""

    def contradict(topic, msg):
        if topic == "/scan":
            msg.angle_max = msg.angle_min + 1.0

    bag = rewrite(RECORDING, tmp_path / "bag", until_ns=4 * 10**9, change=contradict)
    code, metrics, stdout, err = replay(capsys, bag, tmp_path / "out")
    assert code == 0, err
    scans = metrics["scans_played"]
    assert scans >= 15
    assert metrics["scans_received_by_landmarks"] == metrics["scans_refused_by_landmarks"] == scans
    assert metrics["map_landmarks"] == 0
    assert f"the landmarks node refused all {scans} scans it received, the last because: " in stdout
    assert "angle_max" in metrics["last_scan_refusal"]


def _counts(played, received, refused, mapped=0, topic="landmarks"):
    return {
        "observation_topic": topic,
        "map_landmarks": mapped,
        "scans_played": played,
        "scans_received_by_landmarks": received,
        "scans_refused_by_landmarks": refused,
    }


@pytest.mark.parametrize(
    ("counts", "expected"),
    [
        (_counts(10, 10, 0, mapped=3), None),
        (_counts(10, 0, 0, topic="fake_sensor"), None),
        (_counts(0, 0, 0), "the bag's scan topic has no messages"),
        (_counts(10, 0, 0), "none of the 10 scans played reached the landmarks node"),
        (_counts(10, 10, 10), "the landmarks node refused all 10 scans it received"),
        (_counts(10, 10, 4), "the landmarks node took 6 of 10 scans but slam mapped no cylinder"),
    ],
)
def test_the_no_landmarks_hint_tells_the_cases_apart(counts, expected):
    hint = no_landmarks_hint(counts)
    if expected is None:
        assert hint is None
    else:
        assert hint is not None and expected in hint


def test_refused_motion_samples_are_warned_about_with_the_last_reason_and_what_to_set():
    counts = {"motion_source": "odom", "slam_motion_samples_refused": 0, "slam_motion_restarts": 0}
    assert motion_gate_warning(counts) is None
    reason = "value 0 moved 0.3 in 0.100 s, more than 0.2 (...); max rate 0.447 m/s"
    counts.update(slam_motion_samples_refused=40, slam_motion_restarts=13, slam_motion_last_refusal=reason)
    counts.update(slam_motion_silences_bridged=2, slam_motion_longest_bridge_s=3.4)
    warning = motion_gate_warning(counts)
    assert warning is not None and "refused 40 odom samples" in warning and "13 times" in warning
    assert "bridged 2 silences" in warning and "3.4 s" in warning
    assert reason in warning and "max_linear_speed" in warning


def test_a_bad_params_file_is_one_error_line_and_the_output_folder_untouched(tmp_path, capsys):
    out = tmp_path / "out"
    out.mkdir()
    (out / "metrics.json").write_text("previous")
    params = tmp_path / "params.yaml"
    params.write_text("slam: [\n")
    assert main([str(RECORDING), "--params", str(params), "--out", str(out), "--no-progress"]) == 2
    (line,) = capsys.readouterr().err.splitlines()
    assert line.startswith(f"error: cannot read params file {params}: while parsing a flow node")
    assert sorted(p.name for p in tmp_path.iterdir()) == ["out", "params.yaml"]
    assert (out / "metrics.json").read_text() == "previous"
