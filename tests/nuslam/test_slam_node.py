"""slam in process with real rclpy: joint_states and landmark MarkerArrays in; slam/odom, slam/path and
slam/map out.

Expected values come from turtlelib, never from the node: the pose from `DiffDrive.step` composed over the
joint_states intervals from the start pose (x0, y0, theta0), the landmarks from their true places, and for
late observations a `turtlelib.EkfSlam` + `SlamTimeline` fed the same samples directly.

Motion is along arcs of constant wheel speeds, so the true pose at any time t (also between samples) is
``DiffDrive.step(T0, w_left (t - t0), w_right (t - t0))``: the filter's predictions may split such an arc
anywhere without changing where it ends.
"""

from __future__ import annotations

import math
from itertools import pairwise

import numpy as np
import pytest
from diagnostic_msgs.msg import DiagnosticArray, DiagnosticStatus
from geometry_msgs.msg import PoseWithCovarianceStamped
from nav_msgs.msg import Odometry, Path
from rclpy.parameter import Parameter
from rclpy.qos import qos_profile_sensor_data
from ros_test_messages import cylinder_array, node_inputs_matched, stamp, stamp_ns
from ros_test_messages import relative as landmarks_in
from sensor_msgs.msg import JointState, LaserScan
from visualization_msgs.msg import Marker, MarkerArray

from nuslam.landmarks_node import LandmarksNode
from nuslam.slam_node import SlamNode
from nuturtle_description.robot_params import burger_params
from nuturtle_ros_common.conversions import covariance_from_6x6, odometry_message, yaw_from_quaternion
from nuturtle_ros_common.markers import noise_text
from rclpy_harness import matched, record_rosout, refused_at_construction, rosout_matched, warnings_of
from turtlelib import (
    DiffDriveMotion,
    EkfSlam,
    LidarConfig,
    MeasuredMotion,
    MeasuredPoses,
    Outcome,
    SlamConfig,
    SlamTimeline,
    StepResult,
    TimelineConfig,
    Transform2D,
    Twist2D,
    TwistNoise,
    WheelAngles,
    simulate_scan,
)
from turtlelib.estimation.range_bearing import observations_from_points

pytestmark = pytest.mark.ros

DRIVE = burger_params().diff_drive()
R_WHEEL = DRIVE.wheel_radius
T_BODY_SENSOR = Transform2D(-0.032, 0.0, 0.0)  # the LDS-01 on the Burger (its lidar_x)
WHEELS = ("wheel_left_joint", "wheel_right_joint")
S = 1_000_000_000  # ns per s
EPOCH_NS = 1_700_000_000_123_456_789  # an epoch-sized stamp with every nanosecond digit used
# true landmarks in map: id -> (x, y)
LANDMARKS = {3: (1.2, 0.4), 7: (0.5, -1.0), 12: (-0.6, 0.8)}
GREEN = (0.1, 0.8, 0.2, 1.0)
TOL = 1e-9
WHEEL_NOISE = 0.05  # the node's default wheel_noise (sqrt(rad))


def wheel_speeds(vx: float, omega: float) -> tuple[float, float]:
    """(left, right) wheel speeds (rad/s) of a body twist."""
    half_track = 0.5 * DRIVE.track_width
    return (vx - omega * half_track) / R_WHEEL, (vx + omega * half_track) / R_WHEEL


class Arc:
    """Constant wheel speeds from pose ``T0`` and wheel angles ``phi0`` at ``t0_ns``."""

    def __init__(self, T0: Transform2D, t0_ns: int, vx: float, omega: float, phi0=(0.0, 0.0)) -> None:
        self.T0, self.t0_ns, self.phi0 = T0, t0_ns, phi0
        self.speeds = wheel_speeds(vx, omega)

    def angles(self, t_ns: int) -> tuple[float, float]:
        dt = (t_ns - self.t0_ns) / S
        return self.phi0[0] + self.speeds[0] * dt, self.phi0[1] + self.speeds[1] * dt

    def pose(self, t_ns: int) -> Transform2D:
        dt = (t_ns - self.t0_ns) / S
        return DRIVE.step(self.T0, self.speeds[0] * dt, self.speeds[1] * dt)


def joint_state(t_ns: int, positions, names=WHEELS) -> JointState:
    msg = JointState(name=list(names), position=[float(p) for p in positions])
    msg.header.stamp = stamp(t_ns)
    return msg


def relative(T_world_frame: Transform2D, landmarks=LANDMARKS) -> list[tuple[int, float, float]]:
    """``(id, x, y)`` of the landmarks (default: this file's) in a frame at ``T_world_frame``."""
    return landmarks_in(T_world_frame, landmarks)


def pose_of(odom: Odometry) -> tuple[float, float, float]:
    pose = odom.pose.pose
    return pose.position.x, pose.position.y, yaw_from_quaternion(pose.orientation)


def close_pose(odom: Odometry, T: Transform2D, tol: float = TOL) -> bool:
    x, y, yaw = pose_of(odom)
    return abs(x - T.x) <= tol and abs(y - T.y) <= tol and abs(math.remainder(yaw - T.theta, math.tau)) <= tol


def mapped(array: MarkerArray, ns: str = "landmarks") -> dict[int, Marker]:
    markers = [m for m in array.markers if m.ns == ns and m.action == Marker.ADD]
    by_id = {m.id: m for m in markers}
    assert len(by_id) == len(markers), f"an id drawn twice in ns {ns}"
    return by_id


def rgba(marker: Marker) -> tuple[float, float, float, float]:
    return marker.color.r, marker.color.g, marker.color.b, marker.color.a


class Rig:
    """slam plus a helper node publishing joint_states and observations and recording every output.

    Most tests step the wheels once a second, so ``max_sample_gap`` is 1 s unless given (the default
    0.5 s is tested in the hostile-input tests). The filter's own behaviour is tested with its motion
    input as the prediction, so ``scan_registration`` is off unless given (on: test_slam_registration.py)."""

    def __init__(self, ros, **parameters) -> None:
        self.ros = ros
        parameters.setdefault("max_sample_gap", 1.0)
        parameters.setdefault("scan_registration", False)
        overrides = [Parameter(name, value=value) for name, value in parameters.items()]
        self.node = ros.add(SlamNode(context=ros.context, parameter_overrides=overrides))
        helper = ros.node("slam_test_helper")
        self.helper = helper
        self.odoms: list[Odometry] = []
        self.maps: list[MarkerArray] = []
        self.paths: list[Path] = []
        self.logs = record_rosout(helper)
        self.joint_states = helper.create_publisher(JointState, "joint_states", 10)
        topic = "fake_sensor" if parameters.get("association") == "known" else "landmarks"
        self.observations = helper.create_publisher(MarkerArray, topic, 10)
        # the odometry source's odom (odom -> base_footprint), for map -> odom
        self.odom = helper.create_publisher(Odometry, "odom", 10)
        self.initial = helper.create_publisher(PoseWithCovarianceStamped, "initialpose", 10)
        # the occupancy grid's input (slam subscribes unless the grid is off or loaded for localization)
        self.scans = helper.create_publisher(LaserScan, "scan", qos_profile_sensor_data)
        maps_scans = any(s.topic_name == "/scan" for s in self.node.subscriptions)
        # with motion_source odom nobody listens to joint_states
        endpoints = [
            *([self.joint_states] if parameters.get("motion_source") != "odom" else []),
            self.observations,
            self.odom,
            self.initial,
            *([self.scans] if maps_scans else []),
            helper.create_subscription(Odometry, "slam/odom", self.odoms.append, 100),
            helper.create_subscription(MarkerArray, "slam/map", self.maps.append, 100),
            helper.create_subscription(Path, "slam/path", self.paths.append, 100),
        ]
        assert ros.spin_until(
            lambda: matched(*endpoints) and node_inputs_matched(self.node) and rosout_matched(helper), 10.0
        )

    def wheels(self, t_ns: int, positions, names=WHEELS) -> Odometry:
        """Publish joint_states and return the odom it causes."""
        count = len(self.odoms)
        self.joint_states.publish(joint_state(t_ns, positions, names))
        assert self.ros.spin_until(lambda: len(self.odoms) > count, 5.0), "no odom"
        return self.odoms[-1]

    def observe(self, msg: MarkerArray) -> MarkerArray:
        """Publish an observation array and return the map it causes."""
        count = len(self.maps)
        self.observations.publish(msg)
        assert self.ros.spin_until(lambda: len(self.maps) > count, 5.0), "no map"
        return self.maps[-1]

    def warnings(self, at_least: int = 0) -> list[str]:
        """The node's warnings so far (waiting up to 2 s for ``at_least`` of them, then 0.1 s for more)."""
        self.ros.spin_until(lambda: len(warnings_of(self.logs, "slam")) >= at_least, 2.0)
        self.ros.spin_for(0.1)
        return warnings_of(self.logs, "slam")


def assert_map_header(array: MarkerArray, t_ns: int) -> None:
    assert array.markers[0].action == Marker.DELETEALL
    for marker in array.markers:
        assert marker.header.frame_id == "map"
        assert stamp_ns(marker.header.stamp) == t_ns, "stamped with the observation's own stamp"


def assert_covariance(odom: Odometry) -> np.ndarray:
    """The (x, y, yaw) block, checked: only those entries of the 6x6 set, symmetric, PSD."""
    P6 = np.array(odom.pose.covariance).reshape(6, 6)
    P = covariance_from_6x6(odom.pose.covariance)
    rest = P6.copy()
    rest[np.ix_([0, 1, 5], [0, 1, 5])] = 0.0
    assert np.all(rest == 0.0), "z, roll and pitch are not estimated"
    assert np.array_equal(P, P.T)
    assert np.linalg.eigvalsh(P).min() >= -1e-15
    return P


# --- odometry -----------------------------------------------------------------------------------------------


def test_straight_drive_then_arc_follow_the_kinematics_from_the_start_pose_with_a_growing_covariance(ros):
    T0 = Transform2D(0.5, -0.25, 0.7)
    # no observations in this test: no warning that slam only dead-reckons
    # the path at every kept pose (path_period 0), a pose every 2 cm
    rig = Rig(
        ros,
        x0=T0.x,
        y0=T0.y,
        theta0=T0.theta,
        observation_timeout=100.0,
        path_period=0.0,
        path_min_step_m=0.02,
    )
    t_ns, phi = 50 * S, (2.0, -1.0)  # any start angles: only increments count
    first = rig.wheels(t_ns, phi)
    assert close_pose(first, T0)
    assert (first.header.frame_id, first.child_frame_id) == ("map", "base_footprint")
    assert stamp_ns(first.header.stamp) == t_ns
    assert np.all(assert_covariance(first) == 0.0), "initial_xy_std = initial_theta_std = 0"
    # 0.5 s steps: 4 straight (5 cm each), then 4 along an arc (10 cm and 0.4 rad each)
    steps = [(0.05 / R_WHEEL,) * 2] * 4 + [wheel_speeds(0.1, 0.4)] * 4
    T, traces = T0, [0.0]
    for dphi_left, dphi_right in steps:
        t_ns += S // 2
        phi = (phi[0] + dphi_left, phi[1] + dphi_right)
        T = DRIVE.step(T, dphi_left, dphi_right)
        odom = rig.wheels(t_ns, phi)
        assert stamp_ns(odom.header.stamp) == t_ns
        assert (odom.header.frame_id, odom.child_frame_id) == ("map", "base_footprint")
        assert close_pose(odom, T), (pose_of(odom), T)
        twist = DRIVE.body_twist(dphi_left, dphi_right)
        assert odom.twist.twist.linear.x == pytest.approx(twist.vx / 0.5, abs=TOL)
        assert odom.twist.twist.angular.z == pytest.approx(twist.omega / 0.5, abs=TOL)
        P = assert_covariance(odom)
        assert np.all(np.diag(P) > 0.0)
        traces.append(float(np.trace(P)))
    assert all(b > a for a, b in pairwise(traces)), f"no observations: the covariance grows {traces}"
    # the end of the hand-made trajectory: 0.2 m along 0.7 rad, then a 0.25 m-radius arc through 1.6 rad
    assert T.theta == pytest.approx(0.7 + 1.6)
    # the path (frame map) keeps every pose: each step is more than path_min_step_m
    assert rig.ros.spin_until(lambda: len(rig.paths) == 1 + len(steps), 5.0), "a path per kept pose"
    path = rig.paths[-1]
    assert path.header.frame_id == "map"
    assert len(path.poses) == 1 + len(steps)
    last = path.poses[-1].pose
    assert (last.position.x, last.position.y) == pytest.approx((T.x, T.y), abs=TOL)
    assert rig.warnings() == []


def test_initial_pose_standard_deviations_set_the_first_covariance(ros):
    rig = Rig(ros, initial_xy_std=0.1, initial_theta_std=0.05, x0=-1.0)
    odom = rig.wheels(S, (0.0, 0.0))
    assert close_pose(odom, Transform2D(-1.0, 0.0, 0.0))
    assert assert_covariance(odom) == pytest.approx(np.diag([0.01, 0.01, 0.0025]), abs=1e-15)


# --- known association --------------------------------------------------------------------------------------


def test_known_association_maps_the_fake_sensor_landmarks_at_their_true_places(ros):
    T0 = Transform2D(0.2, 0.1, -0.4)
    rig = Rig(ros, association="known", x0=T0.x, y0=T0.y, theta0=T0.theta, landmark_radius=0.05)
    arc = Arc(T0, EPOCH_NS, vx=0.15, omega=0.3, phi0=(10.0, 20.0))
    rig.wheels(EPOCH_NS, arc.angles(EPOCH_NS))
    # first sighting from the start pose, stamped at the first joint_states
    first = rig.observe(cylinder_array("base_footprint", EPOCH_NS, relative(T0)))
    maps = [(EPOCH_NS, first)]
    # then drive at 10 Hz, each observation stamped between the last two samples
    for k in range(1, 9):
        t_ns = EPOCH_NS + k * S // 10
        rig.wheels(t_ns, arc.angles(t_ns))
        t_obs = t_ns - S // 20
        maps.append((t_obs, rig.observe(cylinder_array("base_footprint", t_obs, relative(arc.pose(t_obs))))))
    major_axes = []
    for t_obs, array in maps:
        assert_map_header(array, t_obs)
        cylinders, ellipses = mapped(array, "landmarks"), mapped(array, "covariance")
        assert len(array.markers) == 1 + len(cylinders) + len(ellipses)
        assert sorted(cylinders) == sorted(ellipses) == sorted(LANDMARKS), "marker id = landmark id"
        for landmark_id, (x, y) in LANDMARKS.items():
            cylinder, ellipse = cylinders[landmark_id], ellipses[landmark_id]
            assert cylinder.type == Marker.CYLINDER and ellipse.type == Marker.CYLINDER
            assert (cylinder.pose.position.x, cylinder.pose.position.y) == pytest.approx((x, y), abs=1e-6)
            assert (ellipse.pose.position.x, ellipse.pose.position.y) == pytest.approx((x, y), abs=1e-6)
            assert cylinder.scale.x == cylinder.scale.y == pytest.approx(0.1), "2 landmark_radius"
            assert rgba(cylinder) == pytest.approx(GREEN)
            assert ellipse.scale.x >= ellipse.scale.y > 0.0 and ellipse.scale.z < 0.05, "a flat ellipse"
            assert rgba(ellipse)[:3] == pytest.approx(GREEN[:3]) and rgba(ellipse)[3] < 1.0
            major_axes.append((t_obs, landmark_id, ellipse.scale.x))
    # first sighting with an exact pose: Sigma = fake_sensor_std^2 I, a 2-sigma circle of diameter 4 std
    first_ellipses = mapped(first, "covariance")
    for ellipse in first_ellipses.values():
        assert (ellipse.scale.x, ellipse.scale.y) == pytest.approx((0.04, 0.04), abs=1e-9)
    # more sightings never make a landmark less certain, and eight more make it clearly more certain
    for landmark_id in LANDMARKS:
        axes = [axis for _, i, axis in major_axes if i == landmark_id]
        assert all(b <= a + 1e-12 for a, b in pairwise(axes))
        assert axes[-1] < 0.8 * axes[0]
    # consistent observations leave the pose on the true arc
    t_end = EPOCH_NS + 8 * S // 10
    assert close_pose(rig.odoms[-1], arc.pose(t_end), 1e-6)
    assert rig.warnings() == []


def test_an_unseen_landmark_joins_the_map_when_first_observed(ros):
    rig = Rig(ros, association="known")
    rig.wheels(S, (0.0, 0.0))
    first = rig.observe(cylinder_array("base_footprint", S, relative(Transform2D(), {3: LANDMARKS[3]})))
    assert sorted(mapped(first)) == [3]
    # nothing visible: an array with only its DELETEALL still gives a map (the same one)
    empty = rig.observe(cylinder_array("base_footprint", S, []))
    assert sorted(mapped(empty)) == [3]
    both = rig.observe(cylinder_array("base_footprint", S, relative(Transform2D(), LANDMARKS)))
    assert sorted(mapped(both)) == [3, 7, 12]
    for landmark_id, xy in LANDMARKS.items():
        marker = mapped(both)[landmark_id]
        assert (marker.pose.position.x, marker.pose.position.y) == pytest.approx(xy, abs=1e-9)
        assert marker.scale.x == pytest.approx(0.076), "default landmark_radius 0.038"


# --- unknown association ------------------------------------------------------------------------------------


@pytest.mark.parametrize("frame_id", ["base_scan", "base_footprint"])
def test_unknown_association_maps_each_landmark_once_after_confirm_count_sightings(ros, frame_id):
    T0 = Transform2D(-0.3, 0.2, 1.0)
    rig = Rig(ros, x0=T0.x, y0=T0.y, theta0=T0.theta)  # association unknown, confirm_count 5 by default
    arc = Arc(T0, 5 * S, vx=0.1, omega=-0.2)
    offset = T_BODY_SENSOR if frame_id == "base_scan" else Transform2D()
    counts = []
    for k in range(8):
        t_ns = 5 * S + k * S // 5
        rig.wheels(t_ns, arc.angles(t_ns))
        # the landmarks node's arrays carry no ids that mean anything: number them per scan, shuffled
        seen = relative(arc.pose(t_ns) @ offset)
        seen = [(j, x, y) for j, (_, x, y) in enumerate(seen[k % 3 :] + seen[: k % 3])]
        array = rig.observe(cylinder_array(frame_id, t_ns, seen))
        assert_map_header(array, t_ns)
        cylinders = mapped(array)
        counts.append(len(cylinders))
        assert sorted(mapped(array, "covariance")) == sorted(cylinders)
        if len(cylinders) == 3:
            assert sorted(cylinders) == [0, 1, 2], "each landmark once, numbered as created"
            found = sorted((m.pose.position.x, m.pose.position.y) for m in cylinders.values())
            assert np.array(found) == pytest.approx(np.array(sorted(LANDMARKS.values())), abs=1e-6)
    assert counts == [0, 0, 0, 0, 3, 3, 3, 3], "tentative until the 5th sighting"
    assert close_pose(rig.odoms[-1], arc.pose(5 * S + 7 * S // 5), 1e-6)
    assert rig.warnings() == []


@pytest.mark.parametrize(
    ("frame_id", "R"),
    [
        ("base_scan", None),  # a recording made before detections carried their noise: the filter's default
        ("base_scan", np.diag([0.001**2, 0.001**2])),
        ("base_scan", np.array([[0.05**2, 1e-5], [1e-5, 0.03**2]])),
        ("base_footprint", np.array([[0.05**2, 1e-5], [1e-5, 0.03**2]])),
    ],
    ids=["no text", "small", "large", "large in base_footprint"],
)
def test_each_detection_is_fused_with_the_noise_its_marker_carries(ros, frame_id, R):
    """Standing at the origin with an exact pose, a new landmark's covariance is its observation's noise
    carried into the map: ``G R G^T`` with ``G = dp/dz`` at the marker's range and bearing in its frame (the
    sensor's axes are the map's)."""
    rig = Rig(ros, confirm_count=1)
    rig.wheels(S, (0.0, 0.0))
    x, y = relative(T_BODY_SENSOR if frame_id == "base_scan" else Transform2D())[0][1:]
    array = cylinder_array(frame_id, S, [(0, x, y)])
    if R is not None:
        array.markers[1].text = noise_text(R)
    assert len(mapped(rig.observe(array))) == 1
    r, b = math.hypot(x, y), math.atan2(y, x)
    G = np.array([[math.cos(b), -r * math.sin(b)], [math.sin(b), r * math.cos(b)]])
    R_used = np.diag([SlamConfig().range_std ** 2, SlamConfig().bearing_std ** 2]) if R is None else R
    np.testing.assert_allclose(rig.node.slam.landmark_covariances[0], G @ R_used @ G.T, rtol=1e-9, atol=0.0)
    assert rig.warnings() == []


def test_an_array_with_a_malformed_noise_text_is_skipped_with_a_warning(ros):
    rig = Rig(ros, confirm_count=1)
    rig.wheels(S, (0.0, 0.0))
    bad = cylinder_array("base_scan", S, relative(T_BODY_SENSOR))
    bad.markers[1].text = "R=0.0004 0.0"
    rig.observations.publish(bad)
    array = rig.observe(cylinder_array("base_scan", S, relative(T_BODY_SENSOR)))
    assert len(rig.maps) == 1 and len(mapped(array)) == 3, "the map answers the good array only"
    warnings = rig.warnings(at_least=1)
    assert len(warnings) == 1 and "landmarks skipped" in warnings[0] and "'R=0.0004 0.0'" in warnings[0]


def test_confirm_count_sets_the_sightings_that_confirm_a_landmark(ros):
    rig = Rig(ros, confirm_count=2)
    # driving straight at 0.4 m/s: the second sighting is from a viewpoint 8 cm on
    arc = Arc(Transform2D(), S, vx=0.4, omega=0.0)
    counts = []
    for k in range(3):  # three scans (distinct stamps: copies of one scan count once)
        t_ns = S + k * S // 5
        rig.wheels(t_ns, arc.angles(t_ns))
        seen = relative(arc.pose(t_ns) @ T_BODY_SENSOR)
        counts.append(len(mapped(rig.observe(cylinder_array("base_scan", t_ns, seen)))))
    assert counts == [0, 3, 3]


def test_scans_through_the_landmarks_node_map_the_cylinders_of_a_simulated_lidar(ros):
    """The real chain: LDS-01 scans (1 cm noise) -> landmarks -> slam, while driving an arc."""
    ros.add(LandmarksNode(context=ros.context))
    rig = Rig(ros)
    scans = rig.helper.create_publisher(LaserScan, "scan", qos_profile_sensor_data)
    assert ros.spin_until(lambda: matched(scans), 10.0)
    lidar = LidarConfig(noise=0.01, resolution=0.01)
    circles = np.array([(x, y, 0.05) for x, y in LANDMARKS.values()])
    rng = np.random.default_rng(3)
    arc = Arc(Transform2D(), S, vx=0.1, omega=0.3)
    for k in range(7):
        t_ns = S + k * S // 5
        rig.wheels(t_ns, arc.angles(t_ns))
        scan = LaserScan(angle_min=0.0, angle_increment=lidar.angle_increment, range_min=0.12, range_max=3.5)
        scan.angle_max = (lidar.samples - 1) * lidar.angle_increment
        scan.header.stamp, scan.header.frame_id = stamp(t_ns), "base_scan"
        T_world_sensor = arc.pose(t_ns) @ T_BODY_SENSOR
        scan.ranges = simulate_scan(T_world_sensor, circles, np.empty((0, 4)), lidar, rng).tolist()
        count = len(rig.maps)
        scans.publish(scan)
        assert ros.spin_until(lambda count=count: len(rig.maps) > count, 5.0), "no map for this scan"
        assert_map_header(rig.maps[-1], t_ns)
    cylinders = mapped(rig.maps[-1])
    assert len(cylinders) == 3
    for x, y in LANDMARKS.values():
        nearest = min(math.hypot(m.pose.position.x - x, m.pose.position.y - y) for m in cylinders.values())
        assert nearest < 0.02
    assert rig.warnings() == []


# --- time alignment -----------------------------------------------------------------------------------------


def test_late_and_early_observations_are_applied_at_their_own_stamps(ros):
    """Driving fast at 20 Hz, observations arrive 0.1-0.2 s after the joint_states of their stamp (and one
    before); the node must match a turtlelib filter fed the same samples, and the map the truth."""
    T0 = Transform2D(0.1, -0.2, 0.3)
    rig = Rig(ros, association="known", x0=T0.x, y0=T0.y, theta0=T0.theta)
    config, timeline_config = SlamConfig(sensor_x=T_BODY_SENSOR.x), TimelineConfig()
    slam = EkfSlam(config, DiffDriveMotion(DRIVE, WHEEL_NOISE), T0)
    timeline = SlamTimeline(slam, WheelAngles(), timeline_config)
    arc = Arc(T0, EPOCH_NS, vx=0.22, omega=0.6)
    rng = np.random.default_rng(11)
    fake_std = 0.01

    def observation(t_obs: int) -> tuple[MarkerArray, list]:
        """The fake sensor at t_obs (5 mm noise per axis) and what the node makes of it, for the reference."""
        noise = rng.normal(0.0, 0.005, (len(LANDMARKS), 2))
        seen = [
            (i, x + dx, y + dy) for (i, x, y), (dx, dy) in zip(relative(arc.pose(t_obs)), noise, strict=True)
        ]
        ids = np.array([i for i, _, _ in seen])
        p_sensor = T_BODY_SENSOR.inverse() @ np.array([(x, y) for _, x, y in seen])
        z, R = observations_from_points(p_sensor, np.broadcast_to(fake_std**2 * np.eye(2), (3, 2, 2)))
        return cylinder_array("base_footprint", t_obs, seen), [t_obs, z, R, ids]

    def check_map(array: MarkerArray, t_obs: int) -> None:
        assert_map_header(array, t_obs)
        cylinders = mapped(array)
        assert sorted(cylinders) == list(slam.landmark_ids) == sorted(LANDMARKS)
        for landmark_id, xy in zip(slam.landmark_ids, slam.landmarks, strict=True):
            marker = cylinders[int(landmark_id)]
            assert (marker.pose.position.x, marker.pose.position.y) == pytest.approx(tuple(xy), abs=TOL)
            truth = LANDMARKS[int(landmark_id)]
            assert math.dist((marker.pose.position.x, marker.pose.position.y), truth) < 0.015

    dt_ns = S // 20
    late = {8: 4, 14: 2, 20: 3, 26: 4}  # sample k: its observation arrives after sample k + delay
    waiting = []
    for k in range(36):
        t_ns = EPOCH_NS + k * dt_ns
        odom = rig.wheels(t_ns, arc.angles(t_ns))
        timeline.add_motion(t_ns, arc.angles(t_ns))
        T_ref, P_ref = timeline.latest_pose()
        assert close_pose(odom, T_ref), (k, pose_of(odom), T_ref)
        assert covariance_from_6x6(odom.pose.covariance) == pytest.approx(P_ref, abs=1e-12)
        if k in late:
            waiting.append((k + late[k], t_ns))
        if k == 30:
            # between samples, in the filter's window: 0.125 s back
            waiting.append((k, t_ns - 5 * dt_ns // 2))
        for t_obs in [t for due, t in waiting if due == k]:
            msg, args = observation(t_obs)
            timeline.add_observations(*args)
            check_map(rig.observe(msg), t_obs)
        if k == 32:
            # early: stamped 20 ms after this sample, applied once the next one reaches it
            t_obs = t_ns + dt_ns * 2 // 5
            msg, args = observation(t_obs)
            assert timeline.add_observations(*args) == []
            rig.observations.publish(msg)
            rig.ros.spin_for(0.2)
            count = len(rig.maps)
            t_next = t_ns + dt_ns
            rig.wheels(t_next, arc.angles(t_next))
            timeline.add_motion(t_next, arc.angles(t_next))
            assert rig.ros.spin_until(lambda count=count: len(rig.maps) > count, 5.0)
            check_map(rig.maps[-1], t_obs)
            break
    assert len(rig.maps) == len(late) + 2
    # the same filter: the final pose and its covariance
    T_ref, P_ref = timeline.latest_pose()
    assert close_pose(rig.odoms[-1], T_ref)
    assert covariance_from_6x6(rig.odoms[-1].pose.covariance) == pytest.approx(P_ref, abs=1e-12)
    assert rig.warnings() == []


def test_a_late_observation_of_a_fast_robot_is_placed_from_the_pose_at_its_stamp(ros):
    """0.2 m/s (near the Burger's top speed), the observation 0.2 s late: applied at the pose of its
    delivery it would misplace the landmarks by about 4 cm."""
    rig = Rig(ros, association="known")
    arc = Arc(Transform2D(), 7 * S, vx=0.2, omega=0.0)
    for k in range(6):
        rig.wheels(7 * S + k * S // 20, arc.angles(7 * S + k * S // 20))
    t_obs = 7 * S + S // 20  # sample 1, delivered after sample 5
    array = rig.observe(cylinder_array("base_footprint", t_obs, relative(arc.pose(t_obs))))
    for landmark_id, xy in LANDMARKS.items():
        marker = mapped(array)[landmark_id]
        assert (marker.pose.position.x, marker.pose.position.y) == pytest.approx(xy, abs=1e-6)


# --- bad input ----------------------------------------------------------------------------------------------


BAD_JOINT_STATES = {
    # kind: (message, part of the warning)
    "unknown joint names": (joint_state(2 * S, (5.0, 5.0), names=("left", "right")), "missing"),
    "one wheel missing": (joint_state(2 * S, (5.0,), names=WHEELS[:1]), "'wheel_right_joint' is missing"),
    "NaN position": (joint_state(2 * S, (math.nan, 5.0)), "non-finite"),
    "infinite position": (joint_state(2 * S, (5.0, math.inf)), "non-finite"),
    "fewer positions than names": (
        JointState(name=list(WHEELS), position=[5.0]),
        "2 joint names but 1 values",
    ),
    "more positions than names": (
        JointState(name=list(WHEELS), position=[5.0] * 3),
        "2 joint names but 3 values",
    ),
}


@pytest.mark.parametrize("kind", BAD_JOINT_STATES)
def test_bad_joint_states_are_skipped_with_a_warning_and_the_node_keeps_going(ros, kind):
    bad, reason = BAD_JOINT_STATES[kind]
    rig = Rig(ros)
    rig.wheels(S, (0.0, 0.0))
    for _ in range(3):
        rig.joint_states.publish(bad)
    # a topic keeps its order: the next odom answers this good message, driven from the first one
    dphi = 0.1 / R_WHEEL
    odom = rig.wheels(2 * S, (dphi, dphi))
    assert close_pose(odom, Transform2D(0.1, 0.0, 0.0))
    assert stamp_ns(odom.header.stamp) == 2 * S
    assert len(rig.odoms) == 2, "no odom for the bad messages"
    warnings = rig.warnings(at_least=1)
    assert len(warnings) == 1, "three bad messages, one throttled warning"
    assert "joint_states skipped" in warnings[0] and reason in warnings[0]


@pytest.mark.parametrize("dt_ns", [S // 20, S // 2], ids=["20 Hz", "2 Hz"])
def test_finite_angles_whose_increment_overflows_are_refused_and_forgotten(ros, dt_ns):
    """At 20 Hz the filter (0.25 s behind) would not have reached the bad interval yet, at 2 Hz it would:
    either way the sample is refused before it reaches the filter, the next samples drive on from the
    last good one and observations are still applied."""
    rig = Rig(ros, association="known", observation_timeout=100.0)
    t_ns = S
    rig.wheels(t_ns, (0.0, 0.0))
    rig.wheels(t_ns + dt_ns, (0.0, 0.0))
    rig.joint_states.publish(joint_state(t_ns + 2 * dt_ns, (1e308, -1e308)))  # the turn rate would overflow
    rig.wheels(t_ns + 3 * dt_ns, (0.0, 0.0))  # the stream goes on
    dphi = 0.005 / R_WHEEL  # 0.1 m/s at 20 Hz
    odom = rig.wheels(t_ns + 4 * dt_ns, (dphi, dphi))
    assert close_pose(odom, Transform2D(0.005, 0.0, 0.0))
    assert len(rig.odoms) == 4, "no odom for the refused sample"
    for k in range(5, 11):  # standing, the filter catches up
        rig.wheels(t_ns + k * dt_ns, (dphi, dphi))
    array = rig.observe(
        cylinder_array("base_footprint", t_ns + 10 * dt_ns, relative(Transform2D(0.005, 0.0, 0.0)))
    )
    for landmark_id, xy in LANDMARKS.items():
        marker = mapped(array)[landmark_id]
        assert (marker.pose.position.x, marker.pose.position.y) == pytest.approx(xy, abs=1e-9)
    warnings = rig.warnings(at_least=1)
    assert len(warnings) == 1, warnings
    assert "joint_states refused" in warnings[0] and "value 0 moved 1e+308" in warnings[0]


def test_a_sample_the_filter_refuses_is_skipped_with_a_warning_and_changes_nothing(ros):
    """With the gate opened wide (speed_margin 1e4: up to ~3e4 rad in 0.5 s) wheels 12000 rad apart reach the
    filter, whose motion model refuses the step to its new time (half the interval: the body would turn by
    0.033 / 0.16 * 6000 = 1237 rad > 1000 rad): one throttled warning, the state as it was, and the next
    samples drive on from the last good one."""
    rig = Rig(ros, association="known", observation_timeout=100.0, speed_margin=1e4)
    dt_ns = S // 2
    rig.wheels(S, (0.0, 0.0))
    rig.wheels(S + dt_ns, (0.0, 0.0))
    node = rig.node

    def state():
        timeline = node.timeline
        times = (timeline.filter_time_ns, timeline.latest_time_ns, timeline.pending_count)
        return node.slam.state.copy(), node.slam.covariance.copy(), times, len(rig.odoms)

    before = state()
    for k in (2, 3):
        rig.joint_states.publish(joint_state(S + k * dt_ns, (6000.0, -6000.0)))
    warnings = rig.warnings(at_least=1)
    after = state()
    np.testing.assert_array_equal(after[0], before[0])
    np.testing.assert_array_equal(after[1], before[1])
    assert after[2:] == before[2:], "no sample kept, no odom"
    assert len(warnings) == 1, "two refused samples, one throttled warning"
    assert "joint_states skipped" in warnings[0] and "is not a motion" in warnings[0], warnings
    dphi = 0.01 / R_WHEEL
    odom = rig.wheels(S + 4 * dt_ns, (dphi, dphi))
    assert close_pose(odom, Transform2D(0.01, 0.0, 0.0), 1e-12), pose_of(odom)
    assert node.timeline.latest_time_ns == S + 4 * dt_ns


def observation_case(kind: str, frame_id: str) -> tuple[MarkerArray, str]:
    """A bad observation array (stamps in the node's time, filter at 1.75 s) and part of its warning."""
    good = relative(T_BODY_SENSOR if frame_id == "base_scan" else Transform2D())
    if kind == "unknown frame":
        return cylinder_array("odom", 2 * S, good), "'odom'"
    if kind == "NaN position":
        return cylinder_array(frame_id, 2 * S, [good[0], (good[1][0], math.nan, 0.5), good[2]]), "non-finite"
    if kind == "stale":
        # the filter runs max_observation_delay (0.25 s) behind the newest joint_states (2 s)
        return cylinder_array(frame_id, 2 * S - 300_000_000, good), "stale observation"
    if kind == "mixed frames":
        msg = cylinder_array(frame_id, 2 * S, good)
        msg.markers[2].header.frame_id = "base_link"
        return msg, "share frame and stamp"
    if kind == "empty array":
        return MarkerArray(), "empty MarkerArray"
    raise AssertionError(kind)


@pytest.mark.parametrize(
    "association, frame_id",
    [("known", "base_footprint"), ("unknown", "base_scan")],
    ids=["fake_sensor", "landmarks"],
)
@pytest.mark.parametrize("kind", ["unknown frame", "NaN position", "stale", "mixed frames", "empty array"])
def test_bad_observations_are_skipped_with_a_warning_and_the_next_one_applied(
    ros, association, frame_id, kind
):
    rig = Rig(ros, association=association, confirm_count=1)
    rig.wheels(S, (0.0, 0.0))
    rig.wheels(2 * S, (0.0, 0.0))  # standing: the filter is at 1.75 s
    bad, reason = observation_case(kind, frame_id)
    for _ in range(3):
        rig.observations.publish(bad)
    # the next map answers this good array: the robot is at the origin
    good = cylinder_array(
        frame_id, 2 * S, relative(T_BODY_SENSOR if frame_id == "base_scan" else Transform2D())
    )
    array = rig.observe(good)
    assert len(rig.maps) == 1, "no map for the bad arrays"
    assert_map_header(array, 2 * S)
    found = sorted((m.pose.position.x, m.pose.position.y) for m in mapped(array).values())
    assert np.array(found) == pytest.approx(np.array(sorted(LANDMARKS.values())), abs=1e-9)
    if association == "known":
        assert sorted(mapped(array)) == sorted(LANDMARKS)
    warnings = rig.warnings(at_least=1)
    topic = "fake_sensor" if association == "known" else "landmarks"
    assert len(warnings) == 1, warnings
    assert f"{topic} skipped" in warnings[0] and reason in warnings[0]


def test_a_restarted_simulator_restarts_the_timeline_after_restart_samples_keeping_the_estimate(ros):
    rig = Rig(ros, association="known")
    dphi = 0.1 / R_WHEEL
    rig.wheels(10 * S, (0.0, 0.0))
    rig.wheels(10 * S + S // 2, (dphi, dphi))  # 0.1 m
    rig.wheels(11 * S, (dphi, dphi))  # standing for longer than max_observation_delay
    rig.observe(cylinder_array("base_footprint", 11 * S, relative(Transform2D(0.1, 0.0, 0.0))))
    # a restarted simulator: time and wheel angles start again; the third message (restart_samples)
    # restarts the timeline at the first and drives on along the others
    rig.joint_states.publish(joint_state(S // 2, (0.0, 0.0)))
    rig.joint_states.publish(joint_state(S, (dphi, dphi)))
    odom = rig.wheels(S + S // 2, (2 * dphi, 2 * dphi))  # 0.2 m more from the new start
    assert rig.ros.spin_until(lambda: len(rig.odoms) == 5)
    odom = rig.odoms[-1]
    assert close_pose(odom, Transform2D(0.3, 0.0, 0.0))
    assert stamp_ns(odom.header.stamp) == S + S // 2
    # observations in the new time base are applied; the map is kept
    array = rig.observe(cylinder_array("base_footprint", S + S // 2, relative(Transform2D(0.3, 0.0, 0.0))))
    assert_map_header(array, S + S // 2)
    for landmark_id, xy in LANDMARKS.items():
        marker = mapped(array)[landmark_id]
        assert (marker.pose.position.x, marker.pose.position.y) == pytest.approx(xy, abs=1e-9)
    warnings = rig.warnings(at_least=2)
    assert len(warnings) == 2 and "not after" in warnings[0] and "restarted" in warnings[1]
    # and counted in /diagnostics: two samples refused (the third restarted the stream), one restart
    gate, values = motion_gate_status(rig)
    assert gate.level == DiagnosticStatus.WARN and "restarted" in gate.message
    assert (values["motion_samples_refused"], values["motion_restarts"]) == ("2", "1")
    gate, _ = motion_gate_status(rig)
    assert gate.level == DiagnosticStatus.OK and "2 joint_states samples refused" in gate.message


def motion_gate_status(rig: Rig) -> tuple[DiagnosticStatus, dict[str, str]]:
    """slam's `slam: motion gate` status as its report makes it now, and its values by key."""
    gate = {status.name: status for status in rig.node.report.statuses(0)}["slam: motion gate"]
    return gate, {pair.key: pair.value for pair in gate.values}


def test_a_restart_while_driving_keeps_the_motion_up_to_the_newest_sample(ros):
    rig = Rig(ros, restart_samples=1)
    dphi = 0.1 / R_WHEEL
    rig.wheels(10 * S, (0.0, 0.0))
    odom = rig.wheels(10 * S + S // 2, (dphi, dphi))  # 0.1 m, the filter 0.25 s behind
    assert close_pose(odom, Transform2D(0.1, 0.0, 0.0))
    rig.joint_states.publish(joint_state(S // 2, (0.0, 0.0)))  # the clock jumps back right after
    odom = rig.wheels(S, (dphi, dphi))  # 0.1 m more
    assert close_pose(odom, Transform2D(0.2, 0.0, 0.0), 1e-6), pose_of(odom)


# --- parameters ---------------------------------------------------------------------------------------------


def invalid(name: str, value, message: str):
    """A parametrize row: the parameter ``name`` set to an invalid ``value``, and part of the error."""
    return pytest.param(Parameter(name, value=value), message, id=f"{name}={value!r}")


@pytest.mark.parametrize(
    "parameter, message",
    [
        invalid("association", "maybe", "association must be one of"),
        invalid("fake_sensor_std", -0.01, "fake_sensor_std"),
        invalid("fake_sensor_std", 0.0, "fake_sensor_std"),
        invalid("landmark_radius", math.nan, "landmark_radius"),
        invalid("map_id", "odom", "distinct"),
        invalid("sensor_id", "base_footprint", "distinct"),
        invalid("body_id", "", "non-empty"),
        invalid("x0", math.inf, "x0 must be a finite number"),
        invalid("matcher", "greedy", "matcher"),
        invalid("confirm_count", 0, "confirm_count"),
        invalid("tentative_timeout", 0.0, "tentative_timeout"),
        invalid("tentative_timeout", "2", "tentative_timeout must be of type float"),
        invalid("gate_known", 1.5, "gate_known"),
        invalid("linearization", "exact", "linearization must be one of"),
        invalid("noise_correlation", 1.0, "noise_correlation"),
        invalid("noise_correlation_length", -0.3, "noise_correlation_length"),
        invalid("wheel_noise", -0.1, "wheel_noise"),
        invalid("max_observation_delay", -0.1, "max_observation_delay"),
        invalid("wheel_right", "wheel_left_joint", "wheel_left, wheel_right must be distinct joint names"),
        invalid("wheel_radius", -0.033, "wheel_radius"),
        invalid("theta0", "north", "theta0 must be of type float"),
    ],
)
def test_an_invalid_parameter_raises_value_error_at_construction(ros, parameter, message):
    refused_at_construction(lambda: SlamNode(context=ros.context, parameter_overrides=[parameter]), message)


def test_the_default_parameters(ros):
    node = ros.add(SlamNode(context=ros.context))
    assert node.node_config.association == "unknown"
    # the sensor mount is the robot's (lidar_x ...), not a parameter of the filter's own
    assert node.config == SlamConfig(sensor_x=T_BODY_SENSOR.x)
    assert not node.has_parameter("sensor_x")
    # the observation noise is the detections' own (the landmarks node's): the filter keeps its default as
    # the fallback for arrays without
    assert not any(node.has_parameter(name) for name in ("range_std", "bearing_std", "range_std_per_m"))
    assert node.get_parameter("tentative_timeout").value == 2.0  # s
    assert node.get_parameter("gate_known").value == 0.9999
    assert node.get_parameter("linearization").value == "standard"
    # the motion: each scan registered with the robot's wheels (the node's wheel_noise) as its prior, the
    # filter predicting with the registered motion
    assert node.get_parameter("wheel_noise").value == WHEEL_NOISE
    assert node.get_parameter("scan_registration").value is True
    assert node.scan_odometry.noise == TwistNoise.from_wheel_slip(DRIVE, WHEEL_NOISE)
    assert node.slam.motion == MeasuredMotion()
    assert node.timeline.signal == MeasuredPoses()
    assert node.timeline.config == TimelineConfig()
    assert node.get_parameter("wheel_radius").value == R_WHEEL


@pytest.mark.parametrize("linearization", ["fej", "invariant"])
def test_the_filter_parameters_reach_the_filter(ros, linearization):
    overrides = [
        Parameter("scan_registration", value=False),  # the wheels' own motion model, then
        Parameter("wheel_noise", value=0.2),
        Parameter("tentative_timeout", value=0.5),
        Parameter("gate_known", value=1.0),
        Parameter("linearization", value=linearization),
        Parameter("noise_correlation", value=0.9),
        Parameter("noise_correlation_length", value=0.3),
    ]
    node = ros.add(SlamNode(context=ros.context, parameter_overrides=overrides))
    assert node.slam.motion == DiffDriveMotion(DRIVE, 0.2)
    assert node.node_config.wheel_noise == 0.2
    assert node.config == SlamConfig(
        sensor_x=T_BODY_SENSOR.x,
        tentative_timeout=0.5,
        gate_known=1.0,
        linearization=linearization,
        noise_correlation=0.9,
        noise_correlation_length=0.3,
    )


def test_the_invariant_filter_in_localization_is_refused_at_start_up(ros):
    overrides = [Parameter("mode", value="localization"), Parameter("linearization", value="invariant")]
    refused_at_construction(
        lambda: SlamNode(context=ros.context, parameter_overrides=overrides), "'invariant' is for mapping"
    )


def test_the_filter_s_sensor_mount_is_the_robot_s_lidar_mount(ros):
    """Written once: another robot's lidar_x, lidar_y, lidar_yaw (set explicitly) move the filter's
    sensor."""
    overrides = [
        Parameter("lidar_x", value=0.1),
        Parameter("lidar_y", value=-0.05),
        Parameter("lidar_yaw", value=math.pi),
    ]
    node = ros.add(SlamNode(context=ros.context, parameter_overrides=overrides))
    assert node.config.T_body_sensor == Transform2D(0.1, -0.05, math.pi)
    # the filter's measurement model observes from there
    assert node.slam.measurement.T_body_sensor == Transform2D(0.1, -0.05, math.pi)


def test_turning_wheels_without_observations_warn_that_slam_only_dead_reckons(ros):
    rig = Rig(ros, observation_timeout=2.0)
    dphi = 0.1 / R_WHEEL
    for k in range(4):
        rig.wheels((k + 1) * S, (k * dphi, k * dphi))
    warnings = rig.warnings(at_least=1)
    assert len(warnings) == 1 and "no landmarks for 3.0 s while the robot moves" in warnings[0]


def test_no_warning_while_observations_arrive_or_the_robot_stands(ros):
    rig = Rig(ros, observation_timeout=2.0)
    dphi = 0.1 / R_WHEEL
    for k in range(4):
        rig.wheels((k + 1) * S, (0.0, 0.0))  # standing: nothing to observe is no news
    for k in range(4):
        rig.wheels((k + 5) * S, (k * dphi, k * dphi))
        rig.observations.publish(cylinder_array("base_scan", (k + 5) * S, []))  # a scan without cylinders
        rig.ros.spin_for(0.05)
    assert rig.warnings() == []


class TfRecorder:
    """Stands in for /tf, which needs tf2_msgs (not on any registry): records the transforms slam sends."""

    available = True

    def __init__(self) -> None:
        self.sent = []

    def send(self, *transforms) -> None:
        self.sent.extend(transforms)


@pytest.mark.parametrize("odom_first", [True, False], ids=["odom before joint_states", "odom after"])
def test_map_to_odom_composed_with_the_broadcast_odom_gives_slam_s_pose_when_slam_starts_late(
    ros, odom_first
):
    rig = Rig(ros, observation_timeout=100.0)
    recorder = rig.node._map_to_odom._tf = TfRecorder()
    odom_publisher = rig.odom
    # the odometry node has run for a while: its odom frame is far from slam's map (which starts at 0)
    T_odom_start = Transform2D(-0.13, 0.98, -2.89)
    slam_poses = {}
    dphi = 0.05 / R_WHEEL
    for k in range(6):
        t_ns, phi = (k + 1) * S, (k * dphi, k * 1.2 * dphi)
        T_odom_body = T_odom_start @ DRIVE.step(Transform2D(), *phi)
        odom = odometry_message(T_odom_body, Twist2D(), "odom", "base_footprint", stamp(t_ns))
        if odom_first:
            odom_publisher.publish(odom)
            ros.spin_for(0.05)
        slam_poses[t_ns] = Transform2D(*pose_of(rig.wheels(t_ns, phi)))
        if not odom_first:
            odom_publisher.publish(odom)
        assert ros.spin_until(lambda k=k: len(recorder.sent) >= k + 1, 5.0), "no map -> odom"
        sent = recorder.sent[-1]
        assert (sent.header.frame_id, sent.child_frame_id) == ("map", "odom")
        assert stamp_ns(sent.header.stamp) == t_ns
        T_map_odom = transform_from_pose_msg(sent.transform)
        # /tf's chain map -> odom -> base_footprint is slam's pose at that stamp
        np.testing.assert_allclose(
            (T_map_odom @ T_odom_body).as_array(), slam_poses[t_ns].as_array(), atol=1e-9
        )
    assert len(recorder.sent) == 6, "one map -> odom per pose"


def test_odom_in_other_frames_is_skipped_with_a_warning(ros):
    rig = Rig(ros, observation_timeout=100.0)
    rig.odom.publish(odometry_message(Transform2D(), Twist2D(), "world", "base_footprint", stamp(S)))
    warnings = rig.warnings(at_least=1)
    assert len(warnings) == 1 and "odom skipped" in warnings[0] and "'world'" in warnings[0]


def transform_from_pose_msg(transform) -> Transform2D:
    return Transform2D(
        transform.translation.x, transform.translation.y, yaw_from_quaternion(transform.rotation)
    )


def test_diagnostics_report_the_inputs_and_an_error_when_observations_stop(ros):
    rig = Rig(ros, observation_timeout=100.0)
    arrays: list[DiagnosticArray] = []
    subscription = rig.helper.create_subscription(DiagnosticArray, "/diagnostics", arrays.append, 10)
    assert ros.spin_until(lambda: matched(subscription), 5.0)
    t_ns = S
    dphi = 0.01 / R_WHEEL

    def drive(seconds: float, observe: bool) -> None:
        nonlocal t_ns
        for _ in range(round(seconds * 10)):
            t_ns += S // 10
            rig.joint_states.publish(joint_state(t_ns, (t_ns / S * dphi, t_ns / S * dphi)))
            if observe:
                rig.observations.publish(cylinder_array("base_scan", t_ns, relative(T_BODY_SENSOR)))
            ros.spin_for(0.1)

    def latest() -> dict[str, DiagnosticStatus]:
        return {s.name: s for s in arrays[-1].status}

    drive(1.5, observe=True)
    statuses = latest()
    assert set(statuses) == {
        "slam: joint_states", "slam: motion gate", "slam: landmarks", "slam: filter", "slam: occupancy grid",
        "slam: motion vs LiDAR",
    }  # fmt: skip
    assert statuses["slam: joint_states"].level == DiagnosticStatus.OK
    assert statuses["slam: motion gate"].level == DiagnosticStatus.OK
    assert statuses["slam: motion vs LiDAR"].level == DiagnosticStatus.OK
    assert statuses["slam: occupancy grid"].level == DiagnosticStatus.OK
    assert statuses["slam: landmarks"].level == DiagnosticStatus.OK
    values = {pair.key: pair.value for pair in statuses["slam: filter"].values}
    assert int(values["observations_fused"]) > 0 and "landmarks_mapped" in values
    drive(3.0, observe=False)
    statuses = latest()
    assert statuses["slam: joint_states"].level == DiagnosticStatus.OK
    assert statuses["slam: landmarks"].level == DiagnosticStatus.ERROR
    assert "nothing on landmarks for" in statuses["slam: landmarks"].message


def test_a_phantom_turn_is_reported_and_undone_against_the_map(ros):
    """The wheels report 0.75 rad of turn in place that the body does not make (a slip event); the LiDAR
    keeps seeing the landmarks from the true pose. slam says so in /diagnostics, names the cause, and ends at
    the true pose with the map it had (no landmark beside the true ones)."""
    rig = Rig(ros, observation_timeout=100.0)
    arrays: list[DiagnosticArray] = []
    subscription = rig.helper.create_subscription(DiagnosticArray, "/diagnostics", arrays.append, 10)
    assert ros.spin_until(lambda: matched(subscription), 5.0)
    # left and right wheel angles of a 0.75 rad turn in place: -+ 0.75 (track / 2) / r
    turn_wheel = 0.75 * 0.5 * DRIVE.track_width / R_WHEEL
    levels: list[tuple[int, str]] = []

    def run(seconds: float, phi_at, x_at=lambda f: 0.0) -> None:
        for k in range(1, round(seconds * 10) + 1):
            run.t_ns += S // 10
            f = k / round(seconds * 10)
            rig.joint_states.publish(joint_state(run.t_ns, phi_at(f)))
            if k % 2 == 0:  # scans at 5 Hz, always from the true pose (x_at along x, then at the origin)
                seen = relative(Transform2D(x_at(f), 0.0, 0.0) @ T_BODY_SENSOR)
                rig.observations.publish(cylinder_array("base_scan", run.t_ns, seen))
            ros.spin_for(0.1)
            if arrays:
                motion = {s.name: s for s in arrays[-1].status}["slam: motion vs LiDAR"]
                levels.append((motion.level, motion.message))

    run.t_ns = S
    # three landmarks mapped driving 0.1 m ahead and back (several viewpoints), then at rest
    ahead = 0.1 / R_WHEEL
    run(1.0, lambda f: (ahead * f, ahead * f), lambda f: 0.1 * f)
    run(1.0, lambda f: (ahead * (1.0 - f), ahead * (1.0 - f)), lambda f: 0.1 * (1.0 - f))
    run(1.0, lambda f: (0.0, 0.0))
    run(1.0, lambda f: (-turn_wheel * f, turn_wheel * f))  # the phantom turn, over a second
    run(2.0, lambda f: (-turn_wheel, turn_wheel))
    x, y, yaw = pose_of(rig.odoms[-1])
    assert math.hypot(x, y) < 0.01 and abs(yaw) < 0.01
    assert set(mapped(rig.maps[-1])) == set(range(len(LANDMARKS)))
    reports = [message for level, message in levels if level == DiagnosticStatus.WARN]
    assert any(message.startswith("wheel slip") for message in reports), levels


def test_observations_before_the_first_joint_states_are_dropped_without_a_warning(ros):
    rig = Rig(ros)
    rig.observations.publish(cylinder_array("base_scan", S, relative(T_BODY_SENSOR)))
    ros.spin_for(0.3)
    assert rig.maps == [] and rig.warnings() == []
    # and the node goes on normally once joint_states arrive
    rig.wheels(2 * S, (0.0, 0.0))
    assert rig.observe(cylinder_array("base_scan", 2 * S, relative(T_BODY_SENSOR))).markers


class FixedPoseSource:
    """A second pose source attached to the running node's timeline (as a scan registration will be): its
    payload is a measured pose, fused with EkfSlam.update_pose."""

    def apply(self, slam: EkfSlam, payload: Transform2D, stamp_ns: int) -> StepResult:
        _, fused = slam.update_pose(payload, np.diag([1e-4, 1e-4, 1e-4]))
        return StepResult(Outcome.APPLIED if fused else Outcome.HELD)

    def relocalized(self, T_map_body: Transform2D) -> None:
        """Nothing kept between measurements."""


def test_a_pose_source_attached_to_the_node_moves_its_estimate_and_its_report_takes_it(ros):
    """Review: the node counted every applied measurement as landmark observations and failed on one of
    another kind. A pose source's measurement, applied when the wheels reach its stamp, moves slam's pose
    and the node goes on publishing."""
    rig = Rig(ros, observation_timeout=100.0, initial_xy_std=0.01, initial_theta_std=0.01)
    source = rig.node.timeline.attach(FixedPoseSource())
    t_ns = 10 * S
    rig.wheels(t_ns, (0.0, 0.0))
    rig.node.timeline.add(t_ns + S // 2, source, Transform2D(0.3, 0.0, 0.0))
    odom = rig.wheels(t_ns + S, (0.0, 0.0))
    # standing still: x = 0.3 P / (P + R) with P = R = 1e-4
    assert pose_of(odom) == pytest.approx((0.15, 0.0, 0.0), abs=1e-9)
    assert rig.node.observation_counts["applied"] == 0
