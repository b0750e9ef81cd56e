"""Reader of the Victoria Park run (ACFR, Guivant & Nebot 2001) and its GPS outlier check: numpy/scipy.

Sources
-------
In one directory:

* ``aa3_dr.mat`` (MATLAB 5, ``scipy.io.loadmat``): ``time`` (N, 1) int32 ms on the sensor clock, 40 Hz;
  ``speed`` (N, 1) m/s from the **rear-left wheel encoder** (as recorded, not the rear-axle centre);
  ``steering`` (N, 1) rad, front-wheel steering angle, positive = turning left.
* ``aa3_gpsx.mat``: ``timeGps`` (G, 1) int32 ms on the same clock, nominally 5 Hz with gaps; ``Lo_m``
  (G, 1) "longitude in metres" = local **East**; ``La_m`` (G, 1) "latitude in metres" = local **North**.
  The GPS antenna sits at the laser.
* ``detections_rfsslam/measurements.dat`` (text, whitespace separated): ``t [s]``, ``range [m]``,
  ``bearing [rad]``, ``diameter [m]``: the vendor tree detector's output per laser scan (RFS-SLAM
  conversion). The range is laser to trunk centre. The bearing is in the **laser frame, 0..pi**
  (0 = right, pi/2 = ahead, pi = left). Several rows share one scan time, and scans without a detection
  are absent.

Frames
------
Bearings are returned in the **vehicle frame** (x forward, y left, CCW+) as ``bearing - pi/2``, so a
detection straight ahead has bearing 0. GPS positions are ``[East, North]`` in metres.

Time base
---------
Everything is put on the common base of the derived files, ``t = (t_ms - timeGps[0]) / 1000`` s, in
int64 ns. ``timeGps[0]`` (20967 ms) is the earliest stamp of the run, so the first GPS fix is at 0 s, the
first laser scan at 0.852 s and the first odometry sample at 0.973 s. The .mat stamps become
``(t_ms - timeGps[0]) * 1_000_000`` exactly. ``measurements.dat`` is already on this base, in seconds
with three decimals (millisecond resolution). Its stamps become ``np.round(t_s * 1e6).astype(np.int64)
* 1000``, which rounds to whole microseconds and so keeps those millisecond stamps exact. The odometry
and GPS stamps must be increasing and the detection stamps non-decreasing (the files are; checked),
otherwise ValueError.
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

import numpy as np
import scipy.io
from numpy.typing import NDArray

from nuturtle_eval.datasets._files import existing_file, existing_folder, read_table


@dataclass(frozen=True)
class VictoriaRecording:
    """The Victoria Park run on the common time base (int64 ns since ``timeGps[0]``)."""

    odometry_t_ns: NDArray[np.int64]
    """(M,) increasing."""
    speed_mps: NDArray[np.float64]
    """(M,) rear-left wheel encoder speed (m/s), as recorded."""
    steering_rad: NDArray[np.float64]
    """(M,) front-wheel steering angle (rad), positive = left."""
    detection_t_ns: NDArray[np.int64]
    """(K,) non-decreasing: the scan time of each tree detection."""
    detection_range_m: NDArray[np.float64]
    """(K,) laser to trunk centre (m)."""
    detection_bearing_rad: NDArray[np.float64]
    """(K,) vehicle frame (x forward, CCW+): the laser-frame bearing minus pi/2 (rad)."""
    detection_diameter_m: NDArray[np.float64]
    """(K,) apparent trunk diameter (m)."""
    gps_t_ns: NDArray[np.int64]
    """(G,) increasing."""
    gps_xy: NDArray[np.float64]
    """(G, 2) ``[East, North]`` (m)."""


def load_victoria(directory: str | Path) -> VictoriaRecording:
    """Read the Victoria Park run in ``directory`` (see the module docstring).

    Raises ValueError, naming the file, for a missing or unreadable file, a missing variable, variables
    of unequal length, a non-integer time, a wrong column count, or stamps out of order.
    """
    folder = existing_folder(Path(directory))
    gps_path = folder / "aa3_gpsx.mat"
    gps = _read_mat(gps_path, ("timeGps", "Lo_m", "La_m"))
    base_ms = int(gps["timeGps"][0])
    gps_t_ns = _increasing((gps["timeGps"] - base_ms) * 1_000_000, gps_path, strict=True)

    odometry_path = folder / "aa3_dr.mat"
    odometry = _read_mat(odometry_path, ("time", "speed", "steering"))
    odometry_t_ns = _increasing((odometry["time"] - base_ms) * 1_000_000, odometry_path, strict=True)

    detections_path = folder / "detections_rfsslam" / "measurements.dat"
    detections = read_table(detections_path, 4)
    detection_t_ns = np.round(detections[:, 0] * 1e6).astype(np.int64) * 1000

    return VictoriaRecording(
        odometry_t_ns=odometry_t_ns,
        speed_mps=odometry["speed"].astype(np.float64),
        steering_rad=odometry["steering"].astype(np.float64),
        detection_t_ns=_increasing(detection_t_ns, detections_path, strict=False),
        detection_range_m=detections[:, 1].copy(),
        detection_bearing_rad=detections[:, 2] - np.pi / 2,
        detection_diameter_m=detections[:, 3].copy(),
        gps_t_ns=gps_t_ns,
        gps_xy=np.column_stack([gps["Lo_m"], gps["La_m"]]).astype(np.float64),
    )


def gps_outliers(
    gps_t_ns: NDArray[np.int64], gps_xy: NDArray[np.float64], max_speed_mps: float = 20.0
) -> NDArray[np.bool_]:
    """Flags (G,) of the isolated GPS fixes that are physically impossible.

    The implied speed between consecutive fixes is their distance over their time step. An inner fix is
    flagged when the implied speeds from **both** its previous and its next fix exceed ``max_speed_mps``
    (20 m/s by default, far above a car's speed in a park). A jump followed by a track consistent with
    the fix after it, as when the GPS comes back after a gap, is therefore not flagged. Two adjacent bad
    fixes are not flagged either, because each agrees with the other. An end fix has one neighbour. It
    is flagged when the speed to that neighbour is too high while the neighbour agrees with its own
    other neighbour, so that the jump belongs to the end fix. With fewer than three fixes nothing is
    flagged.

    ``gps_t_ns`` (G,) are increasing times (ns) and ``gps_xy`` (G, 2) positions (m).
    """
    t_ns = np.asarray(gps_t_ns)
    xy = np.asarray(gps_xy, dtype=np.float64)
    if t_ns.ndim != 1 or not np.issubdtype(t_ns.dtype, np.integer):
        raise ValueError(f"gps_t_ns must be a 1-D integer array, got {t_ns.dtype} of shape {t_ns.shape}")
    if xy.shape != (t_ns.size, 2):
        raise ValueError(f"gps_xy must have shape ({t_ns.size}, 2), got {xy.shape}")
    if np.any(np.diff(t_ns) <= 0):
        raise ValueError("gps_t_ns must be increasing")
    if not max_speed_mps > 0:
        raise ValueError(f"max_speed_mps must be positive, got {max_speed_mps}")
    flags = np.zeros(t_ns.size, dtype=bool)
    if t_ns.size < 3:
        return flags
    speed_mps = np.hypot(*np.diff(xy, axis=0).T) / (np.diff(t_ns) * 1e-9)
    too_fast = speed_mps > max_speed_mps
    flags[1:-1] = too_fast[:-1] & too_fast[1:]
    flags[0] = too_fast[0] and not too_fast[1]
    flags[-1] = too_fast[-1] and not too_fast[-2]
    return flags


def _read_mat(path: Path, names: tuple[str, ...]) -> dict[str, NDArray[np.generic]]:
    """The variables ``names`` of a MAT-file, each raveled from (N, 1) to (N,); the first holds integer ms."""
    try:
        contents = scipy.io.loadmat(existing_file(path))
    except (ValueError, TypeError, scipy.io.matlab.MatReadError) as error:
        raise ValueError(f"{path}: not a readable MAT-file ({error})") from error
    missing = [name for name in names if name not in contents]
    if missing:
        raise ValueError(f"{path}: variable(s) {missing} missing")
    variables = {}
    for name in names:
        value = np.asarray(contents[name])
        if value.ndim != 2 or value.shape[1] != 1 or value.shape[0] == 0:
            raise ValueError(f"{path}: {name} must have shape (N, 1) with N >= 1, got {value.shape}")
        variables[name] = value.ravel()
    if len({value.size for value in variables.values()}) != 1:
        raise ValueError(f"{path}: {', '.join(names)} have unequal lengths")
    if not np.issubdtype(variables[names[0]].dtype, np.integer):
        raise ValueError(
            f"{path}: {names[0]} must hold integer milliseconds, got {variables[names[0]].dtype}"
        )
    variables[names[0]] = variables[names[0]].astype(np.int64)
    return variables


def _increasing(t_ns: NDArray[np.int64], path: Path, *, strict: bool) -> NDArray[np.int64]:
    """``t_ns`` itself, or a ValueError naming the file when it is not increasing (``strict``) or sorted."""
    steps = np.diff(t_ns)
    if np.any(steps <= 0) if strict else np.any(steps < 0):
        raise ValueError(f"{path}: times must be {'increasing' if strict else 'non-decreasing'}")
    return t_ns
