"""`demo_monitor`: collect the pose streams a run is judged by, as an ordinary subscriber.

Subscribes (nav_msgs/Odometry)
    `nusim/ground_truth` (frame `nusim/world`), `odom` (frame `odom`), `slam/odom` (frame `map`, with the
    EKF's pose covariance).
Publishes
    `demo_monitor/slam_error` (std_msgs/Float64MultiArray) ``[position_error_m, heading_error_rad,
    nees_pose]``, one message per `slam/odom` sample: ``e = [x_hat - x, y_hat - y, wrap(theta_hat -
    theta)]`` against the truth interpolated at that sample's stamp (``metrics.pose_errors``), ``|e_xy|``,
    ``e_theta`` and ``e^T P^-1 e`` (3 dof; NaN while P is not positive definite, as at the exactly known
    start). Computed in batches: when a ground-truth stamp enters a new ``ERROR_BATCH_S`` period of
    simulation time, for every sample since the last batch that the ground truth has passed, in one
    vectorised call (so a sample's error comes 0.05-0.55 s of simulation time after its stamp, the
    batch's messages back to back; the samples of the run's last period are not published). A live
    view's plots (docs/live.md); nothing is published without ground truth.

Each stream keeps ``[t, x, y, theta]`` per message (t = header stamp, s) and, for `slam/odom`, the
(x, y, yaw) block of the 6x6 pose covariance. A message whose stamp is not later than the previous one
of its stream replaces that sample (an estimator may publish twice for one instant: after prediction
and after the update), so every series is strictly increasing in time.

Memory stays flat however long the run: each stream is a :class:`RowTable` of float64 rows (32 bytes per
pose, 72 more per covariance) that holds its newest ``BLOCK_ROWS`` rows in memory and moves every full
block to an unnamed temporary file; the series are read back when asked for. (Kept as Python tuples and
3x3 arrays in memory, the samples took about 180 and 200 bytes each: 50 MB per hour of robot time.)
"""

from __future__ import annotations

import math
import os
import tempfile
from collections.abc import Sequence
from typing import Any

import numpy as np
from nav_msgs.msg import Odometry
from numpy.typing import NDArray
from rclpy.node import Node
from std_msgs.msg import Float64MultiArray, MultiArrayDimension, MultiArrayLayout

from nuturtle_eval.metrics import PoseSeries, pose_errors, pose_nees
from nuturtle_ros_common.conversions import covariance_from_6x6, stamp_seconds, yaw_from_quaternion

TRUTH_TOPIC = "nusim/ground_truth"
ODOM_TOPIC = "odom"
SLAM_TOPIC = "slam/odom"
# Subscription depth: no sample may be lost while the executor is busy
DEPTH = 100
# Rows of a stream held in memory before they move to its temporary file (204 s of a 20 Hz stream)
BLOCK_ROWS = 4096
POSE_COLUMNS = 4  # t, x, y, theta
COVARIANCE_COLUMNS = 9  # the (x, y, theta) 3x3 covariance, row-major
ERROR_TOPIC = "~/slam_error"
ERROR_LABELS = ("position_error_m", "heading_error_rad", "nees_pose")
# Simulation time between two batches of the live error (s)
ERROR_BATCH_S = 0.5
# Ground-truth samples before the last batch's newest that the next batch still reads: how far (2.5 s of a
# 20 Hz stream) a slam/odom sample may arrive behind the ground truth and still be judged
ERROR_TRUTH_ROWS = 50


class RowTable:
    """A growing table of rows of ``width`` float64 values in bounded memory: the newest rows (at most
    ``block_rows``, >= 1) in one block, the older ones in an unnamed temporary file (in ``directory``, or
    the default temporary folder if None), written a block at a time. ``close()`` deletes the file."""

    def __init__(self, width: int, block_rows: int = BLOCK_ROWS, directory: str | None = None) -> None:
        if width < 1 or block_rows < 1:
            raise ValueError(f"width and block_rows must be >= 1, got {width} and {block_rows}")
        self.width = int(width)
        self._block = np.empty((int(block_rows), self.width), dtype=np.float64)
        self._in_block = 0
        self._in_file = 0
        self._directory = directory
        self._file: Any = None

    def __len__(self) -> int:
        return self._in_file + self._in_block

    def append(self, row: Sequence[float]) -> None:
        """Add a row of ``width`` values; a full block first moves to the file."""
        if self._in_block == self._block.shape[0]:
            if self._file is None:
                self._file = tempfile.TemporaryFile(dir=self._directory)
            self._file.seek(0, os.SEEK_END)
            self._file.write(self._block.tobytes())
            self._in_file += self._in_block
            self._in_block = 0
        self._block[self._in_block] = row
        self._in_block += 1

    @property
    def last(self) -> NDArray[np.float64]:
        """The newest row, a view (assigning to it replaces that row); IndexError when empty."""
        if not self._in_block:
            raise IndexError("no rows")
        return self._block[self._in_block - 1]

    def rows(self, start: int = 0) -> NDArray[np.float64]:
        """Rows ``start`` (from 0, or from the end when negative) to the newest, (n, width), a copy."""
        begin = max(len(self) + start, 0) if start < 0 else min(start, len(self))
        parts = []
        if begin < self._in_file:
            self._file.seek(begin * self.width * 8)
            data = self._file.read((self._in_file - begin) * self.width * 8)
            parts.append(np.frombuffer(data, dtype=np.float64).reshape(-1, self.width))
        parts.append(self._block[max(begin - self._in_file, 0) : self._in_block])
        return np.concatenate(parts) if len(parts) > 1 else parts[0].copy()

    def close(self) -> None:
        if self._file is not None:
            self._file.close()
            self._file = None
        self._in_file = self._in_block = 0


class _Stream:
    """Rows ``[t, x, y, theta]`` (and, with ``covariances``, the 3x3 covariance's 9 values) with strictly
    increasing t."""

    def __init__(self, covariances: bool = False) -> None:
        self.table = RowTable(POSE_COLUMNS + (COVARIANCE_COLUMNS if covariances else 0))

    def add(self, msg: Odometry, covariance: NDArray[np.float64] | None = None) -> None:
        pose = msg.pose.pose
        row = [
            stamp_seconds(msg.header.stamp),
            pose.position.x,
            pose.position.y,
            yaw_from_quaternion(pose.orientation),
        ]
        if covariance is not None:
            row.extend(np.asarray(covariance, dtype=np.float64).reshape(COVARIANCE_COLUMNS).tolist())
        if len(self.table) and row[0] <= self.table.last[0]:
            self.table.last[:] = row
        else:
            self.table.append(row)

    def series(self, last: int | None) -> PoseSeries:
        if last is not None and last < 1:
            raise ValueError(f"last must be >= 1, got {last!r}")
        rows = self.table.rows(-last if last is not None else 0)
        return PoseSeries(rows[:, 0], rows[:, 1:POSE_COLUMNS])

    def covariances(self) -> NDArray[np.float64]:
        return self.table.rows()[:, POSE_COLUMNS:].reshape(-1, 3, 3)


class RunMonitor(Node):
    """The `demo_monitor` node (module docstring); kwargs go to rclpy's Node. ``truth()``, ``odom()`` and
    ``slam()`` give every sample so far, or the newest ``last`` (>= 1)."""

    def __init__(self, **kwargs: Any) -> None:
        super().__init__("demo_monitor", **kwargs)
        self._truth = _Stream()
        self._odom = _Stream()
        self._slam = _Stream(covariances=True)
        # the live error's bookkeeping: slam rows judged so far, truth rows when the last batch ran, and
        # the ERROR_BATCH_S period of that batch
        self._slam_judged = 0
        self._truth_at_batch = 0
        self._batch_period = -1
        self._errors = self.create_publisher(Float64MultiArray, ERROR_TOPIC, DEPTH)
        self._error_msg = Float64MultiArray(
            layout=MultiArrayLayout(dim=[MultiArrayDimension(label=",".join(ERROR_LABELS), size=3, stride=3)])
        )
        self.create_subscription(Odometry, TRUTH_TOPIC, self._on_truth, DEPTH)
        self.create_subscription(Odometry, ODOM_TOPIC, self._odom.add, DEPTH)
        self.create_subscription(Odometry, SLAM_TOPIC, self._on_slam, DEPTH)

    def _on_truth(self, msg: Odometry) -> None:
        self._truth.add(msg)
        period = math.floor(self._truth.table.last[0] / ERROR_BATCH_S)
        if period > self._batch_period:
            self._batch_period = period
            self._publish_errors()

    def _on_slam(self, msg: Odometry) -> None:
        self._slam.add(msg, covariance_from_6x6(msg.pose.covariance))

    def _publish_errors(self) -> None:
        """The error of every slam sample since the last batch that the ground truth has passed; those
        older than the truth read (ERROR_TRUTH_ROWS before the last batch's newest) are skipped."""
        truth_rows = self._truth.table.rows(max(self._truth_at_batch - ERROR_TRUTH_ROWS, 0))
        self._truth_at_batch = len(self._truth.table)
        slam_rows = self._slam.table.rows(self._slam_judged)
        judged = int(np.searchsorted(slam_rows[:, 0], truth_rows[-1, 0], side="left"))
        self._slam_judged += judged
        covered = slam_rows[:judged][slam_rows[:judged, 0] >= truth_rows[0, 0]]
        if not covered.shape[0] or truth_rows.shape[0] < 2:
            return
        truth = PoseSeries(truth_rows[:, 0], truth_rows[:, 1:POSE_COLUMNS])
        estimate = PoseSeries(covered[:, 0], covered[:, 1:POSE_COLUMNS])
        errors = pose_errors(estimate, truth)
        nees_values = pose_nees(errors, covered[:, POSE_COLUMNS:].reshape(-1, 3, 3))
        values = np.column_stack([np.hypot(errors[:, 0], errors[:, 1]), errors[:, 2], nees_values])
        for row in values.tolist():
            self._error_msg.data = row
            self._errors.publish(self._error_msg)

    @property
    def counts(self) -> dict[str, int]:
        return {
            TRUTH_TOPIC: len(self._truth.table),
            ODOM_TOPIC: len(self._odom.table),
            SLAM_TOPIC: len(self._slam.table),
        }

    def truth(self, last: int | None = None) -> PoseSeries:
        return self._truth.series(last)

    def odom(self, last: int | None = None) -> PoseSeries:
        """Odometry poses in its own frame `odom` (see ``metrics.odom_in_world``)."""
        return self._odom.series(last)

    def slam(self, last: int | None = None) -> PoseSeries:
        return self._slam.series(last)

    def slam_covariances(self) -> NDArray[np.float64]:
        """(K, 3, 3) (x, y, theta) covariance of each `slam/odom` sample."""
        return self._slam.covariances()

    def destroy_node(self) -> None:
        """Delete the streams' temporary files, then destroy the node."""
        for stream in (self._truth, self._odom, self._slam):
            stream.table.close()
        super().destroy_node()
