"""`slam`: EKF SLAM (or localization in a saved map) from wheel encoders or any odometry source and
landmark observations (a thin wrapper over turtlelib).

The filter is `turtlelib.EkfSlam`; `turtlelib.SlamTimeline` brings it to each observation's stamp before
the observation is applied (the motion interpolated between motion samples), so observations that arrive
late (up to `max_observation_delay`) are still applied at the pose they were taken from. `slam_managed` runs
this node as a managed (lifecycle) node for a lifecycle manager (`nuslam.managed_nodes`).

Motion (`motion_source`, `scan_registration`)
    `joint_states` (default): the wheel angles through `turtlelib.DiffDriveMotion` (`wheel_noise`);
    `odom`: the relative pose between consecutive `odom` messages through `turtlelib.OdometryMotion`
    (twist noise `odom_*`), for any base that publishes odometry (a Gazebo TurtleBot3, a Create, ...).
    With `scan_registration`, each `scan` is registered to a local map of recent scans with that motion
    as its prior (`nuslam.scan_odometry`, `turtlelib.LidarOdometry`, parameters `registration.*`), and
    the filter predicts with the registered motion and its covariance (`turtlelib.MeasuredMotion`): the
    pose rests on the walls and furniture wherever the scans see any, on the wheels where they do not.
    With `loop_closure` (off by default: each correction is a jump in the published pose,
    docs/loop_closure.md) the registered scans' keyframes also close loops on a revisit
    (`nuslam.loop_closing`, parameters `loops.*`): the filter moves by the correction, the grid is drawn
    again at the corrected poses.
Maps (`map_file`, `mode`)
    `map_file` (a `turtlelib.mapping.landmark_map` JSON file) is loaded at start-up when it exists; in `mode:
    localization` it must, and its landmarks stay fixed (a Schmidt update: only the pose is estimated,
    detections of unmapped landmarks are counted, not added); in `mapping` SLAM goes on from it: its
    landmarks with their covariance, and the occupancy grid saved beside it (`<stem>.yaml` + `.pgm`),
    which the new scans extend and `~/save_map` writes back extended (continued mapping, docs/maps.md),
    and with `loop_closure` loop closure's pose graph saved beside it (`<stem>.graph.npz`), which it
    continues: a revisit of a place an earlier session saw closes a loop onto that session's keyframes
    (`nuslam.loop_closing`; localization neither loads nor saves the graph).
    A corrupt, wrong-version, non-finite or other-frame file, or a grid or graph file that is malformed (or,
    in mapping, a grid saved at another resolution or larger than `grid.max_size_m`), stops the node at
    start-up with the reason.
Occupancy grid (`grid.*`, `nuslam.grid_mapping`)
    Each `scan` placed at slam's pose at its stamp and the robot's LiDAR mount builds an occupancy grid
    (published on `map`); `~/save_map` writes it beside `map_file` as `<stem>.yaml` + `<stem>.pgm`
    (map_server's format); in mapping a grid saved there is continued, in localization it is loaded and
    published instead (without one there, a WARN at start-up names the file looked for, and a fresh grid
    is mapped).

Subscribes
    `joint_states` (sensor_msgs/JointState, with `motion_source: joint_states`): wheel angles (rad) of
        joints `wheel_left`, `wheel_right`.
    `odom` (nav_msgs/Odometry, `odom_id` -> `body_id`): the odometry source's pose (the `odometry` node's,
        or the robot's own), for `map -> odom` and (`motion_source: odom`) as the motion; gated like
        joint_states (`nuturtle_ros_common.odom_stream`: time and speed bounds, a reset source restarts).
    `scan` (sensor_msgs/LaserScan, frame `sensor_id` or `body_id`, sensor-data QoS; with `grid.enabled`
        and no grid loaded, with `scan_registration`, or with `see_through_scans` > 0 in mapping): the
        occupancy grid's, the registration's and the landmark removal's input (each scan judged with the
        filter at its stamp, `turtlelib.estimation.landmark_removal`; one the filter is already past says
        nothing).
    `initialpose` (geometry_msgs/PoseWithCovarianceStamped in `map_id`, RViz's "2D Pose Estimate"):
        relocalization: pose and (x, y, yaw) covariance (finite, symmetric, positive definite, else refused
        with a warning) replace the filter's at its time; the map is kept, independent of the new pose.
    `association` = `unknown` (default): `landmarks` (visualization_msgs/MarkerArray from the `landmarks`
        node, frame `sensor_id` or `body_id`): one scan's cylinder centres; the EKF associates them
        (Mahalanobis gates, nearest neighbour or JCBB, tentative landmarks confirmed after
        `confirm_count` sightings). Noise: each CYLINDER's own range-bearing covariance ``R`` (2x2, [range
        m, bearing rad] about the frame's origin) in its ``text``, ``R=<R_rr> <R_rb> <R_bb>``
        (`nuturtle_ros_common.markers.noise_text`: the landmarks node's `range_std`, `bearing_std`), carried
        into the sensor frame when the markers are in `body_id`; an array whose markers carry no text (a
        recording made before) gets `turtlelib.SlamConfig`'s default ``R = diag(0.02^2, 0.02^2)``, and one
        with a malformed text is skipped.
    `association` = `known`: `fake_sensor` (MarkerArray from nusim, frame `body_id`): marker id = landmark
        id; positions with per-axis standard deviation `fake_sensor_std`, turned into range-bearing with
        ``R = J Sigma J^T`` (`turtlelib.estimation.range_bearing.observations_from_points`).
Publishes
    `~/odom` (nav_msgs/Odometry, `map_id` -> `body_id`, stamped with the joint_states stamp): the pose at
        that stamp with its (x, y, yaw) covariance in the 6x6, and the wheels' body twist. With
        `scan_registration`, a scan that arrives once the motion input has passed its stamp (a LiDAR's
        messages come after the wheels') is registered then, and the pose at the newest input stamp is
        published again, corrected by it (the same stamp twice: after the prediction and after the update).
    `~/path` (nav_msgs/Path, frame `map_id`), decimated by `PathTrailConfig`.
    `~/map` (visualization_msgs/MarkerArray, frame `map_id`, after each applied scan, stamped with it;
        reliable + transient local, REP 2003, so a late RViz or Foxglove gets the last one):
        DELETEALL, then per confirmed landmark a green CYLINDER (ns `landmarks`, id = landmark id, diameter
        2 `landmark_radius`) and its 2-sigma ellipse (ns `covariance`).
    `map` (nav_msgs/OccupancyGrid, frame `map_id`) and `map_metadata` (nav_msgs/MapMetaData), reliable +
        transient local (with `grid.enabled`): the occupancy grid, at most once per `grid.publish_period_s`
        of scan time while scans are added (`nuslam.grid_mapping`).
    `/diagnostics` (diagnostic_msgs/DiagnosticArray, 1 Hz): `slam: <motion_source>` and `slam: <observation
        topic>` (rates; ERROR after `STALE_S` of the node's clock without a message), `slam: motion gate`
        (motion samples refused and restarts of the stream so far, the last reason; WARN when new),
        `slam: filter` (mode, landmarks mapped and tentative, observations fused, rejected and
        (localization) unmapped, time per applied scan; WARN when
        observations were rejected or skipped since the last report), `slam: occupancy grid`
        (`nuslam.grid_mapping`: scans mapped, skipped and past the grid's bound, the grid's cells and
        bytes; WARN when scans were skipped since the last report), `slam: motion vs LiDAR`
        (`turtlelib.estimation.slip_recovery`: WARN naming the cause while scans contradict the wheels' motion
        (slip, bump) and for `slip_report_s` after each relocalization against the map, ERROR when they keep
        coming; scans held and relocalizations so far), `slam: scan registration` (with
        `scan_registration`: what the pose rests on, `nuslam.scan_odometry`), `slam: loop closure` (with
        `loop_closure` too: loops closed, candidates refused by reason, the last correction).
    `/tf` `map_id` -> `odom_id` where tf2_msgs is installed: ``T_map_odom = T_map_body T_odom_body^-1``
        at each pose's stamp, with ``T_odom_body`` the transform the odometry source broadcasts (read from
        its `odom` topic, interpolated between its samples), so that composing the two transforms on /tf
        gives slam's pose exactly, however late slam started (REP 105: the localizer publishes
        `map -> odom`). Not broadcast until `odom` covers a pose's stamp.
Services (std_srvs/Trigger)
    `~/save_map`: writes the confirmed landmarks, their joint covariance, the frame, the filter's time and
        this node's parameters to `map_file` (atomically: a temporary file renamed over it), and the
        occupancy grid beside it (`<stem>.yaml` + `<stem>.pgm`, re-rendered from its keyframes), and with
        `loop_closure` in mapping the pose graph (`<stem>.graph.npz`).
    `~/reset`: back to the start pose (x0, y0, theta0) and the map loaded at start-up (or none), its grid
        too.
Parameters
    `SlamNodeConfig` (association, motion_source, x0, y0, theta0, frame ids, fake_sensor_std,
    landmark_radius, wheel_noise, map_file, observation_timeout), `turtlelib.TwistNoise` as `odom_*`,
    `turtlelib.SlamConfig` (mode, noise_correlation, noise_correlation_length, matcher, gates,
    linearization, confirm_count, tentative_timeout, min_range, max_range, max_landmarks, max_observations,
    initial_*_std, jcbb_max_nodes),
    `turtlelib.TimelineConfig`
    (max_observation_delay, max_observation_lead, max_pending_observations),
    `turtlelib.estimation.landmark_removal.LandmarkRemovalConfig` (see_through_scans, see_through_sigmas,
    see_through_radius, see_through_travel, see_through_range_std: a confirmed landmark the LiDAR sees
    through in `see_through_scans` scans is removed, logged at INFO and counted in /diagnostics; 0: never;
    mapping only: localization's map stays fixed),
    `turtlelib.estimation.slip_recovery.SlipRecoveryConfig` (slip_recovery, slip_min_matches,
    slip_match_radius, slip_confirm_scans, slip_margin_m, slip_margin_rad, slip_stall_tolerance,
    slip_report_s), `model`, then
    `turtlelib.LidarOdometryConfig` and `turtlelib.RegistrationConfig` prefixed `registration.` (used with
    `scan_registration`), `turtlelib.smoothing.loop_closure.LoopClosureConfig` prefixed `loops.` (used with
    `scan_registration` and `loop_closure`),
    `RobotParams` (that model's constants by default), `WheelJoints`, `PathTrailConfig`,
    `turtlelib.SampleGateConfig` (speed_margin, max_sample_gap, max_bridged_gap, restart_samples),
    `nuslam.grid_mapping.GridTopicConfig`, `turtlelib.GridConfig` and `turtlelib.KeyframeConfig` prefixed
    `grid.` (grid.enabled, grid.publish_period_s, grid.resolution_m, ...). Defaults
    in config/slam.yaml. The filter's sensor mount (`SlamConfig.sensor_x/y/theta`) is the robot's `lidar_x`,
    `lidar_y`, `lidar_yaw`. Its observation noise (`range_std`, `bearing_std`, `range_std_per_m`) is no
    parameter: the detections carry theirs, and its defaults are only the fallback for arrays without.
    Invalid values stop the node at start-up with a message.

Observations that arrive before the first motion sample are dropped quietly (start-up order). Bad input
never stops the node and never changes the estimate: invalid or implausible joint_states
(`nuturtle_ros_common.wheel_stream`: a stamp not after the last, more than `max_sample_gap` after it, or
wheels faster than the motors) are refused with a throttled warning; `restart_samples` refused messages in
a row that continue each other either bridge a silence (`max_bridged_gap`: the source's net change across
it applied as one step) or restart the timeline at the first of them (a restarted simulator, a looped
recording, a source reset to zero), the motion along the others kept. Observation arrays that are stale,
stamped beyond `max_observation_lead`, non-finite, in an unknown frame, larger than `max_observations` or
otherwise refused by the filter are skipped with a throttled warning; single observations nearer than
`min_range`, farther than `max_range`, outside the innovation gates, or new while the map holds
`max_landmarks` are rejected (counted in /diagnostics; a full map is warned about).
"""

from __future__ import annotations

import math
import os
import sys
import time
from dataclasses import dataclass

import numpy as np
from builtin_interfaces.msg import Time
from diagnostic_msgs.msg import DiagnosticStatus
from geometry_msgs.msg import PoseWithCovarianceStamped
from nav_msgs.msg import Odometry
from numpy.typing import NDArray
from rclpy.node import Node
from rclpy.qos import DurabilityPolicy, QoSProfile, ReliabilityPolicy, qos_profile_sensor_data
from sensor_msgs.msg import JointState, LaserScan
from std_srvs.srv import Trigger
from visualization_msgs.msg import MarkerArray

from nuslam.grid_mapping import GridMapping
from nuslam.loop_closing import LoopClosing, declare_loop_closure
from nuslam.map_to_odom import MapToOdom
from nuslam.observation_reader import ObservationReader
from nuslam.scan_odometry import ScanOdometry
from nuslam.slam_report import SlamReport
from nuturtle_description.robot_declaration import declare_robot
from nuturtle_description.robot_params import RobotParams
from nuturtle_ros_common.conversions import (
    mounted_range_scan,
    odometry_message,
    positive_definite_pose_covariance,
    stamp_from_nanoseconds,
    stamp_nanoseconds,
    transform_from_pose,
)
from nuturtle_ros_common.diagnostics import (
    DiagnosticsPublisher,
)
from nuturtle_ros_common.markers import (
    cylinder_marker,
    delete_all_marker,
    ellipse_marker,
)
from nuturtle_ros_common.node_main import run_node
from nuturtle_ros_common.odom_stream import OdomStream
from nuturtle_ros_common.path_topic import PathTopic
from nuturtle_ros_common.ros_params import declare_dataclass, field_defaults
from nuturtle_ros_common.throttle import SourceWarnings
from nuturtle_ros_common.wheel_joints import WheelJoints
from nuturtle_ros_common.wheel_stream import declare_wheel_stream
from turtlelib import (
    DiffDriveMotion,
    EkfSlam,
    LidarOdometryConfig,
    MeasuredMotion,
    MeasuredPoses,
    MotionModel,
    MotionSignal,
    OdometryMotion,
    OdometryPoses,
    RegistrationConfig,
    ScanResult,
    SlamConfig,
    SlamTimeline,
    TimelineConfig,
    Transform2D,
    Twist2D,
    TwistNoise,
    WheelAngles,
)
from turtlelib.estimation.landmark_removal import LandmarkRemoval, LandmarkRemovalConfig, MountedScan
from turtlelib.estimation.slip_recovery import SlipRecovery, SlipRecoveryConfig, lost_wheel_turn_per_m
from turtlelib.mapping.landmark_map import LandmarkMap, load_map, save_map
from turtlelib.motion.pose_twist import PoseTwist
from turtlelib.motion.sample_gate import GateResult, SampleGate, Verdict
from turtlelib.motion.wheel_odometry import WheelOdometry
from turtlelib.smoothing.run_smoothing import SmoothingOutcome, smooth_history
from turtlelib.util.validation import finite_real, names, non_negative, one_of, positive, store

ASSOCIATIONS = ("known", "unknown")
# SlamConfig's default observation noise: kept at its defaults, not parameters (the detections carry theirs)
FALLBACK_NOISE_FIELDS = ("range_std", "bearing_std", "range_std_per_m")
MOTION_SOURCES = ("joint_states", "odom")
GREEN = (0.1, 0.8, 0.2, 1.0)
GREEN_TRANSLUCENT = (0.1, 0.8, 0.2, 0.35)
# Drawn confidence region of a mapped landmark (standard deviations)
ELLIPSE_SIGMA = 2.0
# The default wheel slip (sqrt(rad)); the default odom_* twist noise is this slip on the model's twist
WHEEL_NOISE = 0.05
# REP 2003 map QoS: reliable, transient local (the last map reaches late subscribers), keep last 1
MAP_QOS = QoSProfile(
    depth=1, reliability=ReliabilityPolicy.RELIABLE, durability=DurabilityPolicy.TRANSIENT_LOCAL
)


@dataclass(frozen=True)
class SlamNodeConfig:
    """The node's own parameters (ValueError for invalid values):

    * ``association``: ``unknown`` (LiDAR landmarks) or ``known`` (nusim's fake sensor, ids given);
    * ``motion_source``: ``joint_states`` (the wheel angles, :class:`turtlelib.DiffDriveMotion` with
      ``wheel_noise``) or ``odom`` (the relative pose between consecutive `odom` messages,
      :class:`turtlelib.OdometryMotion` with the ``odom_*`` twist noise: any base that publishes odom);
    * ``x0``, ``y0``, ``theta0`` (m, m, rad, finite): the start pose ``T_map_body``;
    * ``map_id``, ``odom_id``, ``body_id``, ``sensor_id``: frame ids, non-empty and distinct;
    * ``fake_sensor_std`` (m, > 0): per-axis standard deviation of the fake sensor's positions;
    * ``landmark_radius`` (m, > 0): drawn radius of the mapped landmarks;
    * ``wheel_noise`` (sqrt(rad), >= 0): the motion model's wheel slip, ``N(0, wheel_noise^2 |dphi|)`` per
      wheel over an increment ``dphi`` (:class:`turtlelib.DiffDriveMotion`);
    * ``map_file``: path of the map file (:mod:`turtlelib.mapping.landmark_map`, JSON): loaded at start-up
      when it exists (it must, with ``mode: localization``), written by ``~/save_map``; empty for none;
    * ``observation_timeout`` (s, > 0): the wheels turning this long (joint_states time) without an
      observation arriving gives a (throttled) warning: slam is only dead-reckoning;
    * ``scan_registration``: register each scan to a local map of recent scans with the motion as its prior,
      and predict with the registered motion (:mod:`nuslam.scan_odometry`);
    * ``loop_closure`` (with ``scan_registration``): close the loops of the registered scans on a revisit,
      moving the filter and drawing the grid at the corrected poses (:mod:`nuslam.loop_closing`, ``loops.*``);
    * ``smooth_saved_map``: keep the run's history (since start-up, the last reset or relocalization, a
      loop closure's excepted: the smoother takes its loops; memory grows with the run) and have
      ``~/save_map`` save the landmark map of the whole run smoothed and the occupancy grid of its
      keyframes at the smoothed poses (:mod:`turtlelib.smoothing.run_smoothing`; the call blocks the node
      while it smooths, seconds for a long run); mapping only.
    """

    association: str = "unknown"
    motion_source: str = "joint_states"
    x0: float = 0.0
    y0: float = 0.0
    theta0: float = 0.0
    map_id: str = "map"
    odom_id: str = "odom"
    body_id: str = "base_footprint"
    sensor_id: str = "base_scan"
    fake_sensor_std: float = 0.01
    landmark_radius: float = 0.038
    wheel_noise: float = WHEEL_NOISE
    map_file: str = ""
    observation_timeout: float = 3.0
    scan_registration: bool = True
    loop_closure: bool = False
    smooth_saved_map: bool = False

    def __post_init__(self) -> None:
        one_of("association", self.association, ASSOCIATIONS)
        one_of("motion_source", self.motion_source, MOTION_SOURCES)
        store(self, ("x0", "y0", "theta0"), finite_real)
        store(self, ("wheel_noise",), non_negative)
        store(self, ("fake_sensor_std", "landmark_radius", "observation_timeout"), positive)
        frames = ("map_id", "odom_id", "body_id", "sensor_id")
        names("frame id", **{name: getattr(self, name) for name in frames})

    @property
    def T_map_body0(self) -> Transform2D:
        return Transform2D(self.x0, self.y0, self.theta0)


class SlamNode(Node):
    """The `slam` node (see the module docstring); kwargs go to rclpy's Node."""

    def __init__(self, **kwargs) -> None:
        super().__init__("slam", **kwargs)
        self.build()

    def build(self) -> None:
        """Read the parameters (ValueError for an invalid one), build the filter and its parts, then the
        topics, services and timer: at construction, or at configure for `slam_managed`
        (`nuslam.managed_nodes`)."""
        self.node_config = frames = declare_dataclass(self, SlamNodeConfig)
        robot = declare_robot(self)
        self._warnings = SourceWarnings(self.get_logger())
        self.timeline = self._estimator(robot)
        self.slam = self.timeline.slam
        self.joints = declare_dataclass(self, WheelJoints)
        self.path = PathTopic(self)
        grid_frames = (frames.map_id, frames.body_id, frames.sensor_id)
        localization = self.config.mode == "localization"
        self.grid = GridMapping(
            self, robot.T_body_scan, grid_frames, self._warnings, frames.map_file, localization
        )
        known = frames.association == "known"
        T_body_sensor = self.config.T_body_sensor
        self._reader = ObservationReader(
            known, frames.fake_sensor_std, frames.sensor_id, frames.body_id, T_body_sensor
        )
        # the stamp (ns) and body twist of the newest pose published
        self._published: tuple[int, Twist2D] | None = None
        # the stamp and value of the first motion sample since the last observation
        self._observed_at: tuple[int, tuple[float, ...]] | None = None
        self._wheels = declare_wheel_stream(self, self.joints, robot, self._warnings)
        self._odom = OdomStream(
            frames.odom_id, frames.body_id, robot, self._wheels.gate.config, self._warnings
        )
        topics = (frames.motion_source, "fake_sensor" if known else "landmarks")
        started_ns = self.get_clock().now().nanoseconds
        self.report = SlamReport(
            self.slam,
            self.recovery,
            self.grid,
            self._warnings,
            topics,
            started_ns,
            self.motion_gate.tally,
            self.removal,
        )
        self._fused_reported = 0
        self.loop_closing = None
        if self.scan_odometry is not None and frames.loop_closure:
            self.loop_closing = LoopClosing(
                self._loops, self.timeline, self.grid, self, self._warnings, frames.map_file, localization
            )
            self.scan_odometry.step_listener = self.loop_closing.add_step
        self._connect(topics[1])

    def _estimator(self, robot: RobotParams) -> SlamTimeline:
        """The filter (``SlamConfig``; the sensor mount is the robot's, written once in its description; the
        observation noise is each detection's own, so the filter's default is only the fallback, not a
        parameter) with its motion model and the map loaded at start-up, on its timeline with slip recovery
        acting on the scans."""
        frames, T_body_scan = self.node_config, robot.T_body_scan
        # the frames a scan may come in, and where they are on the body
        self._T_body_from = {frames.sensor_id: T_body_scan, frames.body_id: Transform2D()}
        fixed = {"sensor_x": T_body_scan.x, "sensor_y": T_body_scan.y, "sensor_theta": T_body_scan.theta}
        fixed.update({name: field_defaults(SlamConfig)[name] for name in FALLBACK_NOISE_FIELDS})
        self.config = declare_dataclass(self, SlamConfig, fixed=fixed)
        timeline_config = declare_dataclass(self, TimelineConfig)
        lost_wheel = {"slip_turn_per_m": lost_wheel_turn_per_m(robot.track_width)}
        self.recovery = SlipRecovery(declare_dataclass(self, SlipRecoveryConfig, fixed=lost_wheel))
        motion, signal, self.odometry = self._motion_model(robot)
        slam = EkfSlam(self.config, motion, frames.T_map_body0)
        # the map loaded at start-up (None: none), which ~/reset goes back to
        self._start_map = self._load_start_map()
        if self._start_map is not None:
            slam.load_map(self._start_map, frames.T_map_body0)
        if frames.smooth_saved_map and self.config.mode == "localization":
            raise ValueError("smooth_saved_map needs mode mapping: in localization the map is fixed")
        timeline = SlamTimeline(
            slam, signal, timeline_config, step=self.recovery, keep_history=frames.smooth_saved_map
        )
        removal = declare_dataclass(self, LandmarkRemovalConfig)
        # mapping only: localization's map is fixed
        mapping = self.config.mode == "mapping"
        self.removal = timeline.attach(LandmarkRemoval(removal)) if removal.enabled and mapping else None
        self._removals_logged = 0
        return timeline

    def _motion_model(
        self, robot: RobotParams
    ) -> tuple[MotionModel, MotionSignal, WheelOdometry | PoseTwist]:
        """The filter's motion model, the signal its samples are read through, and the body-twist odometry
        for the published twist: the wheels' (``joint_states``) or the odometry source's (``odom``); with
        ``scan_registration`` the registered motion, the wheels' or odometry's its prior
        (``self.scan_odometry``, else None)."""
        drive, frames = robot.diff_drive(), self.node_config
        odom_noise = declare_dataclass(
            self, TwistNoise, prefix="odom_", overrides=vars(TwistNoise.from_wheel_slip(drive, WHEEL_NOISE))
        )
        if frames.motion_source == "odom":
            model, signal, odometry = OdometryMotion(odom_noise), OdometryPoses(), PoseTwist()
            input_noise = odom_noise
        else:
            model, signal = DiffDriveMotion(drive, frames.wheel_noise), WheelAngles()
            odometry, input_noise = (
                WheelOdometry(drive),
                TwistNoise.from_wheel_slip(drive, frames.wheel_noise),
            )
        # declared either way, so that the config file holds them and the defaults are there to read
        registration = declare_dataclass(self, RegistrationConfig, prefix="registration.")
        config = declare_dataclass(
            self, LidarOdometryConfig, prefix="registration.", fixed={"registration": registration}
        )
        self._loops = declare_loop_closure(self, registration)
        self.scan_odometry = None
        if not frames.scan_registration:
            return model, signal, odometry
        speed_bounds = (robot.max_linear_speed, robot.max_angular_speed)
        self.scan_odometry = ScanOdometry(config, input_noise, speed_bounds, self._warnings)
        return MeasuredMotion(), MeasuredPoses(), odometry

    def _connect(self, observation_topic: str) -> None:
        """Publishers, subscriptions, services and the diagnostics timer, once everything else is checked
        (a node that fails at start-up must not hold subscriptions: their callbacks keep it alive)."""
        frames = self.node_config
        self._odom_publisher = self.create_publisher(Odometry, "~/odom", 10)
        # REP 2003: maps are reliable and transient local, so a late subscriber (RViz, Foxglove) gets one
        self._map_publisher = self.create_publisher(MarkerArray, "~/map", MAP_QOS)
        self.grid.connect(self, MAP_QOS, self.timeline)
        self._map_to_odom = MapToOdom(self, frames.map_id, frames.odom_id)
        if frames.motion_source == "joint_states":
            self.create_subscription(JointState, "joint_states", self._on_joint_states, 10)
        self.create_subscription(Odometry, "odom", self._on_odom, 10)
        self.create_subscription(PoseWithCovarianceStamped, "initialpose", self._on_initial_pose, 10)
        if self.scan_odometry is not None or self.removal is not None:
            self.create_subscription(LaserScan, "scan", self._on_scan, qos_profile_sensor_data)
        self.create_service(Trigger, "~/save_map", self._on_save_map)
        self.create_service(Trigger, "~/reset", self._on_reset)
        DiagnosticsPublisher(self, self._statuses)
        self.create_subscription(MarkerArray, observation_topic, self._on_observations, 10)

    @property
    def motion_gate(self) -> SampleGate:
        """The gate of the motion source's samples (``motion_source``: the wheels' or the odometry's), whose
        ``tally`` counts what it refused."""
        return self._odom.gate if self.node_config.motion_source == "odom" else self._wheels.gate

    @property
    def observation_counts(self) -> dict[str, int]:
        """Observation arrays so far (read-only): ``received`` on the observation topic, ``applied`` by the
        filter, ``skipped`` (refused), ``pending`` (waiting for motion samples past their stamp)."""
        return {
            "received": self.report.observation_input.count,
            "applied": self.report.counts["arrays_applied"],
            "skipped": self.report.counts["skipped"],
            "pending": self.timeline.pending_count,
        }

    # --- inputs ------------------------------------------------------------------------------------------

    def _on_joint_states(self, msg: JointState) -> None:
        self.report.motion_input.arrived(self.get_clock().now().nanoseconds)
        self._follow(self._wheels.offer(msg))

    def _follow(self, result: GateResult | None) -> None:
        """Apply the plausible motion samples of a joint_states or (``motion_source: odom``) odom message."""
        if result is None:
            return
        samples = list(result.samples)
        if result.verdict is Verdict.RESTARTED:
            self._restart(*samples.pop(0))
        for t_ns, sample in samples:
            self._add_motion_sample(t_ns, sample)

    def _add_motion_sample(self, t_ns: int, sample: tuple[float, ...]) -> None:
        """Move the timeline (or, with ``scan_registration``, the registration's input) and the body-twist
        odometry on to a plausible motion sample (wheel angles or an odometry pose); publish the pose."""
        t_s = t_ns * 1e-9
        source = self.node_config.motion_source
        try:
            applied = [] if self.scan_odometry is not None else self._timed_add_motion(t_ns, sample)
            if self.odometry.reference_time_s is None:
                self.odometry.set_reference(t_s, *sample)
            V_body = self.odometry.step(t_s, *sample)
            if self.scan_odometry is not None:
                self.scan_odometry.input(t_ns, self._input_pose(sample))
                applied = self._add_registered_scans()
                if self.timeline.latest_time_ns is None:
                    return  # no scan registered yet: no pose
            T_map_body, P_pose = self._pose_at(t_ns)
        except (ValueError, np.linalg.LinAlgError) as error:
            # a motion the filter's model refuses (a step turning the body by more than 1000 rad, ...):
            # add_motion changed nothing, so the samples after it drive on from the last good one (the
            # odometry refuses only what the filter refuses: non-finite steps)
            self._warnings.warn(source, f"{source} skipped: {error}")
            return
        self._check_observations_arrive(t_ns, sample)
        self._publish_pose(stamp_from_nanoseconds(t_ns), V_body, T_map_body, P_pose)
        self._published = (t_ns, V_body)
        self.grid.insert_reached()
        if applied:
            self._publish_map(stamp_from_nanoseconds(applied[-1].t_ns))

    def _pose_at(self, t_ns: int) -> tuple[Transform2D, NDArray[np.float64]]:
        """The pose at the newest motion sample ``t_ns`` and its covariance: the timeline's, or with
        ``scan_registration`` the filter's at the newest registered scan moved on by the input since."""
        T_map_body, P_pose = self.timeline.latest_pose()
        if self.scan_odometry is None:
            return T_map_body, P_pose
        return self.scan_odometry.moved_on(self.timeline.latest_time_ns, T_map_body, P_pose, t_ns)

    def _timed_add_motion(self, t_ns: int, sample: tuple[float, ...]) -> list[ScanResult]:
        """``timeline.add_motion``, its applied measurements counted and timed."""
        start = time.perf_counter()
        applied = self.timeline.add_motion(t_ns, sample)
        self.report.applied(applied, 1e3 * (time.perf_counter() - start))
        self._log_removals()
        return applied

    def _log_removals(self) -> None:
        """Log (INFO) the landmarks removed since the last call (``see_through_scans``)."""
        removals = [] if self.removal is None else self.removal.removals[self._removals_logged :]
        for removal in removals:
            x, y = removal.xy
            self.get_logger().info(
                f"landmark {removal.landmark_id} at ({x:.3f}, {y:.3f}) removed: the LiDAR saw through it "
                f"in {removal.scans} scans"
            )
        self._removals_logged += len(removals)

    def _input_pose(self, sample: tuple[float, ...]) -> Transform2D:
        """The motion input's pose ``T_odom_body`` at its newest sample: the odometry's pose, or the wheels'
        dead reckoning."""
        if self.node_config.motion_source == "odom":
            return Transform2D(*sample)
        return self.odometry.T_odom_body

    def _on_scan(self, msg: LaserScan) -> None:
        """A scan for the landmark removal (``see_through_scans``), judged at its stamp, and for the
        registration (``scan_registration``): registered once the motion reaches it. One that cannot be
        read is skipped with a (throttled) warning."""
        try:
            t_ns, scan, T_body_scan = mounted_range_scan(msg, self._T_body_from)
        except ValueError as error:
            if self.scan_odometry is not None:
                self.scan_odometry.skip(f"scan skipped: {error}")
            else:
                self._warnings.warn("scan", f"scan skipped: {error}")
            return
        if self.removal is not None and not self._before_first_motion():
            # a scan the filter is already past cannot be judged in stamp order: it only says nothing
            if t_ns >= self.timeline.filter_time_ns:
                try:
                    self.timeline.add(t_ns, self.removal, MountedScan(scan, T_body_scan))
                except ValueError as error:
                    self._warnings.warn("scan", f"scan skipped by the landmark removal: {error}")
                self._log_removals()
        if self.scan_odometry is None:
            return
        self.scan_odometry.add_scan(t_ns, scan, T_body_scan)
        registered_to = self.timeline.latest_time_ns
        applied = self._add_registered_scans()
        if self._published is not None and registered_to != self.timeline.latest_time_ns:
            t_ns, V_body = self._published
            if t_ns >= self.timeline.latest_time_ns:  # the published pose, corrected by the scan
                self._publish_pose(stamp_from_nanoseconds(t_ns), V_body, *self._pose_at(t_ns))
        self.grid.insert_reached()
        if applied:
            self._publish_map(stamp_from_nanoseconds(applied[-1].t_ns))

    def _add_registered_scans(self) -> list[ScanResult]:
        """The registered scans the motion reaches, as the timeline's motion samples (the first after a
        restart of the input restarts the timeline); the measurements they apply."""
        applied = []
        for t_ns, sample, restart in self.scan_odometry.reached():
            try:
                if restart:
                    self.timeline.restart(t_ns, sample)
                else:
                    applied += self._timed_add_motion(t_ns, sample)
            except (ValueError, np.linalg.LinAlgError) as error:
                # the timeline changed nothing; the next sample moves on from the last it took
                self._warnings.warn("scan", f"registered scan at {t_ns} ns skipped by the filter: {error}")
        return applied

    def _statuses(self, now_ns: int) -> list[DiagnosticStatus]:
        """/diagnostics: the report's, the registration's (``scan_registration``) and the loop closure's."""
        statuses = self.report.statuses(now_ns)
        if self.scan_odometry is not None:
            fused = self.report.counts["fused"]
            statuses.append(self.scan_odometry.status(fused - self._fused_reported))
            self._fused_reported = fused
        if self.loop_closing is not None:
            statuses.append(self.loop_closing.status())
        return statuses

    def _on_observations(self, msg: MarkerArray) -> None:
        """One array of `fake_sensor` (known association) or `landmarks` (unknown) into the timeline."""
        self.report.observation_input.arrived(self.get_clock().now().nanoseconds)
        if self._before_first_motion():
            return
        try:
            t_ns, ids, z, R = self._reader.read(msg)
            start = time.perf_counter()
            applied = self.timeline.add_observations(t_ns, z, R, ids)
            self.report.applied(applied, 1e3 * (time.perf_counter() - start))
        except (ValueError, np.linalg.LinAlgError) as error:
            self.report.skipped(error)
            return
        self._observed_at = None  # the observations arrive: the silence starts again at the next sample
        if applied:
            self._publish_map(msg.markers[0].header.stamp)

    def _on_odom(self, msg: Odometry) -> None:
        """A plausible odom sample is kept for ``map -> odom`` and, with ``motion_source: odom``, moves the
        filter; after a restart of the source (`OdomStream`) the odom frame is another, so the kept samples
        go."""
        from_odom = self.node_config.motion_source == "odom"
        if from_odom:
            self.report.motion_input.arrived(self.get_clock().now().nanoseconds)
        result = self._odom.offer(msg)
        if result is None:
            return
        self._map_to_odom.odom(result.samples, result.verdict is Verdict.RESTARTED)
        if from_odom:
            self._follow(result)

    def _on_initial_pose(self, msg: PoseWithCovarianceStamped) -> None:
        """Relocalize: the pose and its (x, y, yaw) covariance, positive definite, in ``map_id``, become
        the filter's (at the filter's time), independent of the map, which is kept."""
        try:
            if msg.header.frame_id != self.node_config.map_id:
                raise ValueError(
                    f"it is in frame {msg.header.frame_id!r}, not the map frame {self.node_config.map_id!r}"
                )
            T_map_body = transform_from_pose(msg.pose.pose)
            self.timeline.relocalize(T_map_body, positive_definite_pose_covariance(msg.pose.covariance))
        except ValueError as error:
            self._warnings.warn("initialpose", f"initialpose skipped: {error}")
            return
        self.get_logger().info(f"relocalized at {T_map_body} from initialpose")

    def smooth_run(self) -> SmoothingOutcome:
        """The run so far smoothed as a whole (``smooth_saved_map``: the history is kept), with the loops
        closed (``loop_closure``), a pose at every scan the grid keeps (so the smoothed grid places each)
        and the observations of the landmarks removed as gone left out (no landmark takes them); ValueError
        without a history or before the first motion sample."""
        if self.timeline.history is None:
            raise ValueError("no run history: smooth_saved_map is false")
        return smooth_history(
            self.timeline.history,
            self.slam.motion,
            self.timeline.signal,
            self.config,
            self.slam.landmark_ids,
            self.slam.landmarks,
            revise=self.node_config.association == "unknown",
            loops=() if self.loop_closing is None else self.loop_closing.loops.loop_edges(),
            extra_t_ns=self.grid.keyframes.stamps_ns,
            removed_ids=[] if self.removal is None else [r.landmark_id for r in self.removal.removals],
        )

    def map_to_save(self, outcome: SmoothingOutcome | None = None) -> LandmarkMap:
        """The landmark map ``~/save_map`` writes (in ``map_id``, stamped with the filter's time, with the
        node's parameters): the filter's, or that of the smoothed run ``outcome`` (:meth:`smooth_run`)."""
        source = self.slam if outcome is None else outcome
        return source.landmark_map(
            self.node_config.map_id, self.timeline.filter_time_ns or 0, self.map_parameters()
        )

    def _on_save_map(self, request: Trigger.Request, response: Trigger.Response) -> Trigger.Response:
        """Write the map (confirmed landmarks, joint covariance, the parameters) to ``map_file`` and the grid
        beside it: the filter's, or with ``smooth_saved_map`` those of the smoothed run."""
        path = self.node_config.map_file
        if not path:
            response.success, response.message = False, "map_file is not set: nowhere to save the map"
            return response
        try:
            outcome = self.smooth_run() if self.node_config.smooth_saved_map else None
            landmark_map = self.map_to_save(outcome)
            save_map(path, landmark_map)
        except (OSError, ValueError) as error:
            response.success, response.message = False, f"could not save the map to {path}: {error}"
            self.get_logger().error(response.message)
            return response
        smoothed = "" if outcome is None else f" (smoothed run; the filter has {len(self.slam.landmark_ids)})"
        response.message = f"saved {landmark_map.n_landmarks} landmarks{smoothed} to {path}"
        try:
            # the grid's keyframes at the smoothed poses of their scans (else at the filter's)
            grid_saved = self.grid.save(None if outcome is None else outcome.pose_at)
        except (OSError, ValueError) as error:
            response.success = False
            response.message += f"; could not save the occupancy grid: {error}"
            self.get_logger().error(response.message)
            return response
        try:
            graph_saved = "" if self.loop_closing is None else self.loop_closing.save()
        except (OSError, ValueError) as error:
            response.success = False
            response.message += f"; could not save the pose graph: {error}"
            self.get_logger().error(response.message)
            return response
        response.success = True
        response.message += "".join(f" and {saved}" for saved in (grid_saved, graph_saved) if saved)
        self.get_logger().info(response.message)
        return response

    def _on_reset(self, request: Trigger.Request, response: Trigger.Response) -> Trigger.Response:
        """Start again as at start-up: the start pose, and the map loaded then (or none)."""
        self.timeline.reset(self.node_config.T_map_body0, self._start_map)
        self._published = None
        count = 0 if self._start_map is None else self._start_map.n_landmarks
        response.success, response.message = True, f"reset to the start pose with {count} landmarks"
        self.get_logger().info(response.message)
        return response

    def _load_start_map(self) -> LandmarkMap | None:
        """The map in ``map_file``, if set and there; ValueError for a file that is not a map in ``map_id``
        or one that is missing in localization."""
        path = self.node_config.map_file
        if not path and self.config.mode == "localization":
            raise ValueError("mode localization needs map_file: a map saved by ~/save_map")
        if not path or (not os.path.exists(path) and self.config.mode == "mapping"):
            return None
        landmark_map = load_map(path)
        if landmark_map.frame_id != self.node_config.map_id:
            raise ValueError(
                f"{path}: the map is in frame {landmark_map.frame_id!r}, this node's map_id is "
                f"{self.node_config.map_id!r}"
            )
        self.get_logger().info(f"loaded {landmark_map.n_landmarks} landmarks from {path}")
        return landmark_map

    def map_parameters(self) -> dict[str, bool | int | float | str]:
        """This node's scalar parameters, for the map file's record."""
        values = {name: p.value for name, p in sorted(self.get_parameters_by_prefix("").items())}
        return {
            name: value
            for name, value in values.items()
            if isinstance(value, (bool, int, str)) or (isinstance(value, float) and math.isfinite(value))
        }

    def _before_first_motion(self) -> bool:
        """At start-up observations may come before the first joint_states: there is no pose to place them
        on, so they are dropped (a debug message, not a warning: nothing is wrong)."""
        if self.timeline.latest_time_ns is not None:
            return False
        self.get_logger().debug("observation before the first joint_states: dropped")
        return True

    def _check_observations_arrive(self, t_ns: int, sample: tuple[float, ...]) -> None:
        """Warn (throttled) when the robot has moved for ``observation_timeout`` without observations."""
        if self._observed_at is None or t_ns < self._observed_at[0]:
            self._observed_at = (t_ns, sample)
            return
        since_ns, since_sample = self._observed_at
        silent_s = (t_ns - since_ns) * 1e-9
        if silent_s > self.node_config.observation_timeout and sample != since_sample:
            self.report.silent(silent_s)

    def _restart(self, t_ns: int, sample: tuple[float, ...]) -> None:
        """Take this motion sample as the new start of the timeline (with ``scan_registration``, the next
        registered scan) and of the odometry (estimate kept)."""
        if self.scan_odometry is None:
            self.timeline.restart(t_ns, sample)
        else:
            self.scan_odometry.restart()
        self.odometry.set_reference(t_ns * 1e-9, *sample)
        self._published = None  # a pose of the old time base

    # --- outputs -----------------------------------------------------------------------------------------

    def _publish_pose(
        self, stamp: Time, V_body: Twist2D, T_map_body: Transform2D, P_pose: NDArray[np.float64]
    ) -> None:
        frames = self.node_config
        odom = odometry_message(T_map_body, V_body, frames.map_id, frames.body_id, stamp, P_pose)
        self._odom_publisher.publish(odom)
        self._map_to_odom.pose(stamp_nanoseconds(stamp), T_map_body, stamp)
        self.path.add(T_map_body, odom)

    def _publish_map(self, stamp: Time) -> None:
        map_id = self.node_config.map_id
        markers = [delete_all_marker(map_id, stamp)]
        radius_m = self.node_config.landmark_radius
        for landmark_id, xy, covariance in zip(
            self.slam.landmark_ids.tolist(), self.slam.landmarks, self.slam.landmark_covariances, strict=True
        ):
            markers.append(
                cylinder_marker(
                    map_id, stamp, "landmarks", landmark_id, float(xy[0]), float(xy[1]), radius_m, GREEN
                )
            )
            markers.append(
                ellipse_marker(
                    map_id, stamp, "covariance", landmark_id, xy, covariance, ELLIPSE_SIGMA, GREEN_TRANSLUCENT
                )
            )
        self._map_publisher.publish(MarkerArray(markers=markers))


def main(args: list[str] | None = None) -> None:
    sys.exit(run_node(lambda: SlamNode(), "slam", __doc__, args))


if __name__ == "__main__":
    main()
