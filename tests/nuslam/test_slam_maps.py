"""slam's maps that last (real rclpy): ~/save_map writes the map file, map_file loads it at start-up,
mode localization keeps it fixed, initialpose relocalizes, ~/reset starts again; bad map files stop the
node at start-up with a clear message.

Expected values come from turtlelib (`turtlelib.mapping.landmark_map.load_map`, the true landmarks), never
from the node.
"""

from __future__ import annotations

import json
import math
from pathlib import Path

import numpy as np
import pytest
from diagnostic_msgs.msg import DiagnosticArray, DiagnosticStatus
from geometry_msgs.msg import PoseWithCovarianceStamped
from ros_test_messages import cylinder_array, stamp
from std_srvs.srv import Trigger
from test_slam_node import LANDMARKS, R_WHEEL, Rig, S, close_pose, mapped, pose_of, relative

from nuslam.slam_node import SlamNode
from nuturtle_ros_common.conversions import pose_from_transform
from rclpy_harness import refused_at_construction
from turtlelib import Transform2D
from turtlelib.mapping.landmark_map import load_map

pytestmark = pytest.mark.ros


def diagnostics(rig: Rig, name: str) -> DiagnosticStatus:
    """slam's first status ``name`` on /diagnostics."""
    arrays: list[DiagnosticArray] = []
    rig.helper.create_subscription(DiagnosticArray, "/diagnostics", arrays.append, 10)
    assert rig.ros.spin_until(lambda: any(s.name == name for a in arrays for s in a.status), 5.0), name
    return next(s for a in arrays for s in a.status if s.name == name)


def diagnostics_values(rig: Rig, name: str = "slam: filter") -> dict[str, str]:
    """The values of slam's status ``name``, as /diagnostics gets them."""
    return {pair.key: pair.value for pair in diagnostics(rig, name).values}


def call(rig: Rig, service: str) -> Trigger.Response:
    client = rig.helper.create_client(Trigger, f"slam/{service}")
    assert rig.ros.spin_until(client.service_is_ready, 5.0), f"no slam/{service}"
    future = client.call_async(Trigger.Request())
    assert rig.ros.spin_until(future.done, 5.0)
    return future.result()


def initial_pose(T: Transform2D, covariance_xyt, frame_id: str = "map") -> PoseWithCovarianceStamped:
    msg = PoseWithCovarianceStamped()
    msg.header.frame_id = frame_id
    msg.header.stamp = stamp(0)
    msg.pose.pose = pose_from_transform(T)
    P6 = np.zeros((6, 6))
    P6[np.ix_([0, 1, 5], [0, 1, 5])] = covariance_xyt
    msg.pose.covariance = P6.ravel().tolist()
    return msg


def drive_and_observe(rig: Rig, t0_ns: int, T_start: Transform2D, steps: int, extra=None) -> Transform2D:
    """Drive straight 5 cm per 0.5 s from ``T_start`` (true pose), observing the landmarks (and ``extra``
    ones) after each step; returns the true pose at the end."""
    dphi = 0.05 / R_WHEEL
    T, t_ns = T_start, t0_ns
    landmarks = {**LANDMARKS, **(extra or {})}
    rig.wheels(t_ns, (0.0, 0.0))
    for k in range(1, steps + 1):
        t_ns += S // 2
        T = T @ Transform2D(0.05, 0.0, 0.0)
        rig.wheels(t_ns, (k * dphi, k * dphi))
        rig.observe(cylinder_array("base_footprint", t_ns, relative(T, landmarks)))
    return T


def mapped_then_saved(ros, tmp_path: Path) -> tuple[Path, Rig]:
    path = tmp_path / "maps" / "lab.json"
    rig = Rig(ros, association="known", map_file=str(path))
    drive_and_observe(rig, 10 * S, Transform2D(), 4)
    response = call(rig, "save_map")
    assert response.success, response.message
    assert response.message.startswith(f"saved {len(LANDMARKS)} landmarks to {path} and ")
    return path, rig


def stop(ros, rig: Rig) -> None:
    ros.executor.remove_node(rig.node)
    rig.node.destroy_node()


def test_save_map_writes_every_landmark_with_its_joint_covariance_and_the_parameters(ros, tmp_path):
    path, rig = mapped_then_saved(ros, tmp_path)
    saved = load_map(path)
    assert saved.equals(rig.node.slam.landmark_map("map", saved.stamp_ns, saved.parameters))
    assert saved.frame_id == "map" and saved.ids.tolist() == sorted(LANDMARKS)
    np.testing.assert_allclose(saved.xy, [LANDMARKS[i] for i in sorted(LANDMARKS)], atol=1e-9)
    assert saved.covariance.shape == (6, 6) and np.any(saved.covariance[0, 2:] != 0.0), "joint, not marginal"
    assert saved.stamp_ns > 10 * S
    assert saved.parameters["association"] == "known" and saved.parameters["map_file"] == str(path)
    document = json.loads(path.read_text())
    assert document["version"] == 1 and document["format"] == "nuturtle_slam_map"
    assert not list(path.parent.glob("*.tmp")), "no temporary file left"


def test_localization_keeps_the_loaded_map_bit_for_bit_and_adds_no_landmark(ros, tmp_path):
    path, rig = mapped_then_saved(ros, tmp_path)
    stop(ros, rig)
    saved = load_map(path)
    rig = Rig(ros, association="known", map_file=str(path), mode="localization")
    assert rig.node.slam.landmark_map("map", saved.stamp_ns, saved.parameters).equals(saved), (
        "loaded as saved"
    )
    # a landmark the map does not hold is seen all along: counted, never added
    T = drive_and_observe(rig, 100 * S, Transform2D(), 6, extra={40: (0.8, 0.9)})
    assert close_pose(rig.odoms[-1], T, 1e-6), (pose_of(rig.odoms[-1]), T)
    assert set(mapped(rig.maps[-1])) == set(LANDMARKS)
    assert rig.node.slam.landmark_map("map", saved.stamp_ns, saved.parameters).equals(saved), "fixed map"
    assert diagnostics_values(rig)["observations_unmapped"] == "6"
    # saving in localization writes the same landmarks, bit for bit
    response = call(rig, "save_map")
    assert response.success
    again = load_map(path)
    assert np.array_equal(again.xy, saved.xy) and np.array_equal(again.covariance, saved.covariance)
    assert np.array_equal(again.ids, saved.ids)


def test_initialpose_relocalizes_against_the_loaded_map(ros, tmp_path):
    path, rig = mapped_then_saved(ros, tmp_path)
    stop(ros, rig)
    rig = Rig(ros, association="known", map_file=str(path), mode="localization")
    T_true = Transform2D(0.5, 0.3, 0.5)
    rig.wheels(50 * S, (0.0, 0.0))
    # the user's guess: 5 cm and 0.05 rad off the truth, with that uncertainty
    guess = T_true @ Transform2D(0.05, -0.03, 0.05)
    rig.initial.publish(initial_pose(guess, np.diag([0.1**2, 0.1**2, 0.1**2])))
    rig.ros.spin_for(0.2)
    assert close_pose(rig.wheels(50 * S + S // 5, (0.0, 0.0)), guess, 1e-9), "the guess is the pose"
    # observations from the true pose pull the estimate onto it
    t_ns = 50 * S + S // 5
    for _ in range(5):
        t_ns += S // 10
        rig.wheels(t_ns, (0.0, 0.0))
        rig.observe(cylinder_array("base_footprint", t_ns, relative(T_true)))
    x, y, theta = pose_of(rig.wheels(t_ns + S // 10, (0.0, 0.0)))
    assert math.hypot(x - T_true.x, y - T_true.y) < 0.005 and abs(theta - T_true.theta) < 0.005
    assert rig.warnings() == []


@pytest.mark.parametrize(
    ("covariance", "frame_id", "reason"),
    [
        (np.diag([0.01, 0.01, 0.0]), "map", "must be positive definite"),
        (np.diag([0.01, -0.01, 0.01]), "map", "must be positive definite"),
        (np.zeros((3, 3)), "map", "must be positive definite"),
        (np.array([[0.01, 0.02, 0.0], [0.0, 0.01, 0.0], [0.0, 0.0, 0.01]]), "map", "must be symmetric"),
        (np.diag([0.01, math.nan, 0.01]), "map", "must be finite"),
        (np.diag([0.01, 0.01, 0.01]), "odom", "not the map frame"),
    ],
)
def test_an_initialpose_that_cannot_be_a_pose_estimate_is_refused_with_a_warning(
    ros, covariance, frame_id, reason
):
    rig = Rig(ros, observation_timeout=100.0)
    rig.wheels(S, (0.0, 0.0))
    rig.initial.publish(initial_pose(Transform2D(1.0, 1.0, 1.0), covariance, frame_id))
    warnings = rig.warnings(at_least=1)
    assert len(warnings) == 1 and "initialpose skipped" in warnings[0] and reason in warnings[0]
    assert close_pose(rig.wheels(2 * S, (0.0, 0.0)), Transform2D())


def test_reset_goes_back_to_the_start_pose_and_the_loaded_map(ros, tmp_path):
    path, rig = mapped_then_saved(ros, tmp_path)
    response = call(rig, "reset")
    assert response.success and "0 landmarks" in response.message
    assert len(rig.node.slam.landmark_ids) == 0, "no map was loaded: reset empties it"
    stop(ros, rig)
    rig = Rig(ros, association="known", map_file=str(path), x0=0.2)
    drive_and_observe(rig, 100 * S, Transform2D(0.2, 0.0, 0.0), 2, extra={40: (0.8, 0.9)})
    assert 40 in rig.node.slam.landmark_ids.tolist(), "mapping goes on from the loaded map"
    standing = (2 * 0.05 / R_WHEEL,) * 2
    rig.wheels(101 * S + S // 2, standing)  # the filter catches up with the motion (max_observation_delay)
    response = call(rig, "reset")
    assert response.success and f"{len(LANDMARKS)} landmarks" in response.message
    saved, now = load_map(path), rig.node.slam.landmark_map("map", 0)
    assert np.array_equal(now.ids, saved.ids) and np.array_equal(now.xy, saved.xy)
    assert np.array_equal(now.covariance, saved.covariance)
    assert close_pose(rig.wheels(102 * S, standing), Transform2D(0.2, 0.0, 0.0))


def test_save_map_without_a_map_file_says_so(ros):
    rig = Rig(ros)
    response = call(rig, "save_map")
    assert not response.success and "map_file is not set" in response.message


def good_document() -> dict:
    return {
        "format": "nuturtle_slam_map",
        "version": 1,
        "frame_id": "map",
        "stamp_ns": 5,
        "landmarks": [{"id": 0, "x": 1.0, "y": 2.0}],
        "covariance": [[1e-4, 0.0], [0.0, 1e-4]],
        "parameters": {},
    }


@pytest.mark.parametrize(
    ("edit", "message"),
    [
        (lambda text: text[: len(text) // 2], "JSON"),
        (lambda text: text.replace('"version": 1', '"version": 2'), "version"),
        (lambda text: text.replace('"x": 1.0', '"x": NaN'), "NaN"),
        (lambda text: text.replace('"frame_id": "map"', '"frame_id": "world"'), "frame"),
    ],
    ids=["truncated", "wrong version", "non-finite", "another frame"],
)
def test_a_bad_map_file_stops_the_node_at_start_up_with_a_clear_message(ros, tmp_path, edit, message):
    path = tmp_path / "bad.json"
    path.write_text(edit(json.dumps(good_document(), indent=2)))
    from rclpy.parameter import Parameter

    overrides = [Parameter("map_file", value=str(path))]
    text = refused_at_construction(
        lambda: SlamNode(context=ros.context, parameter_overrides=overrides), message
    )
    assert str(path) in text


def test_localization_without_a_saved_grid_warns_once_that_it_maps_a_fresh_grid(ros, tmp_path):
    # only the landmark map copied (the old recipe of docs/maps.md): the grid was mapped anew, silently
    path = tmp_path / "lab.json"
    path.write_text(json.dumps(good_document()))
    rig = Rig(ros, map_file=str(path), mode="localization")
    warnings = rig.warnings(at_least=1)
    assert len(warnings) == 1, warnings
    assert f"no {tmp_path / 'lab.yaml'} beside map_file" in warnings[0] and "fresh grid" in warnings[0]
    assert any(s.topic_name == "/scan" for s in rig.node.subscriptions), "the scans are mapped"
    assert not (tmp_path / "lab.yaml").exists()


@pytest.mark.parametrize(("map_file", "message"), [("missing.json", "missing.json"), ("", "needs map_file")])
def test_localization_without_a_map_file_stops_the_node(ros, tmp_path, map_file, message):
    # an empty map_file ran localization in an empty map: dead reckoning, silently
    from rclpy.parameter import Parameter

    path = str(tmp_path / map_file) if map_file else ""
    overrides = [Parameter("map_file", value=path), Parameter("mode", value="localization")]
    refused_at_construction(lambda: SlamNode(context=ros.context, parameter_overrides=overrides), message)


def test_smooth_saved_map_saves_the_smoothed_run_and_starts_again_at_a_reset(ros, tmp_path):
    path = tmp_path / "lab.json"
    rig = Rig(ros, association="known", map_file=str(path), smooth_saved_map=True)
    drive_and_observe(rig, 10 * S, Transform2D(), 6)
    response = call(rig, "save_map")
    assert (
        response.success
        and f"saved {len(LANDMARKS)} landmarks (smoothed run; the filter has {len(LANDMARKS)}) to {path}"
        in response.message
    )
    saved = load_map(path)
    # what the node's smoother gives for its run (deterministic), with the covariance of the information
    assert saved.equals(rig.node.smooth_run().landmark_map("map", saved.stamp_ns, saved.parameters))
    assert saved.ids.tolist() == sorted(LANDMARKS) and saved.parameters["smooth_saved_map"] is True
    np.testing.assert_allclose(saved.xy, [LANDMARKS[i] for i in sorted(LANDMARKS)], atol=1e-6)
    assert np.all(np.linalg.eigvalsh(saved.covariance) > 0.0)
    history = rig.node.timeline.history
    assert history.n_scans == 6
    assert call(rig, "reset").success
    assert history.n_scans == 0 and np.array_equal(history.start_pose, [0.0, 0.0, 0.0])


def test_smooth_saved_map_in_localization_stops_the_node(ros, tmp_path):
    from rclpy.parameter import Parameter

    path, rig = mapped_then_saved(ros, tmp_path)
    stop(ros, rig)
    overrides = [
        Parameter("map_file", value=str(path)),
        Parameter("mode", value="localization"),
        Parameter("smooth_saved_map", value=True),
    ]
    refused_at_construction(
        lambda: SlamNode(context=ros.context, parameter_overrides=overrides),
        "smooth_saved_map needs mode mapping",
    )
