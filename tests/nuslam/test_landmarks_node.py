"""landmarks in process with real rclpy: LiDAR scans in, `landmarks` and `~/clusters` MarkerArrays out.

Scans are LDS-01 scans (360 beams of 1 deg, 0.12-3.5 m, frame base_scan) ray cast by
`turtlelib.simulate_scan` with 1 cm noise and 1 cm resolution (seeded), of two cylinders at known places
inside a square arena, everything given in the sensor frame; and Gazebo's scans as recorded by a third
party (the first 2 s of tests/data/tb3_gazebo_burger: tests/data/README.md), decoded by
rclpy from the recorded bytes, against the world's cylinders seen from the recording's true /odom.
"""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np
import pytest
from diagnostic_msgs.msg import DiagnosticArray, DiagnosticStatus
from nav_msgs.msg import Odometry
from rclpy.parameter import Parameter
from rclpy.qos import qos_profile_sensor_data
from rclpy.serialization import deserialize_message
from ros_test_messages import node_inputs_matched, scan_message, stamp_ns
from rosbags.rosbag2 import Reader
from sensor_msgs.msg import LaserScan
from visualization_msgs.msg import Marker, MarkerArray

from nusim.nusim_node import NusimNode
from nuslam.landmarks_node import LandmarksNode
from nuturtle_ros_common.markers import marker_noise
from rclpy_harness import matched, record_rosout, refused_at_construction, warnings_of
from turtlelib import DetectorConfig, LidarConfig, Transform2D, arena_walls, simulate_scan

pytestmark = pytest.mark.ros

LDS01 = LidarConfig(noise=0.01, resolution=0.01)
# [x, y, r] in base_scan (m): one small ahead-left, one larger behind-left
CYLINDERS = np.array([[1.0, 0.3, 0.05], [-0.6, 1.1, 0.08]])
# the arena's walls, seen from a sensor off its centre
WALLS = (Transform2D(0.4, -0.3, 0.2).inverse() @ arena_walls(5.0, 5.0).reshape(-1, 2)).reshape(-1, 4)
GREEN = (0.1, 0.8, 0.2, 1.0)
CENTRE_TOL_M = 0.015
RADIUS_TOL_M = 0.01
T0_NS = 1_700_000_000_123_456_789  # an epoch-sized stamp with every nanosecond digit used
# The first 2 s of a TurtleBot3 Burger in Gazebo's turtlebot3_world (tests/data/README.md): nine cylinders of
# radius 0.15 m at x, y in {-1.1, 0, 1.1} (world frame, m); /odom is the true pose of base_footprint, and
# base_scan sits 0.032 m behind it
GAZEBO_RECORDING = Path(__file__).resolve().parents[1] / "data" / "tb3_gazebo_burger"
EXCERPT_NS = 2_000_000_000
TB3_WORLD_CYLINDERS = np.array([(x, y) for x in (-1.1, 0.0, 1.1) for y in (-1.1, 0.0, 1.1)])
TB3_WORLD_RADIUS_M = 0.15
T_FOOTPRINT_SCAN = Transform2D(-0.032, 0.0, 0.0)


def scan_ranges(circles=CYLINDERS, walls=WALLS, seed: int = 7) -> np.ndarray:
    return simulate_scan(Transform2D(), circles, walls, LDS01, np.random.default_rng(seed))


def cylinders_of(array: MarkerArray) -> list[Marker]:
    return [marker for marker in array.markers if marker.action == Marker.ADD]


class Rig:
    """landmarks plus a helper node publishing scans and recording both outputs and /rosout."""

    def __init__(self, ros, **parameters) -> None:
        self.ros = ros
        overrides = [Parameter(name, value=value) for name, value in parameters.items()]
        self.node = ros.add(LandmarksNode(context=ros.context, parameter_overrides=overrides))
        helper = ros.node("landmarks_test_helper")
        self.landmarks: list[MarkerArray] = []
        self.clusters: list[MarkerArray] = []
        self.logs = record_rosout(helper)
        self.scan = helper.create_publisher(LaserScan, "scan", qos_profile_sensor_data)
        endpoints = [
            self.scan,
            helper.create_subscription(MarkerArray, "landmarks", self.landmarks.append, 10),
            helper.create_subscription(MarkerArray, "landmarks/clusters", self.clusters.append, 10),
        ]
        assert ros.spin_until(lambda: matched(*endpoints) and node_inputs_matched(self.node), 10.0)

    def send(self, msg: LaserScan) -> MarkerArray:
        """Publish a scan and return the `landmarks` array it causes (and wait for its clusters)."""
        count = len(self.landmarks)
        self.scan.publish(msg)
        assert self.ros.spin_until(lambda: len(self.landmarks) > count, 5.0), "no landmarks"
        wanted = msg.header.stamp
        assert self.ros.spin_until(
            lambda: any(c.markers[0].header.stamp == wanted for c in self.clusters), 5.0
        )
        return self.landmarks[-1]

    def warnings(self, at_least: int = 0) -> list[str]:
        """The node's warnings so far (waiting up to 2 s for ``at_least`` of them, then 0.1 s for more)."""
        self.ros.spin_until(lambda: len(warnings_of(self.logs, "landmarks")) >= at_least, 2.0)
        self.ros.spin_for(0.1)
        return warnings_of(self.logs, "landmarks")


def assert_header(array: MarkerArray, t_ns: int, frame_id: str = "base_scan") -> None:
    assert array.markers, "an array always holds at least its DELETEALL"
    for marker in array.markers:
        assert marker.header.frame_id == frame_id
        assert stamp_ns(marker.header.stamp) == t_ns


def test_two_cylinders_give_a_deleteall_then_a_cylinder_each_at_its_centre_with_its_diameter(ros):
    rig = Rig(ros)
    array = rig.send(scan_message(T0_NS, scan_ranges()))
    assert_header(array, T0_NS)
    assert array.markers[0].action == Marker.DELETEALL
    found = cylinders_of(array)
    assert len(array.markers) == 1 + len(found)
    assert len(found) == 2, "the walls are no cylinders"
    assert sorted(marker.id for marker in found) == [0, 1]
    assert len({(marker.ns, marker.id) for marker in found}) == 2
    # pair each true cylinder with the nearest detection
    for x, y, r in CYLINDERS:
        marker = min(found, key=lambda m: math.hypot(m.pose.position.x - x, m.pose.position.y - y))
        assert marker.type == Marker.CYLINDER
        assert math.hypot(marker.pose.position.x - x, marker.pose.position.y - y) < CENTRE_TOL_M
        assert marker.scale.x == marker.scale.y
        assert marker.scale.x == pytest.approx(2 * r, abs=2 * RADIUS_TOL_M)
        assert marker.scale.z > 0.0 and marker.pose.position.z == pytest.approx(0.5 * marker.scale.z)
        assert marker.pose.orientation.w == 1.0
        assert (marker.color.r, marker.color.g, marker.color.b, marker.color.a) == pytest.approx(GREEN)
    assert rig.warnings() == []


def test_each_cylinder_carries_the_detector_s_range_bearing_noise_in_its_text(ros):
    """range_std / bearing_std are THE observation noise of a detection: on the wire with each one."""
    rig = Rig(ros, bearing_std=0.05)
    found = cylinders_of(rig.send(scan_message(T0_NS, scan_ranges())))
    assert len(found) == 2
    R = np.diag([DetectorConfig().range_std ** 2, 0.05**2])
    np.testing.assert_array_equal(marker_noise(MarkerArray(markers=found)), [R, R])


def test_a_scan_in_another_frame_keeps_its_frame_and_each_scan_gets_its_own_array(ros):
    rig = Rig(ros)
    first = rig.send(scan_message(T0_NS, scan_ranges(), frame_id="robot/base_scan"))
    # the second scan: only the far cylinder, moved
    moved = np.array([[-0.2, -1.5, 0.08]])
    second = rig.send(
        scan_message(T0_NS + 200_000_000, scan_ranges(moved, seed=8), frame_id="robot/base_scan")
    )
    assert_header(first, T0_NS, "robot/base_scan")
    assert_header(second, T0_NS + 200_000_000, "robot/base_scan")
    assert len(cylinders_of(first)) == 2
    (only,) = cylinders_of(second)
    assert (only.pose.position.x, only.pose.position.y) == pytest.approx((-0.2, -1.5), abs=CENTRE_TOL_M)
    assert second.markers[0].action == Marker.DELETEALL, "clears the first scan's two cylinders"


def gazebo_recording() -> tuple[list[LaserScan], list[tuple[int, Transform2D]]]:
    """The excerpt's scans (rclpy messages of the recorded bytes) and true poses ``(stamp_ns,
    T_world_footprint)`` from /odom."""
    scans, poses = [], []
    with Reader(GAZEBO_RECORDING) as reader:
        end_ns = reader.start_time + EXCERPT_NS
        for connection, log_ns, data in reader.messages():
            if log_ns >= end_ns:
                break
            if connection.topic == "/scan":
                scans.append(deserialize_message(data, LaserScan))
            elif connection.topic == "/odom":
                odom = deserialize_message(data, Odometry)
                q, p = odom.pose.pose.orientation, odom.pose.pose.position
                poses.append((stamp_ns(odom.header.stamp), Transform2D(p.x, p.y, 2 * math.atan2(q.z, q.w))))
    return scans, poses


def test_gazebo_scans_of_a_third_party_recording_are_used_and_show_its_cylinders(ros):
    # issue 30: every scan of the stock Gazebo LiDAR (360 beams from 0 to 6.28 rad, the last repeating the
    # first) was refused as "more than one turn"; now the last beam is dropped and the scan used
    scans, poses = gazebo_recording()
    assert len(scans) == 10 and len(poses) == 55
    rig = Rig(ros)
    errors_m, radii_m = [], []
    for scan in scans:
        assert (len(scan.ranges), scan.angle_min, scan.angle_max) == (360, 0.0, pytest.approx(6.28))
        t_ns = stamp_ns(scan.header.stamp)
        array = rig.send(scan)
        assert_header(array, t_ns)
        # the true pose nearest the scan (/odom at 30 Hz): its timing error moves far points by up to 2 cm
        _, T_world_footprint = min(poses, key=lambda pose: abs(pose[0] - t_ns))
        T_world_scan = T_world_footprint @ T_FOOTPRINT_SCAN
        found = cylinders_of(array)
        nearest, distance_m = nearest_cylinders(found, T_world_scan, TB3_WORLD_CYLINDERS)
        assert len(found) >= 5, "five or six cylinders in range in these 2 s"
        assert len(set(nearest.tolist())) == len(found), "each cylinder once"
        # a detection is spurious unless its centre lies inside a cylinder
        assert distance_m.max() < TB3_WORLD_RADIUS_M, "no spurious cylinder"
        errors_m.extend(distance_m)
        radii_m.extend(0.5 * marker.scale.x for marker in found)
        # every point of the first 359 beams drawn once: beam 359 (at 6.28 rad) is dropped
        (clusters,) = [c for c in rig.clusters if stamp_ns(c.markers[0].header.stamp) == t_ns]
        ranges = np.asarray(scan.ranges[:359])
        assert sum(len(m.points) for m in clusters.markers[1:]) == np.count_nonzero(np.isfinite(ranges))
    assert np.median(errors_m) < 0.02, "centres within 2 cm (the pose's timing included)"
    assert np.median(radii_m) == pytest.approx(TB3_WORLD_RADIUS_M, abs=0.01)
    assert rig.warnings() == []


# nusim's world for the LiDAR models: three of our cylinders (0.038 m) and three of turtlebot3_world's
# (0.15 m) around the robot at the origin, inside walls 6 m away, beyond every LiDAR's reach somewhere
SIM_WORLD = {
    "obstacles.x": [0.8, -0.7, 0.2, 1.5, -1.6, -0.3],
    "obstacles.y": [0.3, 0.6, -0.9, 1.2, -1.0, 1.8],
    "obstacles.r": [0.038] * 3 + [0.15] * 3,
    "arena_x_length": 12.0,
    "arena_y_length": 12.0,
    "realtime_factor": 10.0,
}
SCANS_CHECKED = 5


@pytest.mark.parametrize(
    ("lidar_model", "no_return", "range_max"),
    [("lds01", 0.0, 3.5), ("lds02", math.nan, 100.0), ("gazebo", math.inf, 3.5)],
)
def test_in_nusim_every_turtlebot3_lidar_shows_the_cylinders(ros, lidar_model, no_return, range_max):
    overrides = {**SIM_WORLD, "lidar_model": lidar_model}
    nusim = ros.add(
        NusimNode(
            context=ros.context, parameter_overrides=[Parameter(k, value=v) for k, v in overrides.items()]
        )
    )
    rig = Rig(ros)
    helper = ros.node("landmarks_nusim_helper")
    scans: list[LaserScan] = []
    subscription = helper.create_subscription(LaserScan, "scan", scans.append, qos_profile_sensor_data)
    assert ros.spin_until(lambda: matched(subscription), 5.0)

    def answered() -> list[tuple[LaserScan, MarkerArray]]:
        """nusim's scans with the landmarks array that answered each."""
        arrays = {stamp_ns(array.markers[0].header.stamp): array for array in rig.landmarks}
        return [(scan, arrays[t]) for scan in scans if (t := stamp_ns(scan.header.stamp)) in arrays]

    assert ros.spin_until(lambda: len(answered()) >= SCANS_CHECKED, 10.0)
    # the robot stands at its start: every scan is cast from the same pose
    config = nusim.simulation.config
    T_world_scan = config.arena.T_world_start @ config.robot.T_body_scan
    circles = nusim.simulation.circles
    large = set(np.flatnonzero(circles[:, 2] == 0.15).tolist())
    seen, errors_m = np.zeros(len(circles), dtype=int), []
    for scan, array in answered()[:SCANS_CHECKED]:
        nearest, distance_m = nearest_cylinders(cylinders_of(array), T_world_scan, circles[:, :2])
        assert (distance_m < circles[nearest, 2]).all(), "no spurious cylinder"
        assert large <= set(nearest.tolist()), "turtlebot3_world's cylinders in every scan"
        seen[nearest] += 1
        errors_m.extend(distance_m)
        # what the driver writes: the model's range limit and no-return value
        ranges = np.asarray(scan.ranges)
        assert scan.range_max == pytest.approx(range_max)
        assert np.count_nonzero(np.isnan(ranges) if math.isnan(no_return) else ranges == no_return) > 0
    assert (seen > 0).all(), f"every cylinder seen in {SCANS_CHECKED} scans: {seen}"
    assert np.median(errors_m) < 0.015
    beam_counts = {len(scan.ranges) for scan, _ in answered()}
    assert len(beam_counts) > 1 if lidar_model == "lds02" else beam_counts == {360}
    assert rig.warnings() == []


def nearest_cylinders(
    found: list[Marker], T_world_scan: Transform2D, centres_world: np.ndarray
) -> tuple[np.ndarray, np.ndarray]:
    """For each detected cylinder (markers in the scan frame): the nearest true centre's index and the
    distance to it (m)."""
    p_scan = np.array([(m.pose.position.x, m.pose.position.y) for m in found]).reshape(-1, 2)
    p_world = T_world_scan @ p_scan
    distance = np.hypot(*(p_world[:, None, :] - centres_world[None]).transpose(2, 0, 1))
    nearest = distance.argmin(axis=1)
    return nearest, distance[np.arange(len(found)), nearest]


@pytest.mark.parametrize(
    "ranges",
    [
        pytest.param(np.zeros(LDS01.samples), id="no returns"),
        pytest.param(scan_ranges(circles=np.empty((0, 3))), id="walls only"),
    ],
)
def test_a_scan_without_cylinders_gives_an_array_with_only_the_deleteall(ros, ranges):
    rig = Rig(ros)
    array = rig.send(scan_message(T0_NS, ranges))
    assert_header(array, T0_NS)
    assert [marker.action for marker in array.markers] == [Marker.DELETEALL]
    assert rig.warnings() == []


def test_clusters_are_points_markers_green_on_the_cylinders_and_grey_elsewhere(ros):
    rig = Rig(ros)
    rig.send(scan_message(T0_NS, scan_ranges()))
    (clusters,) = rig.clusters
    assert_header(clusters, T0_NS)
    assert clusters.markers[0].action == Marker.DELETEALL
    points = clusters.markers[1:]
    assert len(points) >= 4, "two cylinders and the walls (split where cylinders hide them)"
    assert all(marker.type == Marker.POINTS and marker.action == Marker.ADD for marker in points)
    assert sorted(marker.id for marker in points) == list(range(len(points)))
    green = [m for m in points if (m.color.r, m.color.g, m.color.b, m.color.a) == pytest.approx(GREEN)]
    grey = [m for m in points if m not in green]
    assert len(green) == 2 and len(grey) == len(points) - 2
    for marker in grey:
        assert marker.color.g < 0.7 and marker.color.r == pytest.approx(marker.color.g), "grey"
    for x, y, r in CYLINDERS:
        # the green cluster on this cylinder: its points lie on the circle
        near = [m for m in green if math.hypot(m.points[0].x - x, m.points[0].y - y) < 2 * r]
        assert len(near) == 1
        xy = np.array([(p.x, p.y) for p in near[0].points])
        assert len(xy) >= 4
        assert np.abs(np.hypot(xy[:, 0] - x, xy[:, 1] - y) - r).max() < 0.03
    # every point of the scan is drawn exactly once
    assert sum(len(m.points) for m in points) == int(np.count_nonzero(scan_ranges()))
    for marker in grey:
        xy = np.array([(p.x, p.y) for p in marker.points])
        for x, y, r in CYLINDERS:
            assert np.hypot(xy[:, 0] - x, xy[:, 1] - y).min() > r + 0.05, "wall points, far from cylinders"


BAD_SCANS = {
    # kind: layout overrides, part of the warning
    "NaN angle_increment": ({"angle_increment": math.nan}, "angle_increment"),
    "zero angle_increment": ({"angle_increment": 0.0}, "angle_increment"),
    "infinite angle_min": ({"angle_min": -math.inf}, "angle_min"),
    "range_min == range_max": ({"range_min": 3.5}, "range_min < range_max"),
    "range_min > range_max": ({"range_min": 4.0}, "range_min < range_max"),
    "NaN range_max": ({"range_max": math.nan}, "range_max must be a finite number"),
    "no beams": ({"ranges": []}, "non-empty"),
    # layouts that contradict themselves (the issue: 85 of 85 detections were phantoms)
    "angle_increment negated": ({"angle_increment": -LDS01.angle_increment}, "contradicts itself"),
    "angle_increment doubled": ({"angle_increment": 2 * LDS01.angle_increment}, "contradicts itself"),
    "angle_min 1e10": ({"angle_min": 1e10}, "more than a turn from 0"),
    "720 ranges for 360 beams": ({"ranges": [1.0] * 720}, "contradicts itself"),
    "angle_max halved": ({"angle_max": math.pi}, "contradicts itself"),
    "intensities for half the beams": ({"intensities": [1.0] * 180}, "180 intensities for 360 ranges"),
}


@pytest.mark.parametrize("kind", BAD_SCANS)
def test_a_bad_scan_is_skipped_with_a_warning_and_the_next_good_scan_is_processed(ros, kind):
    layout, reason = BAD_SCANS[kind]
    rig = Rig(ros)
    rig.send(scan_message(T0_NS, scan_ranges()))
    bad = scan_message(
        T0_NS + 100_000_000, scan_ranges(), **{k: v for k, v in layout.items() if k != "ranges"}
    )
    if "ranges" in layout:
        bad.ranges = layout["ranges"]
    rig.scan.publish(bad)
    # a topic keeps its order: the next array answers this good scan
    after = rig.send(scan_message(T0_NS + 200_000_000, scan_ranges(seed=9)))
    assert_header(after, T0_NS + 200_000_000)
    assert len(cylinders_of(after)) == 2
    stamps = [stamp_ns(array.markers[0].header.stamp) for array in rig.landmarks]
    assert stamps == [T0_NS, T0_NS + 200_000_000], "nothing published for the bad scan"
    assert [stamp_ns(array.markers[0].header.stamp) for array in rig.clusters] == stamps
    warnings = rig.warnings(at_least=1)
    assert len(warnings) == 1
    assert "scan skipped" in warnings[0] and reason in warnings[0]


def test_a_max_radius_below_both_cylinders_detects_nothing(ros):
    rig = Rig(ros, max_radius=0.04)
    array = rig.send(scan_message(T0_NS, scan_ranges()))
    assert [marker.action for marker in array.markers] == [Marker.DELETEALL]
    (clusters,) = rig.clusters
    assert all(marker.color.g < 0.7 for marker in clusters.markers[1:]), "every cluster grey"
    assert rig.node.config.max_radius == 0.04


def test_a_max_radius_between_the_cylinders_keeps_only_the_small_one(ros):
    rig = Rig(ros, max_radius=0.065, cluster_threshold=0.08)
    (only,) = cylinders_of(rig.send(scan_message(T0_NS, scan_ranges())))
    x, y, r = CYLINDERS[0]
    assert (only.pose.position.x, only.pose.position.y) == pytest.approx((x, y), abs=CENTRE_TOL_M)
    assert only.scale.x == pytest.approx(2 * r, abs=2 * RADIUS_TOL_M)
    assert rig.node.config.cluster_threshold == 0.08


def test_the_default_parameters_are_the_detector_defaults(ros):
    node = ros.add(LandmarksNode(context=ros.context))
    assert node.config == DetectorConfig()
    assert node.get_parameter("min_points").value == DetectorConfig().min_points


def invalid(name: str, value, message: str):
    """A parametrize row: the parameter ``name`` set to an invalid ``value``, and part of the error."""
    return pytest.param(Parameter(name, value=value), message, id=f"{name}={value!r}")


@pytest.mark.parametrize(
    "parameter, message",
    [
        invalid("min_radius", 0.3, "min_radius < max_radius"),
        invalid("min_points", 2, "min_points"),
        invalid("cluster_threshold", -0.1, "cluster_threshold"),
        invalid("max_inscribed_angle", 4.0, "max_inscribed_angle"),
        invalid("cluster_threshold", "far", "cluster_threshold must be of type float"),
    ],
)
def test_an_invalid_parameter_raises_value_error_at_construction(ros, parameter, message):
    refused_at_construction(
        lambda: LandmarksNode(context=ros.context, parameter_overrides=[parameter]), message
    )


def test_diagnostics_are_an_error_when_no_scan_arrives(ros):
    ros.add(LandmarksNode(context=ros.context))
    helper = ros.node("landmarks_diagnostics_helper")
    arrays: list[DiagnosticArray] = []
    subscription = helper.create_subscription(DiagnosticArray, "/diagnostics", arrays.append, 10)
    assert ros.spin_until(lambda: matched(subscription), 5.0)
    assert ros.spin_until(
        lambda: bool(arrays) and any(s.level == DiagnosticStatus.ERROR for s in arrays[-1].status), 6.0
    )
    statuses = {s.name: s for s in arrays[-1].status}
    assert set(statuses) == {"landmarks: scan", "landmarks: detector"}
    assert "nothing yet on scan" in statuses["landmarks: scan"].message
    assert statuses["landmarks: detector"].level == DiagnosticStatus.OK


def test_diagnostics_tell_refused_scans_from_missing_ones_and_say_why(ros):
    # scans arrive (the scan status is OK) but are refused: the detector status is an ERROR naming the
    # reason while every scan is refused, a WARN while some are used
    rig = Rig(ros)
    helper = ros.node("landmarks_refusal_helper")
    arrays: list[DiagnosticArray] = []
    subscription = helper.create_subscription(DiagnosticArray, "/diagnostics", arrays.append, 10)
    assert ros.spin_until(lambda: matched(subscription), 5.0)
    good = scan_message(T0_NS, scan_ranges())
    bad = scan_message(T0_NS, scan_ranges(), angle_increment=2 * LDS01.angle_increment)

    def publish_until(scans: list[LaserScan], level: bytes) -> dict[str, DiagnosticStatus]:
        """Publish ``scans`` in turn at 20 Hz until the detector status has ``level``; the statuses."""
        for k in range(80):
            rig.scan.publish(scans[k % len(scans)])
            if ros.spin_until(lambda: any(a for a in arrays if detector_level(a) == level), 0.05):
                break
        (last,) = [a for a in arrays if detector_level(a) == level][-1:]
        arrays.clear()
        return {s.name: s for s in last.status}

    refused = publish_until([bad], DiagnosticStatus.ERROR)
    detector = refused["landmarks: detector"]
    assert refused["landmarks: scan"].level == DiagnosticStatus.OK, "scans arrive"
    assert "scans refused" in detector.message and "contradicts itself" in detector.message
    values = {pair.key: pair.value for pair in detector.values}
    assert values["scans_used"] == "0" and int(values["scans_refused"]) > 0
    assert "contradicts itself" in values["last_refusal"]
    mixed = publish_until([good, bad], DiagnosticStatus.WARN)["landmarks: detector"]
    assert "scans refused" in mixed.message
    assert int({pair.key: pair.value for pair in mixed.values}["scans_used"]) > 0
    warnings = rig.warnings(at_least=1)
    assert len(warnings) == 1, "throttled"
    assert "scan skipped" in warnings[0] and "contradicts itself" in warnings[0]


def detector_level(array: DiagnosticArray) -> bytes | None:
    levels = [s.level for s in array.status if s.name == "landmarks: detector"]
    return levels[0] if levels else None
