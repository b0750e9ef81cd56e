"""`nusim`: a simulated TurtleBot3 (any model) in an arena of cylinders or in rooms, publishing what the real
robot does.

A thin ROS wrapper over `nusim.simulation.MultiRobotSimulation` (models in that module's docstring): one
robot, or several in one world (`robots.names`, below).

Subscribes
    `wheel_cmd` (sensor_msgs/JointState): `velocity` (rad/s) of joints `wheel_left`, `wheel_right`
        (matched by name), quantised and clamped to motor units; held until the next command, or for
        `cmd_timeout` s of simulation time, after which the wheels stop (as the robot's firmware does).
    `~/teleport` (geometry_msgs/PoseWithCovarianceStamped, frame `nusim/world` or empty): moves the robot
        to the pose's (x, y, yaw); refused (with a warning) if its disc would overlap a cylinder or a wall.
Publishes (all stamped with simulation time)
    `/clock` (rosgraph_msgs/Clock): every physics step.
    `joint_states` (sensor_msgs/JointState, at `joint_states_rate`): encoder wheel angles (rad, quantised
        to ticks) and wheel speeds (rad/s) of `wheel_left`, `wheel_right`.
    `scan` (sensor_msgs/LaserScan, frame `base_scan`, sensor-data QoS like the real LDS-01, at
        `scan_rate`): every beam is cast from the pose at the stamp, so `time_increment` is 0; layout,
        range limits and no-return value those of `lidar_model` (LDS-01, LDS-02 or Gazebo's).
    `fake_sensor` (visualization_msgs/MarkerArray, frame `base_footprint`, at `fake_sensor_rate`): one
        CYLINDER per landmark within `max_range` (id = obstacle index, noisy centre, diameter as scale,
        ADD) and a DELETE for each landmark out of range.
    `~/ground_truth` (nav_msgs/Odometry, `nusim/world` -> `nusim/base_footprint`, true pose and body
        twist) and `~/path` (nav_msgs/Path, decimated by `PathTrailConfig`), with the same stamps as
        `joint_states`; `/tf` `nusim/world` -> `nusim/base_footprint` where tf2_msgs is installed.
    `~/obstacles` (visualization_msgs/MarkerArray, frame `nusim/world`, transient local): the cylinders
        (namespace `obstacles`, red, id = landmark index) and the placed legs (`legs`, brown).
    `~/walls` (the same): the arena's walls (`walls`, red), the interior walls (`interior_walls`, red) and
        the boxes (`boxes`, brown).
Services
    `~/reset` (std_srvs/Empty): back to (x0, y0, theta0), at rest; the encoders keep their count and time
        runs on (nodes on /clock never see time jump back, odometry sees no wheel motion).
Parameters
    `NusimTiming` (rate, realtime_factor, joint_states_rate, scan_rate, fake_sensor_rate), `ArenaConfig`
    (x0, y0, theta0, arena_x_length, arena_y_length), `Walls` (walls.x, walls.y: a polygon of walls instead
    of the rectangle), `Obstacles` (obstacles.x, obstacles.y, obstacles.r), the rooms of `nusim.house`:
    `InteriorWalls` (interior_walls.x0, .y0, .x1, .y1), `Boxes` (boxes.x, .y, .length, .width, .yaw),
    `Legs` (legs.x_min, .x_max, .y_min, .y_max, .yaw_min, .yaw_max, .length, .width, .r),
    `NoiseConfig` (input_noise, slip_fraction, basic_sensor_variance, max_range, seed), `LidarChoice`
    (lidar_model), `LidarConfig` (lidar.*, defaults from lidar_model), `model`, then `RobotParams` (that
    model's constants by default), `WheelJoints` (wheel_left, wheel_right), `CommandTimeoutConfig`
    (cmd_timeout), `PathTrailConfig` (path_*). The defaults are the default world of
    config/basic_world.yaml. Invalid values stop the node at start-up with a message (exit code 1).

Frames: the robot's frames carry `frame_prefix` (e.g. `tb3_0/`: `tb3_0/base_footprint`, `tb3_0/base_scan`,
and the true pose's child frame `nusim/tb3_0/base_footprint`; robot_state_publisher's convention); the
world frame `nusim/world` is the one world's. Started under a namespace (nusim.launch.py's `namespace`)
with the matching prefix, one robot's streams are that namespace's (`/tb3_0/scan`,
`/tb3_0/nusim/ground_truth`); `/clock` and `/tf` stay global.

Several robots: with `robots.names` (e.g. `[tb3_0, tb3_1]`) and their start poses `robots.x0`,
`robots.y0`, `robots.theta0` (`nusim.simulation.Robots`; then `x0`, `y0`, `theta0` are unused and
`frame_prefix` must be empty) one node simulates them all in one world, each seen by the others' LiDAR
and met by them as a cylinder of its collision radius. Robot `tb3_0` has the topics above under its name:
it subscribes `tb3_0/wheel_cmd` and `tb3_0/nusim/teleport` and publishes `tb3_0/joint_states`,
`tb3_0/scan`, `tb3_0/fake_sensor`, `tb3_0/nusim/ground_truth` and `tb3_0/nusim/path` (what a nusim
under the namespace `tb3_0` would), with the frame prefix `tb3_0/`; `/clock`, `~/obstacles`, `~/walls`
and `~/reset` (every robot to its start) are the world's, once.

Time: a wall-clock (steady) timer ticks at `rate * realtime_factor` Hz and each tick advances simulation
time by `1 / rate` s, so the node needs no `use_sim_time` itself; every other node runs on its /clock.
Built with ``stepped_by_owner``, it has no timer and its owner calls ``step()`` (the demo, in lockstep with
its executor: nuturtle_demo.lockstep).
A stream of `f` Hz is published after step k when ``floor(k f / rate)`` increases.
"""

from __future__ import annotations

import math
import re
import sys
from dataclasses import dataclass
from functools import partial

import numpy as np
from builtin_interfaces.msg import Time
from geometry_msgs.msg import PoseWithCovarianceStamped
from nav_msgs.msg import Odometry
from numpy.typing import NDArray
from rclpy.clock import Clock, ClockType
from rclpy.node import Node
from rclpy.qos import DurabilityPolicy, QoSProfile, qos_profile_sensor_data
from rosgraph_msgs.msg import Clock as ClockMsg
from sensor_msgs.msg import JointState, LaserScan
from std_srvs.srv import Empty
from visualization_msgs.msg import Marker, MarkerArray

from nuturtle_description.robot_declaration import declare_robot
from nuturtle_ros_common.command_timeout import CommandTimeoutConfig, CommandWatchdog
from nuturtle_ros_common.conversions import (
    odometry_message,
    quaternion_from_yaw,
    stamp_from_seconds,
    transform_from_pose,
    transform_stamped,
)
from nuturtle_ros_common.markers import MARKER_HEIGHT_M, cylinder_marker, set_color
from nuturtle_ros_common.node_main import run_node
from nuturtle_ros_common.path_topic import PathTopic
from nuturtle_ros_common.ros_params import declare_dataclass
from nuturtle_ros_common.tf_compat import OptionalTfBroadcaster
from nuturtle_ros_common.throttle import WARN_THROTTLE_S
from nuturtle_ros_common.wheel_joints import WheelJoints, wheel_values
from turtlelib import Twist2D
from turtlelib.geometry.path_trail import PathTrailConfig
from turtlelib.sensing.scan_model import LidarConfig
from turtlelib.util.timebase import NS_PER_S
from turtlelib.util.validation import positive, store

from .house import Boxes, InteriorWalls, Legs, WorldGeometry
from .simulation import (
    ROBOT_NAME,
    ArenaConfig,
    LidarChoice,
    MultiRobotSimulation,
    NoiseConfig,
    Obstacles,
    Robots,
    Simulation,
    SimulationConfig,
    Walls,
)

WORLD_FRAME = "nusim/world"
# the true body frame is TRUE_FRAME_NAMESPACE + frame_prefix + BODY_FRAME (nusim/base_footprint)
TRUE_FRAME_NAMESPACE = "nusim/"
BODY_FRAME = "base_footprint"
SCAN_FRAME = "base_scan"
# A frame prefix: empty, or namespace tokens (as robot names) each ended by "/"
FRAME_PREFIX = re.compile(f"({ROBOT_NAME.pattern}/)*")
# Wall thickness (m): display only (an interior wall has none: it is shown this thin).
WALL_THICKNESS_M = 0.1
INTERIOR_WALL_THICKNESS_M = 0.02
RED = (1.0, 0.0, 0.0, 1.0)
BROWN = (0.55, 0.35, 0.15, 1.0)
YELLOW = (1.0, 0.85, 0.0, 1.0)


@dataclass(frozen=True)
class NusimTiming:
    """Physics rate `rate` and the publishing rates `joint_states_rate`, `scan_rate`, `fake_sensor_rate`
    (Hz, finite, > 0; no stream faster than `rate`), and the `realtime_factor` (> 0) of simulation time
    over wall time."""

    rate: float = 100.0
    realtime_factor: float = 1.0
    joint_states_rate: float = 20.0
    scan_rate: float = 5.0
    fake_sensor_rate: float = 5.0

    def __post_init__(self) -> None:
        streams = ("joint_states_rate", "scan_rate", "fake_sensor_rate")
        store(self, ("rate", "realtime_factor", *streams), positive)
        for name in streams:
            if getattr(self, name) > self.rate:
                raise ValueError(
                    f"{name} ({getattr(self, name)} Hz) cannot exceed the physics rate ({self.rate} Hz)"
                )

    def due(self, step: int, stream_hz: float) -> bool:
        """Whether a stream of `stream_hz` publishes after physics step `step` (>= 1)."""
        # floor(k f / rate) > floor((k - 1) f / rate)
        return math.floor(step * stream_hz / self.rate) > math.floor((step - 1) * stream_hz / self.rate)


@dataclass(frozen=True)
class FrameConfig:
    """`frame_prefix`: what the robot's frame ids start with (`base_footprint`, `base_scan`, and the true
    pose's `nusim/<frame_prefix>base_footprint`): empty (the default) or namespace tokens each ended by
    `/`, such as `tb3_0/` (robot_state_publisher's `frame_prefix`)."""

    frame_prefix: str = ""

    def __post_init__(self) -> None:
        if not isinstance(self.frame_prefix, str) or FRAME_PREFIX.fullmatch(self.frame_prefix) is None:
            raise ValueError(
                "frame_prefix must be empty or namespace tokens each ended by '/' (such as 'tb3_0/'), got "
                f"{self.frame_prefix!r}"
            )


@dataclass(frozen=True)
class RobotFrames:
    """One robot's frame ids: ``body`` (base_footprint), ``scan`` (base_scan) and ``true_body`` (the true
    pose's child frame), each with the robot's ``prefix``."""

    body: str
    scan: str
    true_body: str

    @classmethod
    def with_prefix(cls, prefix: str) -> RobotFrames:
        return cls(prefix + BODY_FRAME, prefix + SCAN_FRAME, TRUE_FRAME_NAMESPACE + prefix + BODY_FRAME)


class RobotPorts:
    """Robot ``index``'s topics on ``node`` and what goes with them: named ``name`` (its topics under
    ``name/``, its private ones under ``name/<node name>/``) or, for the one robot, ``""`` (the node's
    own); its ``frames``, its ``~/path`` and its wheel_cmd watchdog."""

    def __init__(
        self,
        node: NusimNode,
        index: int,
        name: str,
        frames: RobotFrames,
        path_config: PathTrailConfig,
        timeout: CommandTimeoutConfig,
    ) -> None:
        self.name = name
        self.frames = frames
        topic = f"{name}/" if name else ""
        private = f"{name}/{node.get_name()}/" if name else "~/"
        self.path = PathTopic(node, private + "path", path_config)
        self.watchdog = CommandWatchdog(timeout)
        self.joint_states = node.create_publisher(JointState, topic + "joint_states", 10)
        self.scan = node.create_publisher(LaserScan, topic + "scan", qos_profile_sensor_data)
        self.fake_sensor = node.create_publisher(MarkerArray, topic + "fake_sensor", 10)
        self.ground_truth = node.create_publisher(Odometry, private + "ground_truth", 10)
        self.subscriptions = (
            (JointState, topic + "wheel_cmd", partial(node.on_wheel_cmd, index)),
            (PoseWithCovarianceStamped, private + "teleport", partial(node.on_teleport, index)),
        )

    def says(self, text: str) -> str:
        """``text`` naming the robot when there are several."""
        return f"{self.name}: {text}" if self.name else text


def box_marker(
    ns: str, index: int, centre: NDArray[np.float64], yaw: float, size: tuple[float, float], stamp: Time
) -> Marker:
    """A CUBE standing on the floor (frame nusim/world): centre ``(x, y)`` (m), turned by ``yaw`` (rad),
    ``size`` (length along its heading, width across; m), MARKER_HEIGHT_M tall, red."""
    marker = Marker(ns=ns, id=index, type=Marker.CUBE, action=Marker.ADD)
    marker.header.frame_id = WORLD_FRAME
    marker.header.stamp = stamp
    marker.pose.position.x = float(centre[0])
    marker.pose.position.y = float(centre[1])
    marker.pose.position.z = 0.5 * MARKER_HEIGHT_M
    marker.pose.orientation = quaternion_from_yaw(yaw)
    marker.scale.x, marker.scale.y, marker.scale.z = float(size[0]), float(size[1]), MARKER_HEIGHT_M
    set_color(marker, RED)
    return marker


def wall_markers(walls: NDArray[np.float64], stamp: Time) -> MarkerArray:
    """One CUBE of WALL_THICKNESS_M per wall segment ``[x0, y0, x1, y1]`` of the arena's closed polygon, just
    outside its inner face (frame nusim/world): centred on the segment's midpoint moved ``t / 2`` along its
    outward normal, ``L + 2 t`` long (closing the corners), turned along the segment."""
    t = WALL_THICKNESS_M
    e = walls[:, 2:] - walls[:, :2]
    length = np.hypot(e[:, 0], e[:, 1])
    # a counter-clockwise polygon (positive shoelace area) has its inside to the left of each edge
    ccw = np.sum(walls[:, 0] * walls[:, 3] - walls[:, 2] * walls[:, 1]) > 0.0
    outward = np.column_stack([e[:, 1], -e[:, 0]]) / length[:, None] * (1.0 if ccw else -1.0)
    centres = 0.5 * (walls[:, :2] + walls[:, 2:]) + 0.5 * t * outward
    return MarkerArray(
        markers=[
            box_marker("walls", k, centre, math.atan2(ey, ex), (length_m + 2 * t, t), stamp)
            for k, (centre, length_m, (ex, ey)) in enumerate(zip(centres, length, e, strict=True))
        ]
    )


def house_markers(world: WorldGeometry, stamp: Time) -> list[Marker]:
    """The interior walls (namespace ``interior_walls``: CUBEs INTERIOR_WALL_THICKNESS_M thick on their
    segments, red) and the boxes (``boxes``: CUBEs of their size, brown), frame nusim/world."""
    markers = []
    for k, (x0, y0, x1, y1) in enumerate(world.interior):
        centre = np.array([0.5 * (x0 + x1), 0.5 * (y0 + y1)])
        length_m = math.hypot(x1 - x0, y1 - y0)
        yaw = math.atan2(y1 - y0, x1 - x0)
        markers.append(
            box_marker("interior_walls", k, centre, yaw, (length_m, INTERIOR_WALL_THICKNESS_M), stamp)
        )
    for b, corners in enumerate(world.boxes):
        # corners counter-clockwise from (-length/2, -width/2) in the box's frame
        along, across = corners[1] - corners[0], corners[3] - corners[0]
        size = (float(np.hypot(*along)), float(np.hypot(*across)))
        marker = box_marker("boxes", b, corners.mean(axis=0), math.atan2(along[1], along[0]), size, stamp)
        set_color(marker, BROWN)
        markers.append(marker)
    return markers


class NusimNode(Node):
    """The `nusim` node (module docstring); ``stepped_by_owner``: no timer, the owner calls ``step()``.

    ``fleet``: every robot's simulation; ``ports[k]``: robot ``k``'s topics, frames, path and watchdog."""

    def __init__(self, stepped_by_owner: bool = False, **kwargs) -> None:
        super().__init__("nusim", **kwargs)
        self.timing = declare_dataclass(self, NusimTiming)
        lidar_choice = declare_dataclass(self, LidarChoice)
        self.lidar_model = lidar_choice.model
        config = SimulationConfig(
            arena=declare_dataclass(self, ArenaConfig),
            robots=declare_dataclass(self, Robots, prefix="robots."),
            obstacles=declare_dataclass(self, Obstacles, prefix="obstacles."),
            walls=declare_dataclass(self, Walls, prefix="walls."),
            interior_walls=declare_dataclass(self, InteriorWalls, prefix="interior_walls."),
            boxes=declare_dataclass(self, Boxes, prefix="boxes."),
            legs=declare_dataclass(self, Legs, prefix="legs."),
            robot=declare_robot(self),
            noise=declare_dataclass(self, NoiseConfig),
            lidar=declare_dataclass(
                self, LidarConfig, prefix="lidar.", overrides=vars(self.lidar_model.sensor)
            ),
        )
        frame_prefix = declare_dataclass(self, FrameConfig).frame_prefix
        if frame_prefix and config.robots.names:
            raise ValueError(
                f"frame_prefix ({frame_prefix!r}) must be empty with robots.names: each robot's frames "
                "are prefixed with its name"
            )
        self.joints = declare_dataclass(self, WheelJoints)
        timeout = declare_dataclass(self, CommandTimeoutConfig)
        path_config = declare_dataclass(self, PathTrailConfig)
        self.fleet = MultiRobotSimulation(config)
        self.step_count = 0
        lidar = config.lidar
        spin = f", spin spread {lidar.spin_spread:g}" if lidar.spin_spread else ""
        self.get_logger().info(
            f"LiDAR {lidar_choice.lidar_model}: {lidar.samples} beams of {lidar.angle_increment:.5f} rad "
            f"from {lidar.angle_min:g} rad, {lidar.range_min:g}-{lidar.range_max:g} m, no return "
            f"{lidar.no_return}{spin}"
        )

        self._clock_publisher = self.create_publisher(ClockMsg, "/clock", 10)
        self.ports = [
            RobotPorts(
                self,
                k,
                name,
                RobotFrames.with_prefix(f"{name}/" if name else frame_prefix),
                path_config,
                timeout,
            )
            for k, name in enumerate(self.fleet.names)
        ]
        latched = QoSProfile(depth=1, durability=DurabilityPolicy.TRANSIENT_LOCAL)
        obstacles_publisher = self.create_publisher(MarkerArray, "~/obstacles", latched)
        walls_publisher = self.create_publisher(MarkerArray, "~/walls", latched)
        self._tf = OptionalTfBroadcaster(self)
        for ports in self.ports:
            for message_type, topic, callback in ports.subscriptions:
                self.create_subscription(message_type, topic, callback, 10)
        self.create_service(Empty, "~/reset", self._on_reset)

        start = self.sim_stamp()
        # one /clock message, restamped every step (publish serialises it at once)
        self._clock_msg = ClockMsg(clock=start)
        self._clock_publisher.publish(self._clock_msg)
        obstacles_publisher.publish(self._obstacle_markers(start))
        walls = wall_markers(self.simulation.walls, start)
        walls.markers += house_markers(self.simulation.world, start)
        walls_publisher.publish(walls)
        if not stepped_by_owner:
            # a steady (wall) clock, never the ROS clock: this node is what drives /clock
            self.create_timer(
                1.0 / (self.timing.rate * self.timing.realtime_factor),
                self.step,
                clock=Clock(clock_type=ClockType.STEADY_TIME),
            )

    @property
    def simulation(self) -> Simulation:
        """Robot 0's simulation (the one robot's): its world and its config are every robot's."""
        return self.fleet.robots[0]

    def _sim_time_ns(self) -> int:
        """Simulation time ``step_count / rate`` in integer ns."""
        return round(self.step_count * NS_PER_S / self.timing.rate)

    def sim_stamp(self) -> Time:
        """Simulation time ``step_count / rate`` (s) as a stamp."""
        return stamp_from_seconds(self.step_count / self.timing.rate)

    # --- inputs ------------------------------------------------------------------------------------------

    def on_wheel_cmd(self, index: int, msg: JointState) -> None:
        """Robot ``index``'s `wheel_cmd`."""
        ports = self.ports[index]
        try:
            left_rad_s, right_rad_s = wheel_values(self.joints, msg.name, msg.velocity)
        except ValueError as error:
            self.get_logger().warning(
                ports.says(f"wheel_cmd skipped: {error}"), throttle_duration_sec=WARN_THROTTLE_S
            )
            return
        self.fleet.robots[index].command_wheels(left_rad_s, right_rad_s)
        ports.watchdog.command(self._sim_time_ns())

    def on_teleport(self, index: int, msg: PoseWithCovarianceStamped) -> None:
        """Robot ``index``'s `~/teleport`."""
        ports = self.ports[index]
        frame_id = msg.header.frame_id
        try:
            if frame_id not in ("", WORLD_FRAME):
                raise ValueError(f"the pose is in frame {frame_id!r}, not {WORLD_FRAME!r}")
            self.fleet.teleport(index, transform_from_pose(msg.pose.pose))
        except ValueError as error:
            self.get_logger().warning(
                ports.says(f"teleport refused: {error}"), throttle_duration_sec=WARN_THROTTLE_S
            )
            return
        ports.path.clear()
        T = self.fleet.robots[index].T_world_body
        self.get_logger().info(
            ports.says(f"teleported to x = {T.x:.3f} m, y = {T.y:.3f} m, theta = {T.theta:.3f} rad")
        )

    def _on_reset(self, request: Empty.Request, response: Empty.Response) -> Empty.Response:
        self.fleet.reset()
        for ports in self.ports:
            ports.path.clear()
        self.get_logger().info("reset to the start pose")
        return response

    # --- physics and outputs -----------------------------------------------------------------------------

    def step(self) -> None:
        """One physics step of ``1 / rate`` s, then /clock and every stream due after it."""
        self.fleet.step(1.0 / self.timing.rate)
        self.step_count += 1
        for k, ports in enumerate(self.ports):
            if ports.watchdog.expired(self._sim_time_ns()):
                self.fleet.robots[k].command_wheels(0.0, 0.0)
                self.get_logger().info(ports.says("no wheel_cmd for cmd_timeout: wheels stopped"))
        stamp = self.sim_stamp()
        self._clock_msg.clock = stamp
        self._clock_publisher.publish(self._clock_msg)
        for k in range(len(self.ports)):
            if self.timing.due(self.step_count, self.timing.joint_states_rate):
                self._publish_joint_states(k, stamp)
                self._publish_ground_truth(k, stamp)
            if self.timing.due(self.step_count, self.timing.scan_rate):
                self._publish_scan(k, stamp)
            if self.timing.due(self.step_count, self.timing.fake_sensor_rate):
                self._publish_fake_sensor(k, stamp)

    def _publish_joint_states(self, k: int, stamp: Time) -> None:
        simulation = self.fleet.robots[k]
        msg = JointState(
            name=self.joints.names,
            position=simulation.wheel_angles_rad.tolist(),
            velocity=simulation.wheel_speed_rad_s.tolist(),
        )
        msg.header.stamp = stamp
        self.ports[k].joint_states.publish(msg)

    def _publish_ground_truth(self, k: int, stamp: Time) -> None:
        simulation, ports = self.fleet.robots[k], self.ports[k]
        T_world_body = simulation.T_world_body
        V_body = Twist2D(*simulation.V_body)
        odom = odometry_message(T_world_body, V_body, WORLD_FRAME, ports.frames.true_body, stamp)
        ports.ground_truth.publish(odom)
        self._tf.send(transform_stamped(T_world_body, WORLD_FRAME, ports.frames.true_body, stamp))
        ports.path.add(T_world_body, odom)

    def _publish_scan(self, k: int, stamp: Time) -> None:
        scan = self.fleet.scan(k)
        lidar, model = scan.layout, self.lidar_model
        range_min, range_max = model.reported_range_m or (lidar.range_min, lidar.range_max)
        last_beam = lidar.samples - 1 + model.angle_max_past_last_beam
        msg = LaserScan(
            angle_min=lidar.angle_min,
            angle_max=lidar.angle_min + last_beam * lidar.angle_increment,
            angle_increment=lidar.angle_increment,
            time_increment=0.0,
            scan_time=1.0 / self.timing.scan_rate,
            range_min=range_min,
            range_max=range_max,
            ranges=scan.range_m.tolist(),
        )
        msg.header.stamp = stamp
        msg.header.frame_id = self.ports[k].frames.scan
        self.ports[k].scan.publish(msg)

    def _publish_fake_sensor(self, k: int, stamp: Time) -> None:
        simulation, ports = self.fleet.robots[k], self.ports[k]
        readings = simulation.sense_landmarks()
        radii_m = simulation.circles[:, 2]
        body = ports.frames.body
        markers = [
            cylinder_marker(body, stamp, "fake_sensor", int(j), float(x), float(y), float(radii_m[j]), YELLOW)
            for j, (x, y) in zip(readings.ids, readings.p_body, strict=True)
        ]
        for j in sorted(set(range(radii_m.size)) - set(readings.ids.tolist())):
            marker = Marker(ns="fake_sensor", id=j, action=Marker.DELETE)
            marker.header.frame_id = body
            marker.header.stamp = stamp
            markers.append(marker)
        ports.fake_sensor.publish(MarkerArray(markers=markers))

    def _obstacle_markers(self, stamp: Time) -> MarkerArray:
        """The cylinders (namespace ``obstacles``, red) and the placed legs (``legs``, brown)."""
        return MarkerArray(
            markers=[
                cylinder_marker(WORLD_FRAME, stamp, "obstacles", j, float(x), float(y), float(r), RED)
                for j, (x, y, r) in enumerate(self.simulation.circles)
            ]
            + [
                cylinder_marker(WORLD_FRAME, stamp, "legs", k, float(x), float(y), float(r), BROWN)
                for k, (x, y, r) in enumerate(self.simulation.world.legs)
            ]
        )


def main(args: list[str] | None = None) -> None:
    sys.exit(run_node(lambda: NusimNode(), "nusim", __doc__, args))


if __name__ == "__main__":
    main()
