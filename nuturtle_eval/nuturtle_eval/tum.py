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
