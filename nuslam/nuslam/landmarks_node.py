"""`landmarks`: cylinders found in each LiDAR scan (a thin wrapper over `turtlelib.LandmarkDetector`).
`landmarks_managed` runs it as a managed (lifecycle) node (`nuslam.managed_nodes`).

Subscribes
    `scan` (sensor_msgs/LaserScan, sensor-data QoS as the LDS-01 publishes it).
Publishes (stamped with the scan's stamp, in the scan's frame)
    `landmarks` (visualization_msgs/MarkerArray): a DELETEALL, then one CYLINDER (ADD) per detected cylinder,
        id = its index in this scan, centre in ``pose.position`` (m), diameter in ``scale.x``/``scale.y``,
        and the detection's range-bearing covariance ``R = diag(range_std^2, bearing_std^2)`` (2x2, [range
        m, bearing rad] about the scan frame's origin) in ``text`` as ``R=<R_rr> <R_rb> <R_bb>`` (exact
        floats; `nuturtle_ros_common.markers.noise_text`): the noise slam fuses the detection with.
        One array per scan, also when nothing is found (SLAM counts scans).
    `~/clusters` (visualization_msgs/MarkerArray): a DELETEALL, then one POINTS marker per cluster of the
        scan, cylinders green and rejected clusters grey (for tuning the thresholds).
    `/diagnostics` (diagnostic_msgs/DiagnosticArray, 1 Hz): `landmarks: scan` (rate; ERROR after
        `STALE_S` without a scan) and `landmarks: detector` (time per scan, cylinders in the last scan,
        scans used and refused since start-up, the last refusal's reason; WARN when scans were refused
        since the last report, ERROR when every scan since then was: scans arrive but none is used).
Parameters
    Every field of `turtlelib.DetectorConfig` (cluster_threshold, min_points, min_radius, max_radius, ...),
    under the same names; `range_std` and `bearing_std` are THE observation noise of a detection (slam has
    no such parameters of its own). Invalid values stop the node at start-up with a message.

A scan that `nuturtle_ros_common.conversions.range_scan_from_message` refuses (a layout that contradicts
itself, `turtlelib.check_scan_layout`: angle_min, angle_max, angle_increment and the number of ranges
disagree; intensities neither empty nor one per range; a non-finite layout; range_min >= range_max) is
skipped with a throttled warning and counted; the node keeps running. Every TurtleBot3 LiDAR's layout is
used (LDS-01, LDS-02 with its beam count changing from scan to scan, Gazebo's): beams beyond one full turn
(Gazebo's last, which repeats its first) are dropped, and 0.0, NaN, inf and beams outside [range_min,
range_max] are no return.
"""

from __future__ import annotations

import sys
import time

from geometry_msgs.msg import Point
from rclpy.node import Node
from rclpy.qos import qos_profile_sensor_data
from sensor_msgs.msg import LaserScan
from visualization_msgs.msg import Marker, MarkerArray

from nuturtle_ros_common.conversions import range_scan_from_message
from nuturtle_ros_common.diagnostics import (
    ERROR,
    OK,
    STALE_S,
    WARN,
    DiagnosticsPublisher,
    DurationMonitor,
    InputMonitor,
    status,
)
from nuturtle_ros_common.markers import cylinder_marker, delete_all_marker, noise_text, set_color
from nuturtle_ros_common.node_main import run_node
from nuturtle_ros_common.ros_params import declare_dataclass
from nuturtle_ros_common.throttle import WARN_THROTTLE_S
from turtlelib import Clusters, Detections, DetectorConfig, LandmarkDetector

GREEN = (0.1, 0.8, 0.2, 1.0)
GREY = (0.6, 0.6, 0.6, 0.8)
# Size of a drawn cluster point (m)
CLUSTER_POINT_M = 0.02


def landmark_markers(detections: Detections, msg: LaserScan) -> MarkerArray:
    """The `landmarks` array of one scan: DELETEALL, then a CYLINDER per detection carrying its noise."""
    frame_id, stamp = msg.header.frame_id, msg.header.stamp
    markers = [delete_all_marker(frame_id, stamp)]
    for k, ((x, y), radius_m, R) in enumerate(
        zip(detections.p_sensor, detections.radius, detections.covariance, strict=True)
    ):
        marker = cylinder_marker(frame_id, stamp, "landmarks", k, float(x), float(y), float(radius_m), GREEN)
        marker.text = noise_text(R)
        markers.append(marker)
    return MarkerArray(markers=markers)


def cluster_markers(clusters: Clusters, detections: Detections, msg: LaserScan) -> MarkerArray:
    """The `~/clusters` array of one scan: DELETEALL, then a POINTS marker per cluster, green when the
    cluster became one of the ``detections``, grey otherwise."""
    frame_id, stamp = msg.header.frame_id, msg.header.stamp
    markers = [delete_all_marker(frame_id, stamp)]
    cylinders = set(detections.cluster_index.tolist())
    for k in range(len(clusters)):
        marker = Marker(ns="clusters", id=k, type=Marker.POINTS, action=Marker.ADD)
        marker.header.frame_id = frame_id
        marker.header.stamp = stamp
        marker.pose.orientation.w = 1.0
        marker.scale.x = marker.scale.y = CLUSTER_POINT_M
        marker.points = [Point(x=float(x), y=float(y)) for x, y in clusters.points(k)]
        set_color(marker, GREEN if k in cylinders else GREY)
        markers.append(marker)
    return MarkerArray(markers=markers)


class LandmarksNode(Node):
    """The `landmarks` node (see the module docstring); kwargs go to rclpy's Node."""

    def __init__(self, **kwargs) -> None:
        super().__init__("landmarks", **kwargs)
        self.build()

    def build(self) -> None:
        """Read the parameters (ValueError for an invalid one), build the detector, then the topics and
        timer: at construction, or at configure for `landmarks_managed` (`nuslam.managed_nodes`)."""
        self.config = declare_dataclass(self, DetectorConfig)
        self.detector = LandmarkDetector(self.config)
        self._landmarks_publisher = self.create_publisher(MarkerArray, "landmarks", 10)
        self._clusters_publisher = self.create_publisher(MarkerArray, "~/clusters", 10)
        self.create_subscription(LaserScan, "scan", self._on_scan, qos_profile_sensor_data)
        self._scans = InputMonitor("scan", self.get_clock().now().nanoseconds, STALE_S)
        self._detect_time = DurationMonitor()
        self._used = self._used_reported = 0
        self._refused = self._refused_reported = 0
        self._last_refusal = "none"
        self._cylinders = 0
        DiagnosticsPublisher(self, self._statuses)

    @property
    def scan_counts(self) -> dict[str, int]:
        """Scans so far (read-only): ``received`` on `scan`, ``refused`` (skipped with a warning)."""
        return {"received": self._scans.count, "refused": self._refused}

    @property
    def last_refusal(self) -> str:
        """Why the last refused scan was refused (``none`` before any was)."""
        return self._last_refusal

    def _statuses(self, now_ns: int) -> list:
        """The scan input, and the detector: WARN when scans were refused since the last report, ERROR
        when every one since then was (with the last reason)."""
        refused_now, self._refused_reported = self._refused - self._refused_reported, self._refused
        used_now, self._used_reported = self._used - self._used_reported, self._used
        values = {
            "cylinders_last_scan": self._cylinders,
            "scans_used": self._used,
            "scans_refused": self._refused,
            "last_refusal": self._last_refusal,
        }
        values.update(self._detect_time.values("detection"))
        level, message = OK, f"{self._cylinders} cylinders in the last scan"
        if refused_now:
            level = WARN if used_now else ERROR
            message = (
                f"{refused_now} of {refused_now + used_now} scans refused in the last "
                f"{DiagnosticsPublisher.PERIOD_S:g} s ({self._last_refusal}); {message}"
            )
        detector = status("landmarks: detector", "landmarks", level, message, values)
        return [self._scans.status("landmarks", now_ns), detector]

    def _on_scan(self, msg: LaserScan) -> None:
        self._scans.arrived(self.get_clock().now().nanoseconds)
        start = time.perf_counter()
        try:
            detections, clusters = self.detector.detect_with_clusters(range_scan_from_message(msg))
        except ValueError as error:
            self.get_logger().warning(f"scan skipped: {error}", throttle_duration_sec=WARN_THROTTLE_S)
            self._refused += 1
            self._last_refusal = str(error)
            return
        self._used += 1
        self._detect_time.add(1e3 * (time.perf_counter() - start))
        self._cylinders = len(detections.radius)
        self._landmarks_publisher.publish(landmark_markers(detections, msg))
        if self._clusters_publisher.get_subscription_count():
            self._clusters_publisher.publish(cluster_markers(clusters, detections, msg))


def main(args: list[str] | None = None) -> None:
    sys.exit(run_node(lambda: LandmarksNode(), "landmarks", __doc__, args))


if __name__ == "__main__":
    main()
