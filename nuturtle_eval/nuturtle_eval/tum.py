"""Trajectories in the TUM RGB-D benchmark's text format, which evo and most SLAM evaluators read: no ROS.

One pose a line, ``timestamp tx ty tz qx qy qz qw``: the stamp in seconds, the position (m) and the
orientation as a unit quaternion with its scalar part last. A planar pose ``(x, y, theta)`` is the
position ``(x, y, 0)`` and the rotation by ``theta`` about z, ``q = (0, 0, sin(theta / 2), cos(theta / 2))``.
Lines starting with ``#`` are comments.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from .metrics import PoseSeries

HEADER = "# timestamp tx ty tz qx qy qz qw\n"


def tum_lines(series: PoseSeries) -> str:
    """The poses of ``series`` as TUM lines (module docstring): stamps to the nanosecond, positions to the
    tenth of a micrometre, quaternions to 1e-9."""
    half = 0.5 * series.poses[:, 2]
    rows = [
        f"{t:.9f} {x:.7f} {y:.7f} 0 0 0 {qz:.9f} {qw:.9f}\n"
        for t, x, y, qz, qw in zip(
            series.t_s, series.poses[:, 0], series.poses[:, 1], np.sin(half), np.cos(half), strict=True
        )
    ]
    return HEADER + "".join(rows)


def write_tum(path: Path, series: PoseSeries) -> Path:
    """``path``: ``series`` in the TUM format (:func:`tum_lines`); its path."""
    path = Path(path)
    path.write_text(tum_lines(series), encoding="utf-8")
    return path


def read_tum(path: Path) -> PoseSeries:
    """The planar poses of a TUM file (module docstring): ``theta = 2 atan2(qz, qw)`` of each line's
    quaternion (its rotation about z; ``qx``, ``qy`` and ``z`` are not read). ValueError for a file that
    is not 8 numbers a line, or whose stamps do not increase."""
    path = Path(path)
    try:
        table = np.loadtxt(path, comments="#", ndmin=2)
    except ValueError as error:
        raise ValueError(f"{path}: not a TUM trajectory: {error}") from None
    if table.shape[1:] != (8,):
        raise ValueError(f"{path}: a TUM line has 8 numbers, these have {table.shape[1]}")
    t_s, x, y, _, _, _, qz, qw = table.T
    return PoseSeries(t_s, np.column_stack([x, y, 2.0 * np.arctan2(qz, qw)]))
