"""nusim in process with real rclpy (fast realtime_factor), plus its executable as a real process.

Assertions compare messages with each other by stamp (joint_states and ground_truth share stamps), never
with wall time, so they hold however fast the machine runs the simulation.
"""

from __future__ import annotations

import math
import signal
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest
from geometry_msgs.msg import PoseWithCovarianceStamped
from nav_msgs.msg import Odometry
from nav_msgs.msg import Path as PathMsg
from rcl_interfaces.msg import Log
from rclpy.parameter import Parameter
from rclpy.qos import DurabilityPolicy, QoSProfile, qos_profile_sensor_data
from rosgraph_msgs.msg import Clock
from sensor_msgs.msg import JointState, LaserScan
from std_srvs.srv import Empty
from visualization_msgs.msg import Marker, MarkerArray

from nusim.house import Boxes, InteriorWalls, Legs
from nusim.nusim_node import FrameConfig, NusimNode, NusimTiming
from nusim.simulation import ArenaConfig, NoiseConfig, Obstacles, Robots, Walls, default_lidar
from nuturtle_description.robot_params import burger_params
from nuturtle_ros_common.conversions import pose_from_transform, stamp_seconds, yaw_from_quaternion
from nuturtle_ros_common.ros_files import load_ros_yaml
from turtlelib import DiffDrive, Transform2D
from turtlelib.geometry.path_trail import PathTrailConfig

pytestmark = pytest.mark.ros

BASIC_WORLD = Path(__file__).resolve().parents[2] / "nusim" / "config" / "basic_world.yaml"
TURTLEBOT3_WORLD = BASIC_WORLD.parent / "turtlebot3_world.yaml"
BURGER = DiffDrive(0.033, 0.16)
MCU_PER_RAD_S = burger_params().motor_cmd_per_rad_sec  # 41.6666667 in models.yaml
HALF_TICK_RAD = 0.5 * 2.0 * math.pi / 4096.0
QUIET = {"input_noise": 0.0, "slip_fraction": 0.0, "basic_sensor_variance": 0.0}
EXACT_LIDAR = {"lidar.noise": 0.0, "lidar.resolution": 0.0}
ROOMS = (("interior_walls", InteriorWalls), ("boxes", Boxes), ("legs", Legs))
ONE_CYLINDER = {"obstacles.x": [1.0], "obstacles.y": [0.0], "obstacles.r": [0.05]}


def parameters(values: dict) -> list[Parameter]:
    return [Parameter(name, value=value) for name, value in values.items()]


def pose_of(odom: Odometry) -> Transform2D:
    pose = odom.pose.pose
    return Transform2D(pose.position.x, pose.position.y, yaw_from_quaternion(pose.orientation))


def matched(*endpoints) -> bool:
    return all(
        (e.get_subscription_count() if hasattr(e, "get_subscription_count") else e.get_publisher_count()) > 0
        for e in endpoints
    )


class Rig:
    """nusim plus a helper node commanding the wheels and recording every output."""

    def __init__(self, ros, **overrides) -> None:
        self.ros = ros
        # commands hold (no timeout) unless a test says otherwise: most tests drive on one command
        values = {"realtime_factor": 20.0, "cmd_timeout": 0.0, **overrides}
        self.node = ros.add(NusimNode(context=ros.context, parameter_overrides=parameters(values)))
        helper = ros.node("nusim_test_helper")
        self.helper = helper
        self.clock: list[Clock] = []
        self.joint_states: list[JointState] = []
        self.scans: list[LaserScan] = []
        self.fake_sensor: list[MarkerArray] = []
        self.ground_truth: list[Odometry] = []
        self.paths: list[PathMsg] = []
        self.logs: list[Log] = []
        self.wheel_cmd = helper.create_publisher(JointState, "wheel_cmd", 10)
        self.teleport = helper.create_publisher(PoseWithCovarianceStamped, "nusim/teleport", 10)
        self.reset = helper.create_client(Empty, "nusim/reset")
        latched = QoSProfile(depth=1000, durability=DurabilityPolicy.TRANSIENT_LOCAL)
        helper.create_subscription(Log, "/rosout", self.logs.append, latched)
        endpoints = [
            self.wheel_cmd,
            self.teleport,
            helper.create_subscription(Clock, "/clock", self.clock.append, 100),
            helper.create_subscription(JointState, "joint_states", self.joint_states.append, 100),
            helper.create_subscription(LaserScan, "scan", self.scans.append, qos_profile_sensor_data),
            helper.create_subscription(MarkerArray, "fake_sensor", self.fake_sensor.append, 100),
            helper.create_subscription(Odometry, "nusim/ground_truth", self.ground_truth.append, 100),
            helper.create_subscription(PathMsg, "nusim/path", self.paths.append, 100),
        ]
        assert ros.spin_until(lambda: matched(*endpoints) and self.reset.service_is_ready(), 10.0)

    def command(self, names, velocities) -> None:
        self.wheel_cmd.publish(JointState(name=list(names), velocity=[float(v) for v in velocities]))

    def spin_until(self, predicate, timeout_s: float = 20.0) -> None:
        assert self.ros.spin_until(predicate, timeout_s)

    def spin_sim_seconds(self, duration_s: float) -> None:
        """Spin until `duration_s` more seconds of simulation time have passed."""
        target = self.node.step_count + round(duration_s * self.node.timing.rate)
        self.spin_until(lambda: self.node.step_count >= target)

    def truth_at(self, stamp) -> Odometry:
        return next(odom for odom in self.ground_truth if odom.header.stamp == stamp)

    def warnings(self) -> list[str]:
        self.ros.spin_for(0.1)
        return [log.msg for log in self.logs if log.name == "nusim" and log.level == Log.WARN]


def test_commanded_wheels_move_the_true_robot_and_the_encoders_as_the_kinematics_say(ros):
    rig = Rig(ros, **QUIET)
    # names in the other order: matched by name, not by position
    rig.command(["wheel_right_joint", "wheel_left_joint"], [4.0, 2.0])
    rig.spin_until(lambda: bool(rig.ground_truth) and pose_of(rig.ground_truth[-1]).x > 0.1)
    rig.spin_sim_seconds(0.1)
    joints = rig.joint_states[-1]
    assert list(joints.name) == ["wheel_left_joint", "wheel_right_joint"]
    # quantised to motor units: round(2 * 41.67) = 83 mcu, round(4 * 41.67) = 167 mcu
    np.testing.assert_allclose(joints.velocity, [83 / MCU_PER_RAD_S, 167 / MCU_PER_RAD_S], rtol=1e-12)
    # one constant command since rest: the true pose is the one arc of the encoder angles
    phi_left, phi_right = joints.position
    expected = BURGER.step(Transform2D(), phi_left, phi_right)
    truth = rig.truth_at(joints.header.stamp)
    np.testing.assert_allclose(
        pose_of(truth).as_array(), expected.as_array(), atol=0.033 * 2 * HALF_TICK_RAD / 0.16 + 1e-9
    )
    assert truth.header.frame_id == "nusim/world" and truth.child_frame_id == "nusim/base_footprint"
    twist = BURGER.body_twist(83 / MCU_PER_RAD_S, 167 / MCU_PER_RAD_S)
    assert truth.twist.twist.linear.x == pytest.approx(twist.vx, rel=1e-9)
    assert truth.twist.twist.angular.z == pytest.approx(twist.omega, rel=1e-9)
    # the path ends at the latest kept true pose, in nusim/world
    assert rig.paths[-1].header.frame_id == "nusim/world" and len(rig.paths[-1].poses) >= 2


def test_the_wheels_stop_cmd_timeout_after_the_last_wheel_cmd(ros):
    rig = Rig(ros, **QUIET, cmd_timeout=0.5)
    rig.command(["wheel_left_joint", "wheel_right_joint"], [3.0, 3.0])
    rig.spin_until(lambda: bool(rig.joint_states) and rig.joint_states[-1].velocity[0] > 0.0)
    started = rig.node.step_count
    rig.spin_until(lambda: list(rig.joint_states[-1].velocity) == [0.0, 0.0])
    # stopped at the first physics step past 0.5 s of simulation time after the command
    assert (rig.node.step_count - started) / rig.node.timing.rate == pytest.approx(0.5, abs=0.1)
    rig.spin_sim_seconds(0.1)
    x = pose_of(rig.ground_truth[-1]).x
    assert x > 0.03
    rig.spin_sim_seconds(0.5)
    assert pose_of(rig.ground_truth[-1]).x == pytest.approx(x, abs=1e-12)


def test_clock_steps_by_one_over_rate_and_streams_publish_on_their_grids(ros):
    rig = Rig(ros)
    rig.spin_until(lambda: len(rig.scans) >= 3 and len(rig.fake_sensor) >= 3)
    clock_s = np.array([stamp_seconds(msg.clock) for msg in rig.clock])
    steps = np.round(clock_s * 100.0)
    np.testing.assert_allclose(clock_s, steps / 100.0, atol=1e-9)
    assert np.all(np.diff(steps) == 1)  # every step, none skipped (depth 100 and a local subscriber)
    streams = [
        ([m.header.stamp for m in rig.joint_states], 0.05),
        ([m.header.stamp for m in rig.scans], 0.2),
        ([m.markers[0].header.stamp for m in rig.fake_sensor], 0.2),
    ]
    for stamps, period_s in streams:
        stamps_s = np.array([stamp_seconds(stamp) for stamp in stamps])
        np.testing.assert_allclose(stamps_s / period_s, np.round(stamps_s / period_s), atol=1e-6)
        assert np.all(np.diff(stamps_s) > 0)
    # the default world: eight landmarks, three or more of them in range from the origin
    ids = {m.id for m in rig.fake_sensor[-1].markers}
    assert ids == set(range(8))


def test_scan_at_the_start_pose_sees_the_cylinder_ahead_and_the_walls(ros):
    rig = Rig(ros, arena_x_length=4.0, arena_y_length=3.0, **ONE_CYLINDER, **EXACT_LIDAR)
    rig.spin_until(lambda: bool(rig.scans))
    scan = rig.scans[-1]
    assert scan.header.frame_id == "base_scan"
    assert scan.angle_min == 0.0
    assert scan.angle_increment == pytest.approx(math.radians(1.0), rel=1e-7)
    assert scan.angle_max == pytest.approx(math.radians(359.0), rel=1e-7)
    assert (scan.range_min, scan.range_max) == pytest.approx((0.12, 3.5), rel=1e-7)
    assert scan.scan_time == pytest.approx(0.2, rel=1e-7)
    assert scan.time_increment == 0.0
    ranges = np.array(scan.ranges)
    assert ranges.shape == (360,)
    # LiDAR at x = -0.032 m: cylinder face at 1 - 0.05 + 0.032, walls x = -2 and y = +-1.5
    np.testing.assert_allclose(ranges[[0, 90, 180, 270]], [0.982, 1.5, 1.968, 1.5], rtol=1e-6)


def test_fake_sensor_reports_landmarks_in_range_by_id_and_deletes_the_others(ros):
    rig = Rig(
        ros,
        **{
            "obstacles.x": [0.5, 0.0, -3.0],
            "obstacles.y": [0.0, 1.5, 0.0],
            "obstacles.r": [0.05, 0.04, 0.05],
        },
        arena_x_length=8.0,
        arena_y_length=8.0,
        basic_sensor_variance=1e-6,
    )
    rig.spin_until(lambda: bool(rig.fake_sensor))
    markers = {m.id: m for m in rig.fake_sensor[-1].markers}
    assert sorted(markers) == [0, 1, 2]
    assert markers[2].action == Marker.DELETE
    for j, (x, y, r) in {0: (0.5, 0.0, 0.05), 1: (0.0, 1.5, 0.04)}.items():
        marker = markers[j]
        assert (marker.action, marker.type) == (Marker.ADD, Marker.CYLINDER)
        assert marker.header.frame_id == "base_footprint"
        assert marker.scale.x == marker.scale.y == pytest.approx(2 * r)
        assert (marker.pose.position.x, marker.pose.position.y) == pytest.approx((x, y), abs=5e-3)


def test_obstacles_and_walls_are_latched_red_markers_in_the_world_frame(ros):
    rig = Rig(ros, arena_x_length=4.0, arena_y_length=3.0, **ONE_CYLINDER)
    obstacles: list[MarkerArray] = []
    walls: list[MarkerArray] = []
    latched = QoSProfile(depth=1, durability=DurabilityPolicy.TRANSIENT_LOCAL)
    # subscribed after they were published: transient local delivers them
    rig.helper.create_subscription(MarkerArray, "nusim/obstacles", obstacles.append, latched)
    rig.helper.create_subscription(MarkerArray, "nusim/walls", walls.append, latched)
    rig.spin_until(lambda: bool(obstacles) and bool(walls))
    (cylinder,) = obstacles[0].markers
    assert cylinder.header.frame_id == "nusim/world" and cylinder.type == Marker.CYLINDER
    position = cylinder.pose.position
    assert (position.x, position.y, cylinder.scale.x) == pytest.approx((1.0, 0.0, 0.1))
    assert len(walls[0].markers) == 4
    for marker in obstacles[0].markers + walls[0].markers:
        assert (marker.color.r, marker.color.g, marker.color.b) == (1.0, 0.0, 0.0)
    # the walls' inner faces are the arena's bounds: each wall turned by yaw along its face, whose normal
    # (-sin yaw, cos yaw) is scale.y / 2 nearer the centre than the marker's
    inner = []
    for m in walls[0].markers:
        yaw = yaw_from_quaternion(m.pose.orientation)
        normal_m = -math.sin(yaw) * m.pose.position.x + math.cos(yaw) * m.pose.position.y
        inner.append(abs(normal_m) - m.scale.y / 2)
    assert sorted(inner) == pytest.approx([1.5, 1.5, 2.0, 2.0])


def test_collision_stops_the_true_robot_while_the_encoders_keep_counting(ros):
    rig = Rig(ros, **QUIET, **{"obstacles.x": [0.5], "obstacles.y": [0.0], "obstacles.r": [0.05]})
    rig.command(["wheel_left_joint", "wheel_right_joint"], [6.0, 6.0])
    # contact where the centre is R + r = 0.16 m from the cylinder, i.e. at x = 0.34 m
    rig.spin_until(lambda: bool(rig.ground_truth) and pose_of(rig.ground_truth[-1]).x > 0.3399)
    rig.spin_sim_seconds(0.5)
    assert pose_of(rig.ground_truth[-1]).as_array() == pytest.approx([0.34, 0.0, 0.0], abs=1e-9)
    assert max(pose_of(odom).x for odom in rig.ground_truth) <= 0.34 + 1e-12
    # wheels turning against the cylinder: more rotation than the body moved
    assert rig.joint_states[-1].position[0] > 0.34 / 0.033 + 2.0


def test_reset_returns_to_the_start_pose_and_time_runs_on(ros):
    rig = Rig(ros, x0=0.5, y0=-0.5, theta0=1.0)
    rig.command(["wheel_left_joint", "wheel_right_joint"], [5.0, 3.0])
    rig.spin_until(lambda: bool(rig.ground_truth) and pose_of(rig.ground_truth[-1]).x < 0.45)
    before_s = stamp_seconds(rig.ground_truth[-1].header.stamp)
    future = rig.reset.call_async(Empty.Request())
    rig.spin_until(future.done)
    count = len(rig.ground_truth)
    rig.spin_until(lambda: len(rig.ground_truth) > count)
    after = rig.ground_truth[-1]
    assert pose_of(after).as_array() == pytest.approx([0.5, -0.5, 1.0], abs=1e-12)
    assert stamp_seconds(after.header.stamp) > before_s
    # at rest until the next command
    rig.spin_sim_seconds(0.2)
    assert pose_of(rig.ground_truth[-1]).as_array() == pytest.approx([0.5, -0.5, 1.0], abs=1e-12)


def teleport_message(T: Transform2D, frame_id: str = "nusim/world") -> PoseWithCovarianceStamped:
    msg = PoseWithCovarianceStamped()
    msg.header.frame_id = frame_id
    msg.pose.pose = pose_from_transform(T)
    return msg


def test_teleport_moves_the_robot_and_refuses_collisions_and_other_frames(ros):
    rig = Rig(ros, **ONE_CYLINDER)
    rig.teleport.publish(teleport_message(Transform2D(-1.0, 0.5, -2.0)))
    rig.spin_until(lambda: bool(rig.ground_truth) and pose_of(rig.ground_truth[-1]).x == pytest.approx(-1.0))
    assert pose_of(rig.ground_truth[-1]).as_array() == pytest.approx([-1.0, 0.5, -2.0], abs=1e-12)
    rig.teleport.publish(teleport_message(Transform2D(1.05, 0.0, 0.0)))  # inside the cylinder
    rig.teleport.publish(teleport_message(Transform2D(0.0, 0.0, 0.0), frame_id="map"))
    rig.spin_until(lambda: len(rig.warnings()) >= 1)
    rig.spin_sim_seconds(0.2)
    assert pose_of(rig.ground_truth[-1]).as_array() == pytest.approx([-1.0, 0.5, -2.0], abs=1e-12)
    warnings = " ".join(rig.warnings())
    assert "teleport refused" in warnings and "overlaps obstacle 0" in warnings


@pytest.mark.parametrize(
    "orientation",
    [(0.0, 0.0, 0.0, 0.0), (0.0, 0.0, math.inf, -math.inf), (0.0, 0.0, 1.0, 1.0)],
    ids=["zero", "infinite", "norm sqrt(2)"],
)
def test_a_teleport_whose_quaternion_is_not_a_rotation_is_refused(ros, orientation):
    """Issue: a zero or non-finite quaternion was accepted (a yaw from atan2(0, 0) or atan2(inf, -inf))."""
    rig = Rig(ros, **ONE_CYLINDER)
    msg = teleport_message(Transform2D(-1.0, 0.5, 0.0))
    q = msg.pose.pose.orientation
    q.x, q.y, q.z, q.w = orientation
    rig.teleport.publish(msg)
    rig.spin_until(lambda: len(rig.warnings()) >= 1)
    rig.spin_sim_seconds(0.2)
    start = (rig.node.simulation.config.arena.T_world_start).as_array()
    assert pose_of(rig.ground_truth[-1]).as_array() == pytest.approx(start, abs=1e-12)
    (warning,) = rig.warnings()
    assert "teleport refused" in warning and "not a rotation" in warning


@pytest.mark.parametrize(
    ("names", "velocities", "reason"),
    [
        (["wheel_left_joint"], [1.0], "'wheel_right_joint' is missing"),
        (["wheel_left_joint", "wheel_right_joint"], [math.nan, 1.0], "non-finite"),
        (["wheel_left_joint", "wheel_right_joint"], [1.0], "2 joint names but 1 values"),
    ],
)
def test_bad_wheel_commands_are_skipped_with_a_warning(ros, names, velocities, reason):
    rig = Rig(ros)
    rig.command(names, velocities)
    rig.spin_until(lambda: any(reason in w for w in rig.warnings()))
    rig.spin_sim_seconds(0.3)
    assert pose_of(rig.ground_truth[-1]).as_array() == pytest.approx([0.0, 0.0, 0.0], abs=0.0)


def test_the_default_parameters_are_the_basic_world_yaml():
    world = load_ros_yaml(BASIC_WORLD)
    flat = {k: v for k, v in world.items() if not isinstance(v, dict)}
    for group in ("obstacles", "lidar", "walls", "interior_walls", "boxes", "legs", "robots"):
        flat.update({f"{group}.{k}": v for k, v in world[group].items()})
    defaults = {
        **vars(NusimTiming()),
        **vars(ArenaConfig()),
        **vars(NoiseConfig()),
        **{f"obstacles.{k}": list(v) for k, v in vars(Obstacles()).items()},
        **{f"walls.{k}": list(v) for k, v in vars(Walls()).items()},
        **{f"{group}.{k}": list(v) for group, cls in ROOMS for k, v in vars(cls()).items()},
        **{f"lidar.{k}": v for k, v in vars(default_lidar()).items()},
        "lidar_model": "lds01",
        "wheel_left": "wheel_left_joint",
        "wheel_right": "wheel_right_joint",
        "cmd_timeout": 0.5,
        **vars(PathTrailConfig()),
        **{f"robots.{k}": list(v) for k, v in vars(Robots()).items()},
        **vars(FrameConfig()),
    }
    assert flat == defaults


def test_parameters_from_the_world_file_give_the_default_world(ros):
    world = load_ros_yaml(BASIC_WORLD)
    flat = {k: v for k, v in world.items() if not isinstance(v, dict)}
    for group in ("obstacles", "lidar", "walls", "interior_walls", "boxes", "legs"):
        flat.update({f"{group}.{k}": v for k, v in world[group].items()})
    from_file = ros.add(NusimNode(context=ros.context, parameter_overrides=parameters(flat)))
    default = ros.add(NusimNode(context=ros.context))
    assert from_file.simulation.config == default.simulation.config
    assert from_file.timing == default.timing


@pytest.mark.parametrize(
    ("overrides", "message"),
    [
        ({"arena_x_length": -1.0}, "arena_x_length must be finite and > 0"),
        ({"obstacles.x": [1.0, 2.0]}, "same length, got 2, 8 and 8"),
        ({"obstacles.r": [0.0] * 8}, r"obstacles.r\[0\] must be finite and > 0"),
        ({"obstacles.x": "nowhere"}, "parameter obstacles.x must be of type tuple"),
        ({"x0": 1.41, "y0": 0.3}, "overlaps obstacle 0"),
        ({"x0": 3.0}, "is not inside the arena"),
        ({"rate": 0.0}, "rate must be finite and > 0"),
        ({"realtime_factor": -2.0}, "realtime_factor must be finite and > 0"),
        ({"joint_states_rate": 200.0}, r"joint_states_rate \(200.0 Hz\) cannot exceed the physics rate"),
        ({"lidar.samples": 0}, "lidar samples must be >= 1"),
        ({"lidar_model": "lds03"}, r"lidar_model must be one of \('lds01', 'lds02', 'gazebo'\)"),
        ({"slip_fraction": 1.5}, r"slip_fraction must be in \[0.0, 1.0\)"),
        ({"collision_radius": 0.0}, "collision_radius must be finite and > 0"),
    ],
)
def test_invalid_parameters_stop_construction_with_their_reason(ros, overrides, message):
    with pytest.raises(ValueError, match=message):
        NusimNode(context=ros.context, parameter_overrides=parameters(overrides))


def test_executable_runs_the_world_file_and_publishes_until_interrupted(ros, tmp_path):
    process = subprocess.Popen(
        [
            sys.executable,
            "-m",
            "nusim.nusim_node",
            "--ros-args",
            "--params-file",
            str(BASIC_WORLD),
            "-p",
            "realtime_factor:=5.0",
        ],
        cwd=tmp_path,
        stdout=subprocess.PIPE,
        stderr=subprocess.STDOUT,
        text=True,
    )
    try:
        helper = ros.node("nusim_process_listener")
        markers: list[MarkerArray] = []
        helper.create_subscription(MarkerArray, "fake_sensor", markers.append, 10)
        assert ros.spin_until(lambda: bool(markers), 30.0), "no fake_sensor from the process"
        # the eight cylinders of the world file
        assert {m.id for m in markers[-1].markers} == set(range(8))
    finally:
        process.send_signal(signal.SIGINT)
        output, _ = process.communicate(timeout=15)
    assert process.returncode == 0, output


def test_turtlebot3_world_from_its_params_file():
    """`ros2 run nusim nusim --ros-args --params-file nusim/config/turtlebot3_world.yaml`, as rcl reads it:
    the hexagon's six walls, nine 0.15 m cylinders on the 1.1 m grid, the spawn at (-2.0, -0.5) facing +x."""
    import rclpy
    from rclpy.context import Context

    context = Context()
    rclpy.init(context=context, args=["--ros-args", "--params-file", str(TURTLEBOT3_WORLD)])
    try:
        node = NusimNode(context=context)
        simulation = node.simulation
        assert simulation.walls.shape == (6, 4)
        np.testing.assert_allclose(np.abs(simulation.walls[:, [1, 3]]).max(), 2.54)
        np.testing.assert_allclose(
            sorted(map(tuple, simulation.circles)),
            sorted((x, y, 0.15) for x in (-1.1, 0.0, 1.1) for y in (-1.1, 0.0, 1.1)),
        )
        assert simulation.T_world_body.as_array() == pytest.approx([-2.0, -0.5, 0.0])
        node.destroy_node()
    finally:
        rclpy.try_shutdown(context=context)


def test_rooms_world_from_its_params_file_is_simulated_and_shown():
    """`--params-file nusim/config/rooms_posts_world.yaml` as rcl reads it: nine interior walls, eight boxes,
    six pieces on legs (24 legs) and five posts, all on the latched markers (walls and boxes on ~/walls,
    posts and legs on ~/obstacles)."""
    import rclpy
    from rclpy.context import Context
    from rclpy.executors import SingleThreadedExecutor

    context = Context()
    rclpy.init(
        context=context,
        args=["--ros-args", "--params-file", str(BASIC_WORLD.parent / "rooms_posts_world.yaml")],
    )
    executor = SingleThreadedExecutor(context=context)
    try:
        node = NusimNode(stepped_by_owner=True, context=context)
        world = node.simulation.world
        assert (world.interior.shape, world.boxes.shape) == ((9, 4), (8, 4, 2))
        assert (world.landmarks.shape, world.legs.shape) == ((5, 3), (24, 3))
        helper = rclpy.create_node("rooms_listener", context=context)
        latched = QoSProfile(depth=1, durability=DurabilityPolicy.TRANSIENT_LOCAL)
        received: dict[str, MarkerArray] = {}
        for topic in ("nusim/walls", "nusim/obstacles"):
            helper.create_subscription(
                MarkerArray, topic, lambda msg, t=topic: received.setdefault(t, msg), latched
            )
        executor.add_node(helper)
        for _ in range(200):
            if len(received) == 2:
                break
            executor.spin_once(timeout_sec=0.05)
        namespaces = {topic: sorted({(m.ns, m.id) for m in msg.markers}) for topic, msg in received.items()}
        assert namespaces["nusim/walls"] == sorted(
            [("walls", k) for k in range(4)]
            + [("interior_walls", k) for k in range(9)]
            + [("boxes", b) for b in range(8)]
        )
        assert namespaces["nusim/obstacles"] == sorted(
            [("obstacles", j) for j in range(5)] + [("legs", k) for k in range(24)]
        )
        # the sofa: 2.0 m x 0.8 m centred at (-2.6, -2.55)
        sofa = next(m for m in received["nusim/walls"].markers if (m.ns, m.id) == ("boxes", 0))
        assert (sofa.pose.position.x, sofa.pose.position.y, sofa.scale.x, sofa.scale.y) == pytest.approx(
            (-2.6, -2.55, 2.0, 0.8)
        )
        helper.destroy_node()
        node.destroy_node()
    finally:
        executor.shutdown()
        rclpy.try_shutdown(context=context)


def test_two_robots_publish_under_their_names_with_prefixed_frames_and_see_each_other(ros):
    """robots.names [tb3_0, tb3_1]: each robot's streams under its name, its frames prefixed, its own
    wheel_cmd; tb3_0's scan sees tb3_1 where its ground truth puts it. A one-robot nusim under a namespace
    with frame_prefix publishes the same names; /clock stays global."""
    robots = {"robots.names": ["tb3_0", "tb3_1"], "robots.x0": [-0.5, 0.5], "robots.y0": [0.0, 0.0]}
    robots["robots.theta0"] = [0.0, math.pi]
    values = {"realtime_factor": 20.0, "cmd_timeout": 0.0, **QUIET, **EXACT_LIDAR, **robots}
    node = ros.add(NusimNode(context=ros.context, parameter_overrides=parameters(values)))
    alone = {"realtime_factor": 20.0, "frame_prefix": "tb3_9/", **QUIET}
    ros.add(NusimNode(context=ros.context, namespace="tb3_9", parameter_overrides=parameters(alone)))
    helper = ros.node("nusim_robots_listener")
    received: dict[str, list] = {}
    endpoints = []
    streams = [("scan", LaserScan), ("fake_sensor", MarkerArray), ("nusim/ground_truth", Odometry)]
    for name in ("tb3_0", "tb3_1", "tb3_9"):
        for topic, message_type in streams:
            qos = qos_profile_sensor_data if topic == "scan" else 100
            received[f"/{name}/{topic}"] = messages = []
            endpoints.append(
                helper.create_subscription(message_type, f"/{name}/{topic}", messages.append, qos)
            )
    wheel_cmd = helper.create_publisher(JointState, "/tb3_1/wheel_cmd", 10)
    endpoints.append(wheel_cmd)
    assert ros.spin_until(lambda: matched(*endpoints), 10.0)
    # tb3_1 (facing -x) drives towards tb3_0 at 0.1 m/s; tb3_0 gets no command
    wheel_cmd.publish(JointState(name=["wheel_left_joint", "wheel_right_joint"], velocity=[3.0, 3.0]))
    assert ros.spin_until(lambda: len(received["/tb3_0/scan"]) >= 4 and len(received["/tb3_9/scan"]), 20.0)
    for name in ("tb3_0", "tb3_1", "tb3_9"):
        assert received[f"/{name}/scan"][-1].header.frame_id == f"{name}/base_scan"
        truth = received[f"/{name}/nusim/ground_truth"][-1]
        assert (truth.header.frame_id, truth.child_frame_id) == (
            "nusim/world",
            f"nusim/{name}/base_footprint",
        )
        assert {m.header.frame_id for m in received[f"/{name}/fake_sensor"][-1].markers} == {
            f"{name}/base_footprint"
        }
    truth_0, truth_1 = (received[f"/tb3_{k}/nusim/ground_truth"] for k in range(2))
    assert pose_of(truth_0[-1]).as_array() == pytest.approx([-0.5, 0.0, 0.0], abs=1e-12)
    assert pose_of(truth_1[-1]).x < 0.5 - 0.01, "tb3_1 drove on its own wheel_cmd"
    truth_1_at = {stamp_seconds(t.header.stamp): pose_of(t).x for t in truth_1}
    scans = [scan for scan in received["/tb3_0/scan"] if stamp_seconds(scan.header.stamp) in truth_1_at]
    assert len(scans) >= 3
    for scan in scans:
        # beam 0 from tb3_0's sensor at (-0.532, 0) ends on tb3_1's disc (R = 0.11 m) around (x1, 0)
        x1 = truth_1_at[stamp_seconds(scan.header.stamp)]
        assert scan.ranges[0] == pytest.approx(x1 - (-0.5 - 0.032) - 0.11, abs=1e-6)
    # both nusims drive the one global /clock
    assert node.count_publishers("/clock") == 2


def test_a_frame_prefix_is_namespace_tokens_and_not_given_with_several_robots(ros):
    assert FrameConfig("tb3_0/").frame_prefix == "tb3_0/" and FrameConfig("a/b_1/").frame_prefix == "a/b_1/"
    for bad in ("tb3_0", "/tb3_0/", "0a/", "a//"):
        with pytest.raises(ValueError, match="frame_prefix must be empty or namespace tokens"):
            FrameConfig(bad)
    values = {"frame_prefix": "x/", "robots.names": ["tb3_0"], "robots.x0": [0.0], "robots.y0": [0.0]}
    values["robots.theta0"] = [0.0]
    with pytest.raises(ValueError, match="frame_prefix \\('x/'\\) must be empty with robots.names"):
        NusimNode(context=ros.context, parameter_overrides=parameters(values))
