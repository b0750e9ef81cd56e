"""`slam`: EKF SLAM from wheel encoders and landmark observations (a thin wrapper over turtlelib).

The filter is `turtlelib.EkfSlam`; `turtlelib.SlamTimeline` brings it to each observation's stamp before
the observation is applied (wheel angles interpolated between joint_states samples), so observations that
arrive late (up to `max_observation_delay`) are still applied at the pose they were taken from.

Subscribes
    `joint_states` (sensor_msgs/JointState): wheel angles (rad) of joints `wheel_left`, `wheel_right`.
    `odom` (nav_msgs/Odometry, `odom_id` -> `body_id`): the odometry source's pose (the `odometry` node's,
        or the robot's own), for `map -> odom`.
    `association` = `unknown` (default): `landmarks` (visualization_msgs/MarkerArray from the `landmarks`
        node, frame `sensor_id` or `body_id`): one scan's cylinder centres; the EKF associates them
        (Mahalanobis gates, nearest neighbour or JCBB, tentative landmarks confirmed after
        `confirm_count` sightings). Noise ``R = diag(range_std^2, bearing_std^2)``.
    `association` = `known`: `fake_sensor` (MarkerArray from nusim, frame `body_id`): marker id = landmark
        id; positions with per-axis standard deviation `fake_sensor_std`, turned into range-bearing with
        ``R = J Sigma J^T`` (`turtlelib.range_bearing.observations_from_points`).
Publishes
    `~/odom` (nav_msgs/Odometry, `map_id` -> `body_id`, stamped with the joint_states stamp): the pose at
        that stamp with its (x, y, yaw) covariance in the 6x6, and the wheels' body twist.
    `~/path` (nav_msgs/Path, frame `map_id`), decimated by `PathTrailConfig`.
    `~/map` (visualization_msgs/MarkerArray, frame `map_id`, after each applied scan, stamped with it):
        DELETEALL, then per confirmed landmark a green CYLINDER (ns `landmarks`, id = landmark id, diameter
        2 `landmark_radius`) and its 2-sigma ellipse (ns `covariance`).
    `/diagnostics` (diagnostic_msgs/DiagnosticArray, 1 Hz): `slam: joint_states` and `slam: <observation
        topic>` (rates; ERROR after `STALE_S` of the node's clock without a message), `slam: filter`
        (landmarks mapped and tentative, observations fused and rejected, time per applied scan; WARN when
        observations were rejected or skipped since the last report).
    `/tf` `map_id` -> `odom_id` where tf2_msgs is installed: ``T_map_odom = T_map_body T_odom_body^-1``
        at each pose's stamp, with ``T_odom_body`` the transform the odometry source broadcasts (read from
        its `odom` topic, interpolated between its samples), so that composing the two transforms on /tf
        gives slam's pose exactly, however late slam started (REP 105: the localizer publishes
        `map -> odom`). Not broadcast until `odom` covers a pose's stamp.
Parameters
    `SlamNodeConfig` (association, x0, y0, theta0, frame ids, fake_sensor_std, landmark_radius, and the
    motion model's wheel_noise), `turtlelib.SlamConfig` (range_std, bearing_std, matcher, gates,
    linearization, confirm_count, tentative_timeout, min_range, max_range, max_landmarks, max_observations,
    initial_*_std, jcbb_max_nodes),
    `turtlelib.TimelineConfig`
    (max_observation_delay, max_observation_lead, max_pending_observations), `RobotParams` (the Burger's by
    default), `WheelJoints`, `PathTrailConfig`, `turtlelib.SampleGateConfig` (speed_margin,
    max_sample_gap, max_bridged_gap, restart_samples). Defaults in config/slam.yaml. The filter's sensor
    mount (`SlamConfig.sensor_x/y/theta`) is the robot's `lidar_x`, `lidar_y`, `lidar_yaw`. Invalid values
    stop the node at start-up with a message.

Observations that arrive before the first joint_states are dropped quietly (start-up order). Bad input
never stops the node and never changes the estimate: invalid or implausible joint_states
(`nuturtle_ros_common.wheel_stream`: a stamp not after the last, more than `max_sample_gap` after it, or
wheels faster than the motors) are refused with a throttled warning, and only `restart_samples` refused
messages in a row that continue each other restart the timeline at the first of them (a restarted
simulator, a looped recording), the motion along the others kept. Observation arrays that are stale,
stamped beyond `max_observation_lead`, non-finite, in an unknown frame, larger than `max_observations` or
otherwise refused by the filter are skipped with a throttled warning; single observations nearer than
`min_range`, farther than `max_range`, outside the innovation gates, or new while the map holds
`max_landmarks` are rejected (counted in /diagnostics; a full map is warned about).
"""

from __future__ import annotations

import sys
import time
from dataclasses import dataclass

import numpy as np
from builtin_interfaces.msg import Time
from geometry_msgs.msg import PoseStamped
from nav_msgs.msg import Odometry, Path
from numpy.typing import NDArray
from rclpy.node import Node
from sensor_msgs.msg import JointState
from visualization_msgs.msg import MarkerArray

from nuturtle_description.robot_params import RobotParams, burger_params
from nuturtle_ros_common.conversions import (
    odometry_message,
    stamp_from_nanoseconds,
    stamp_nanoseconds,
    transform_from_pose,
    transform_stamped,
)
from nuturtle_ros_common.diagnostics import (
    OK,
    WARN,
    DiagnosticsPublisher,
    DurationMonitor,
    InputMonitor,
    status,
)
from nuturtle_ros_common.markers import cylinder_marker, delete_all_marker, ellipse_marker, marker_positions
from nuturtle_ros_common.node_main import run_node
from nuturtle_ros_common.ros_params import declare_dataclass
from nuturtle_ros_common.tf_compat import OptionalTfBroadcaster
from nuturtle_ros_common.throttle import SourceWarnings
from nuturtle_ros_common.wheel_joints import WheelJoints
from nuturtle_ros_common.wheel_stream import declare_wheel_stream
from turtlelib import (
    DiffDriveMotion,
    EkfSlam,
    ObservationStatus,
    SlamConfig,
    SlamTimeline,
    TimelineConfig,
    Transform2D,
    Twist2D,
    WheelAngles,
)
from turtlelib.path_trail import PathTrail, PathTrailConfig
from turtlelib.pose_buffer import PoseBuffer
from turtlelib.range_bearing import observations_from_points
from turtlelib.sample_gate import Verdict
from turtlelib.validation import finite_real, names, non_negative, one_of, positive, store
from turtlelib.wheel_odometry import WheelOdometry

ASSOCIATIONS = ("known", "unknown")
GREEN = (0.1, 0.8, 0.2, 1.0)
GREEN_TRANSLUCENT = (0.1, 0.8, 0.2, 0.35)
# odom samples kept to pair with slam's poses (10 s at the odometry node's 20 Hz)
ODOM_BUFFER_SAMPLES = 200
# An input silent this long (s, node clock) is an ERROR in /diagnostics
STALE_S = 2.0
# Drawn confidence region of a mapped landmark (standard deviations)
ELLIPSE_SIGMA = 2.0


@dataclass(frozen=True)
class SlamNodeConfig:
    """The node's own parameters (ValueError for invalid values):

    * ``association``: ``unknown`` (LiDAR landmarks) or ``known`` (nusim's fake sensor, ids given);
    * ``x0``, ``y0``, ``theta0`` (m, m, rad, finite): the start pose ``T_map_body``;
    * ``map_id``, ``odom_id``, ``body_id``, ``sensor_id``: frame ids, non-empty and distinct;
    * ``fake_sensor_std`` (m, > 0): per-axis standard deviation of the fake sensor's positions;
    * ``landmark_radius`` (m, > 0): drawn radius of the mapped landmarks;
    * ``wheel_noise`` (sqrt(rad), >= 0): the motion model's wheel slip, ``N(0, wheel_noise^2 |dphi|)`` per
      wheel over an increment ``dphi`` (:class:`turtlelib.DiffDriveMotion`);
    * ``observation_timeout`` (s, > 0): the wheels turning this long (joint_states time) without an
      observation arriving gives a (throttled) warning: slam is only dead-reckoning.
    """

    association: str = "unknown"
    x0: float = 0.0
    y0: float = 0.0
    theta0: float = 0.0
    map_id: str = "map"
    odom_id: str = "odom"
    body_id: str = "base_footprint"
    sensor_id: str = "base_scan"
    fake_sensor_std: float = 0.01
    landmark_radius: float = 0.038
    wheel_noise: float = 0.05
    observation_timeout: float = 3.0

    def __post_init__(self) -> None:
        one_of("association", self.association, ASSOCIATIONS)
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
        self.node_config = declare_dataclass(self, SlamNodeConfig)
        robot = declare_dataclass(self, RobotParams, overrides=vars(burger_params()))
        # the sensor mount is the robot's: written once, in its description
        T_body_scan = robot.T_body_scan
        sensor_mount = {
            "sensor_x": T_body_scan.x,
            "sensor_y": T_body_scan.y,
            "sensor_theta": T_body_scan.theta,
        }
        self.config = declare_dataclass(self, SlamConfig, fixed=sensor_mount)
        timeline_config = declare_dataclass(self, TimelineConfig)
        self.joints = declare_dataclass(self, WheelJoints)
        self.trail: PathTrail[PoseStamped] = PathTrail(declare_dataclass(self, PathTrailConfig))
        drive = robot.diff_drive()
        motion = DiffDriveMotion(drive, self.node_config.wheel_noise)
        self.slam = EkfSlam(self.config, motion, self.node_config.T_map_body0)
        self.timeline = SlamTimeline(self.slam, WheelAngles(), timeline_config)
        self.odometry = WheelOdometry(drive)
        # T_sensor_frame for the frames observations may come in
        T_body_sensor = self.config.T_body_sensor
        self._T_sensor_from = {
            self.node_config.sensor_id: Transform2D(),
            self.node_config.body_id: T_body_sensor.inverse(),
        }
        self._fake_sensor_covariance = self.node_config.fake_sensor_std**2 * np.eye(2)
        self._observation_topic = "fake_sensor" if self.node_config.association == "known" else "landmarks"
        # the joint_states stamp and wheel angles of the first sample since the last observation
        self._observed_at: tuple[int, tuple[float, float]] | None = None
        self._warnings = SourceWarnings(self.get_logger())
        self._wheels = declare_wheel_stream(self, self.joints, robot, self._warnings)

        self._odom_publisher = self.create_publisher(Odometry, "~/odom", 10)
        self._path_publisher = self.create_publisher(Path, "~/path", 10)
        self._map_publisher = self.create_publisher(MarkerArray, "~/map", 10)
        self._tf = OptionalTfBroadcaster(self)
        self._odom_poses = PoseBuffer(ODOM_BUFFER_SAMPLES)
        # the newest pose not yet paired with odom for map -> odom: (t_ns, T_map_body, stamp)
        self._map_to_odom_pending: tuple[int, Transform2D, Time] | None = None
        self.create_subscription(JointState, "joint_states", self._on_joint_states, 10)
        self.create_subscription(Odometry, "odom", self._on_odom, 10)
        started_ns = self.get_clock().now().nanoseconds
        self._joint_states_input = InputMonitor("joint_states", started_ns, STALE_S)
        self._observation_input = InputMonitor(self._observation_topic, started_ns, STALE_S)
        self._update_time = DurationMonitor()
        self._counts = {"fused": 0, "rejected": 0, "skipped": 0, "arrays_applied": 0}
        self._skipped_reported = self._rejected_reported = 0
        DiagnosticsPublisher(self, self._statuses)
        if self.node_config.association == "known":
            self.create_subscription(MarkerArray, "fake_sensor", self._on_fake_sensor, 10)
        else:
            self.create_subscription(MarkerArray, "landmarks", self._on_landmarks, 10)

    @property
    def observation_counts(self) -> dict[str, int]:
        """Observation arrays so far (read-only): ``received`` on the observation topic, ``applied`` by the
        filter, ``skipped`` (refused), ``pending`` (waiting for motion samples past their stamp)."""
        return {
            "received": self._observation_input.count,
            "applied": self._counts["arrays_applied"],
            "skipped": self._counts["skipped"],
            "pending": self.timeline.pending_count,
        }

    # --- inputs ------------------------------------------------------------------------------------------

    def _on_joint_states(self, msg: JointState) -> None:
        self._joint_states_input.arrived(self.get_clock().now().nanoseconds)
        result = self._wheels.offer(msg)
        if result is None:
            return
        samples = list(result.samples)
        if result.verdict is Verdict.RESTARTED:
            t_ns, angles = samples.pop(0)
            self._restart(t_ns, *angles)
        for t_ns, angles in samples:
            self._add_wheel_sample(t_ns, angles)

    def _add_wheel_sample(self, t_ns: int, angles: tuple[float, float]) -> None:
        """Move the timeline and the body-twist odometry on to a plausible wheel sample; publish the pose."""
        phi_left_rad, phi_right_rad = angles
        t_s = t_ns * 1e-9
        try:
            start = time.perf_counter()
            applied = self.timeline.add_motion(t_ns, angles)
            self._count_applied(applied, start)
            if self.odometry.reference_time_s is None:
                self.odometry.set_reference(t_s, phi_left_rad, phi_right_rad)
            V_body = self.odometry.step(t_s, phi_left_rad, phi_right_rad)
            T_map_body, P_pose = self.timeline.latest_pose()
        except (ValueError, np.linalg.LinAlgError) as error:
            # an increment the kinematics cannot take (a turn rate that overflows): the timeline may hold
            # the sample already and would fail on it again at every later sample, so start afresh from it
            self._warnings.warn(
                "joint_states", f"joint_states skipped: {error}; taking it as the new reference"
            )
            self._restart(t_ns, phi_left_rad, phi_right_rad)
            return
        self._check_observations_arrive(t_ns, angles)
        self._publish_pose(stamp_from_nanoseconds(t_ns), V_body, T_map_body, P_pose)
        if applied:
            self._publish_map(stamp_from_nanoseconds(applied[-1][0]))

    def _on_fake_sensor(self, msg: MarkerArray) -> None:
        self._observation_input.arrived(self.get_clock().now().nanoseconds)
        if self._before_first_motion():
            return
        try:
            t_ns, ids, p_sensor, rotation = self._observed_points(msg)
            # Sigma_sensor = R_sf Sigma R_sf^T
            covariance = np.broadcast_to(
                rotation @ self._fake_sensor_covariance @ rotation.T, (len(ids), 2, 2)
            )
            z, R = observations_from_points(p_sensor, covariance)
            start = time.perf_counter()
            applied = self.timeline.add_observations(t_ns, z, R, ids)
            self._count_applied(applied, start)
        except (ValueError, np.linalg.LinAlgError) as error:
            self._warnings.warn("fake_sensor", f"fake_sensor skipped: {error}")
            self._counts["skipped"] += 1
            return
        self._observed_at = None  # the observations arrive: the silence starts again at the next sample
        if applied:
            self._publish_map(msg.markers[0].header.stamp)

    def _on_landmarks(self, msg: MarkerArray) -> None:
        self._observation_input.arrived(self.get_clock().now().nanoseconds)
        if self._before_first_motion():
            return
        try:
            t_ns, ids, p_sensor, _ = self._observed_points(msg)
            z, _ = observations_from_points(p_sensor, np.zeros((len(ids), 2, 2)))
            start = time.perf_counter()
            applied = self.timeline.add_observations(t_ns, z)
            self._count_applied(applied, start)
        except (ValueError, np.linalg.LinAlgError) as error:
            self._warnings.warn("landmarks", f"landmarks skipped: {error}")
            self._counts["skipped"] += 1
            return
        self._observed_at = None  # the observations arrive: the silence starts again at the next sample
        if applied:
            self._publish_map(msg.markers[0].header.stamp)

    def _on_odom(self, msg: Odometry) -> None:
        frames = self.node_config
        try:
            if (msg.header.frame_id, msg.child_frame_id) != (frames.odom_id, frames.body_id):
                raise ValueError(
                    f"frames {msg.header.frame_id!r} -> {msg.child_frame_id!r}, expected "
                    f"{frames.odom_id!r} -> {frames.body_id!r}"
                )
            T_odom_body = transform_from_pose(msg.pose.pose)
            t_ns = stamp_nanoseconds(msg.header.stamp)
            latest_ns = self._odom_poses.latest_time_ns
            if latest_ns is not None and t_ns == latest_ns:
                return  # a copy of the newest sample
            if latest_ns is not None and t_ns < latest_ns:
                self._odom_poses.clear()  # the odometry source restarted (or a recording looped)
            self._odom_poses.add(t_ns, T_odom_body)
        except ValueError as error:
            self._warnings.warn("odom", f"odom skipped: {error}")
            return
        self._send_map_to_odom()

    def _send_map_to_odom(self) -> None:
        """``T_map_odom = T_map_body T_odom_body^-1`` for the pending pose, once odom covers its stamp."""
        if self._map_to_odom_pending is None:
            return
        t_ns, T_map_body, stamp = self._map_to_odom_pending
        T_odom_body = self._odom_poses.at(t_ns)
        if T_odom_body is None:
            return
        frames = self.node_config
        self._tf.send(
            transform_stamped(T_map_body @ T_odom_body.inverse(), frames.map_id, frames.odom_id, stamp)
        )
        self._map_to_odom_pending = None

    def _before_first_motion(self) -> bool:
        """At start-up observations may come before the first joint_states: there is no pose to place them
        on, so they are dropped (a debug message, not a warning: nothing is wrong)."""
        if self.timeline.latest_time_ns is not None:
            return False
        self.get_logger().debug("observation before the first joint_states: dropped")
        return True

    def _count_applied(self, applied: list, start: float) -> None:
        """Count the observations of ``applied`` scans and time the call that applied them; warn when
        observations were rejected because the map is full."""
        if not applied:
            return
        self._update_time.add(1e3 * (time.perf_counter() - start))
        self._counts["arrays_applied"] += len(applied)
        for _, association in applied:
            rejected = int(np.count_nonzero(association.status == ObservationStatus.REJECTED))
            self._counts["rejected"] += rejected
            self._counts["fused"] += len(association.status) - rejected
            if rejected and self.slam.map_full:
                self._warnings.warn(
                    "map",
                    f"the map holds max_landmarks = {self.config.max_landmarks} landmarks: "
                    "new ones are not added",
                )

    def _statuses(self, now_ns: int) -> list:
        """The inputs, and the filter: WARN when observations were rejected or skipped since the last
        report."""
        skipped = self._counts["skipped"] - self._skipped_reported
        rejected = self._counts["rejected"] - self._rejected_reported
        self._skipped_reported, self._rejected_reported = self._counts["skipped"], self._counts["rejected"]
        mapped, tentative = len(self.slam.landmark_ids), len(self.slam.tentative_ids)
        message = f"{mapped} landmarks mapped, {tentative} tentative"
        if skipped or rejected:
            period = f"{DiagnosticsPublisher.PERIOD_S:g} s"
            message += f"; in the last {period} {skipped} arrays skipped, {rejected} observations rejected"
        values = {
            "landmarks_mapped": mapped,
            "landmarks_tentative": tentative,
            "observations_fused": self._counts["fused"],
            "observations_rejected": self._counts["rejected"],
            "observation_arrays_skipped": self._counts["skipped"],
            **self._update_time.values("scan_update"),
        }
        return [
            self._joint_states_input.status("slam", now_ns),
            self._observation_input.status("slam", now_ns),
            status("slam: filter", "slam", WARN if skipped or rejected else OK, message, values),
        ]

    def _check_observations_arrive(self, t_ns: int, angles: tuple[float, float]) -> None:
        """Warn (throttled) when the wheels have turned for ``observation_timeout`` without observations."""
        if self._observed_at is None or t_ns < self._observed_at[0]:
            self._observed_at = (t_ns, angles)
            return
        since_ns, since_angles = self._observed_at
        silent_s = (t_ns - since_ns) * 1e-9
        if silent_s > self.node_config.observation_timeout and angles != since_angles:
            topic = self._observation_topic
            source = "nusim's fake sensor" if topic == "fake_sensor" else "the landmarks node"
            self._warnings.warn(
                "observations",
                f"no {topic} for {silent_s:.1f} s while the wheels turn: slam is only dead-reckoning "
                f"(is {source} running and publishing {topic}?)",
            )

    def _restart(self, t_ns: int, phi_left_rad: float, phi_right_rad: float) -> None:
        """Take this wheel sample as the new start of the timeline and of the odometry (estimate kept)."""
        self.timeline.restart(t_ns, (phi_left_rad, phi_right_rad))
        self.odometry.set_reference(t_ns * 1e-9, phi_left_rad, phi_right_rad)

    def _observed_points(
        self, msg: MarkerArray
    ) -> tuple[int, NDArray[np.int64], NDArray[np.float64], NDArray[np.float64]]:
        """Stamp (ns), ids, centres ``p_sensor`` (K, 2) and the rotation from the markers' frame into the
        sensor frame; ValueError for an unusable array."""
        positions = marker_positions(msg)
        T_sensor_frame = self._T_sensor_from.get(positions.frame_id)
        if T_sensor_frame is None:
            raise ValueError(
                f"markers in frame {positions.frame_id!r}; expected one of {sorted(self._T_sensor_from)}"
            )
        # p_sensor = T_sensor_frame @ p_frame
        p_sensor = T_sensor_frame @ positions.xy if len(positions.ids) else positions.xy
        return stamp_nanoseconds(positions.stamp), positions.ids, p_sensor, T_sensor_frame.rotation_matrix()

    # --- outputs -----------------------------------------------------------------------------------------

    def _publish_pose(
        self, stamp: Time, V_body: Twist2D, T_map_body: Transform2D, P_pose: NDArray[np.float64]
    ) -> None:
        frames = self.node_config
        odom = odometry_message(T_map_body, V_body, frames.map_id, frames.body_id, stamp, P_pose)
        self._odom_publisher.publish(odom)
        if self._tf.available:
            self._map_to_odom_pending = (stamp_nanoseconds(stamp), T_map_body, stamp)
            self._send_map_to_odom()
        if self.trail.offer(T_map_body, PoseStamped(header=odom.header, pose=odom.pose.pose)):
            self._path_publisher.publish(Path(header=odom.header, poses=list(self.trail.items)))

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
    sys.exit(run_node(lambda: SlamNode(), "slam", args))


if __name__ == "__main__":
    main()
