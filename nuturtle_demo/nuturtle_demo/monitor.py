"""`demo_monitor`: collect the pose streams a run is judged by, as an ordinary subscriber.

Subscribes (nav_msgs/Odometry)
    `nusim/ground_truth` (frame `nusim/world`), `odom` (frame `odom`), `slam/odom` (frame `map`, with the
    EKF's pose covariance).
Each stream keeps ``[t, x, y, theta]`` per message (t = header stamp, s) and, for `slam/odom`, the
(x, y, yaw) block of the 6x6 pose covariance. A message whose stamp is not later than the previous one
of its stream replaces that sample (an estimator may publish twice for one instant: after prediction
and after the update), so every series is strictly increasing in time.
"""

from __future__ import annotations

from typing import Any

import numpy as np
from nav_msgs.msg import Odometry
from numpy.typing import NDArray
from rclpy.node import Node

from nuturtle_ros_common.conversions import covariance_from_6x6, stamp_seconds, yaw_from_quaternion

from .metrics import PoseSeries

TRUTH_TOPIC = "nusim/ground_truth"
ODOM_TOPIC = "odom"
SLAM_TOPIC = "slam/odom"
# Subscription depth: no sample may be lost while the executor is busy
DEPTH = 100


class _Stream:
    """Rows ``[t, x, y, theta]`` (and optional 3x3 covariances) with strictly increasing t."""

    def __init__(self) -> None:
        self.rows: list[tuple[float, float, float, float]] = []
        self.covariances: list[NDArray[np.float64]] = []

    def add(self, msg: Odometry, covariance: NDArray[np.float64] | None = None) -> None:
        pose = msg.pose.pose
        row = (
            stamp_seconds(msg.header.stamp),
            pose.position.x,
            pose.position.y,
            yaw_from_quaternion(pose.orientation),
        )
        replace = bool(self.rows) and row[0] <= self.rows[-1][0]
        if replace:
            self.rows[-1] = row
        else:
            self.rows.append(row)
        if covariance is not None:
            if replace:
                self.covariances[-1] = covariance
            else:
                self.covariances.append(covariance)

    def series(self) -> PoseSeries:
        rows = np.array(self.rows, dtype=np.float64).reshape(-1, 4)
        return PoseSeries(rows[:, 0], rows[:, 1:])


class RunMonitor(Node):
    """The `demo_monitor` node (module docstring); kwargs go to rclpy's Node."""

    def __init__(self, **kwargs: Any) -> None:
        super().__init__("demo_monitor", **kwargs)
        self._truth = _Stream()
        self._odom = _Stream()
        self._slam = _Stream()
        self.create_subscription(Odometry, TRUTH_TOPIC, self._truth.add, DEPTH)
        self.create_subscription(Odometry, ODOM_TOPIC, self._odom.add, DEPTH)
        self.create_subscription(Odometry, SLAM_TOPIC, self._on_slam, DEPTH)

    def _on_slam(self, msg: Odometry) -> None:
        self._slam.add(msg, covariance_from_6x6(msg.pose.covariance))

    @property
    def counts(self) -> dict[str, int]:
        return {
            TRUTH_TOPIC: len(self._truth.rows),
            ODOM_TOPIC: len(self._odom.rows),
            SLAM_TOPIC: len(self._slam.rows),
        }

    @property
    def latest_truth_s(self) -> float:
        """Stamp (s) of the latest ground truth, 0 before the first."""
        return self._truth.rows[-1][0] if self._truth.rows else 0.0

    def truth(self) -> PoseSeries:
        return self._truth.series()

    def odom(self) -> PoseSeries:
        """Odometry poses in its own frame `odom` (see ``metrics.odom_in_world``)."""
        return self._odom.series()

    def slam(self) -> PoseSeries:
        return self._slam.series()

    def slam_covariances(self) -> NDArray[np.float64]:
        """(K, 3, 3) (x, y, theta) covariance of each `slam/odom` sample."""
        return np.array(self._slam.covariances, dtype=np.float64).reshape(-1, 3, 3)
