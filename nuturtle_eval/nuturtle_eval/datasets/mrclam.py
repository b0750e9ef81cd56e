"""Reader of one robot of a UTIAS MRCLAM dataset (Leung et al., IJRR 2011): pure numpy, no ROS.

Files
-----
One ``MRCLAM_DatasetN`` directory (N = 1..9) holds, for robot K = 1..5, text files with ``#`` header
lines, CRLF line endings and tab/space separators:

* ``RobotK_Odometry.dat``: ``time [s]``, ``v [m/s]``, ``omega [rad/s]``. The **commanded** forward and
  angular (CCW+) velocities, about 67 Hz; hold each over [t_k, t_k+1] in a unicycle model.
* ``RobotK_Measurement.dat``: ``time [s]``, ``barcode``, ``range [m]``, ``bearing [rad]``. The second
  column is the observed **barcode**, not a subject number; the bearing is in the robot frame (x forward,
  CCW+). Rows of landmarks and of the other robots are mixed, and several rows can share a time.
* ``RobotK_Groundtruth.dat``: ``time [s]``, ``x [m]``, ``y [m]``, ``theta [rad]``: Vicon poses in the
  Vicon (inertial) frame, for evaluation only.
* ``Landmark_Groundtruth.dat``: ``subject``, ``x [m]``, ``y [m]``, ``sigma_x [m]``, ``sigma_y [m]``:
  Vicon mean landmark positions (the standard deviations are not kept).
* ``Barcodes.dat``: ``subject``, ``barcode``. Subjects 1-5 are the robots, the others the landmarks.
  The mapping differs between datasets, so it is always read from the same directory.

A measurement's barcode is mapped to a subject through ``Barcodes.dat``. A row is a landmark observation
when that subject is listed in ``Landmark_Groundtruth.dat``. Every other row (a robot, or a barcode that
``Barcodes.dat`` does not list) is dropped and counted in :attr:`MrclamRecording.dropped_measurements`.
The landmark's id is its subject number, so data association is known.

Time
----
The files stamp rows in Unix epoch seconds with millisecond resolution (three decimals); robot and Vicon
clocks are NTP-synchronised. Stamps become int64 nanoseconds as
``np.round(t_s * 1000).astype(np.int64) * 1_000_000``. Rounding to whole milliseconds first removes the
float64 error of a ~1.2e9 s value (about 2e-7 s), so every stamp is an exact multiple of 1 ms and equals
the file's digits. Each robot file is sorted stably by time, so rows sharing a stamp keep their file
order. The Dataset 6 and 7 files of all five robots are already in time order (checked), so the sort
changes nothing there. Odometry and measurement stamps may repeat; ground-truth stamps must not
(a repeated one is a ValueError).
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

import numpy as np
from numpy.typing import NDArray

from nuturtle_eval.datasets._files import existing_folder, read_table

ROBOTS = range(1, 6)


@dataclass(frozen=True)
class MrclamRecording:
    """One robot's run: commanded velocities, landmark observations, Vicon truth and the landmark map.

    Times are int64 ns since the Unix epoch, on the robots' NTP-synchronised clock.
    """

    robot: int
    odometry_t_ns: NDArray[np.int64]
    """(M,) non-decreasing: the times of the commanded-velocity rows."""
    odometry_v_mps: NDArray[np.float64]
    """(M,) commanded forward velocity (m/s)."""
    odometry_omega_rad_s: NDArray[np.float64]
    """(M,) commanded angular velocity (rad/s, CCW+)."""
    measurement_t_ns: NDArray[np.int64]
    """(K,) non-decreasing: landmark observations only."""
    measurement_subject: NDArray[np.int64]
    """(K,) the observed landmark's subject number (its id)."""
    measurement_range_m: NDArray[np.float64]
    """(K,) range from the robot to the landmark (m)."""
    measurement_bearing_rad: NDArray[np.float64]
    """(K,) bearing in the robot frame (rad, x forward, CCW+)."""
    truth_t_ns: NDArray[np.int64]
    """(T,) increasing."""
    truth_poses: NDArray[np.float64]
    """(T, 3) ``[x, y, theta]`` in the Vicon frame (m, m, rad)."""
    landmark_subjects: NDArray[np.int64]
    """(L,) subject numbers, in the order of ``Landmark_Groundtruth.dat``."""
    landmark_xy: NDArray[np.float64]
    """(L, 2) Vicon landmark positions ``[x, y]`` (m)."""
    dropped_measurements: int
    """Measurement rows whose barcode is not a landmark's (the robots, barcodes missing from Barcodes.dat)."""


def load_mrclam(directory: str | Path, robot: int) -> MrclamRecording:
    """Read robot ``robot`` (1..5) of the MRCLAM dataset in ``directory`` (see the module docstring).

    Raises ValueError for a robot outside 1..5, and, naming the file, for a missing file, a wrong column
    count, a non-integer subject or barcode, a barcode listed twice, a repeated landmark subject or a
    repeated ground-truth time.
    """
    if isinstance(robot, bool) or not isinstance(robot, int | np.integer) or int(robot) not in ROBOTS:
        raise ValueError(f"robot must be one of 1..5, got {robot!r}")
    robot = int(robot)
    folder = existing_folder(Path(directory))

    barcodes_path = folder / "Barcodes.dat"
    barcodes = read_table(barcodes_path, 2)
    barcode_subjects = _integers(barcodes[:, 0], barcodes_path, "subject")
    codes = _integers(barcodes[:, 1], barcodes_path, "barcode")
    if np.unique(codes).size != codes.size:
        raise ValueError(f"{barcodes_path}: a barcode is listed twice")

    landmarks_path = folder / "Landmark_Groundtruth.dat"
    landmarks = read_table(landmarks_path, 5)
    landmark_subjects = _integers(landmarks[:, 0], landmarks_path, "subject")
    if np.unique(landmark_subjects).size != landmark_subjects.size:
        raise ValueError(f"{landmarks_path}: a landmark subject is listed twice")

    odometry = _by_time(read_table(folder / f"Robot{robot}_Odometry.dat", 3))

    measurements_path = folder / f"Robot{robot}_Measurement.dat"
    measurements = _by_time(read_table(measurements_path, 4))
    measured_codes = _integers(measurements[:, 1], measurements_path, "barcode")
    is_landmark = np.isin(measured_codes, codes[np.isin(barcode_subjects, landmark_subjects)])
    landmark_rows = measurements[is_landmark]
    # each kept row's subject: the Barcodes.dat row of its barcode, looked up in the sorted barcodes
    by_code = np.argsort(codes)
    landmark_row_subjects = barcode_subjects[
        by_code[np.searchsorted(codes, measured_codes[is_landmark], sorter=by_code)]
    ]

    truth_path = folder / f"Robot{robot}_Groundtruth.dat"
    truth = _by_time(read_table(truth_path, 4))
    truth_t_ns = _epoch_ns(truth[:, 0])
    if np.any(np.diff(truth_t_ns) == 0):
        raise ValueError(f"{truth_path}: a time stamp is repeated")

    return MrclamRecording(
        robot=robot,
        odometry_t_ns=_epoch_ns(odometry[:, 0]),
        odometry_v_mps=odometry[:, 1].copy(),
        odometry_omega_rad_s=odometry[:, 2].copy(),
        measurement_t_ns=_epoch_ns(landmark_rows[:, 0]),
        measurement_subject=landmark_row_subjects,
        measurement_range_m=landmark_rows[:, 2].copy(),
        measurement_bearing_rad=landmark_rows[:, 3].copy(),
        truth_t_ns=truth_t_ns,
        truth_poses=truth[:, 1:4].copy(),
        landmark_subjects=landmark_subjects,
        landmark_xy=landmarks[:, 1:3].copy(),
        dropped_measurements=int(np.count_nonzero(~is_landmark)),
    )


def _epoch_ns(t_s: NDArray[np.float64]) -> NDArray[np.int64]:
    """Epoch seconds with millisecond resolution as int64 ns: rounded to whole ms, then scaled exactly."""
    return np.round(t_s * 1000).astype(np.int64) * 1_000_000


def _by_time(table: NDArray[np.float64]) -> NDArray[np.float64]:
    """The rows sorted stably by their first column (the time)."""
    return table[np.argsort(table[:, 0], kind="stable")]


def _integers(column: NDArray[np.float64], path: Path, name: str) -> NDArray[np.int64]:
    """A column of whole numbers as int64, or a ValueError naming the file."""
    if not np.all(column == np.round(column)):
        raise ValueError(f"{path}: the {name} column holds a non-integer value")
    return column.astype(np.int64)
