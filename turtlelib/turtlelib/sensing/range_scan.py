"""A 2D LiDAR scan as ``sensor_msgs/LaserScan`` carries it, validated once: the input of the landmark
detector (:mod:`turtlelib.sensing.detection`) and of the occupancy grid
(:mod:`turtlelib.mapping.occupancy_grid`).

Beam ``b`` leaves the sensor at ``phi_b = angle_min + b angle_increment`` (rad, sensor frame) and reads
``rho_b`` (m); a return is a finite ``rho_b > 0`` inside ``[range_min, range_max]`` (0.0, NaN and inf are
what LiDARs write for no return).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

from ..util.validation import finite_real, non_negative, store

# Slack of check_scan_layout (rad): LaserScan's angles are float32, ~1e-7 relative, over ~1000 beams
LAYOUT_SLACK_RAD = 1e-4


@dataclass(frozen=True)
class RangeScan:
    """One 2D LiDAR scan as ``sensor_msgs/LaserScan`` gives it: ``ranges`` (m), beam ``b`` at
    ``angle_min + b angle_increment`` (rad, sensor frame), valid returns in ``[range_min, range_max]``.

    ``ranges`` is stored as a read-only float64 copy (any value allowed: invalid ones mean no return);
    ValueError for an empty or non 1-D ``ranges``, non-finite angles, a zero increment or limits that are
    not ``0 <= range_min < range_max`` finite.
    """

    ranges: NDArray[np.float64]
    angle_min: float
    angle_increment: float
    range_min: float
    range_max: float

    def __post_init__(self) -> None:
        ranges = np.array(self.ranges, dtype=np.float64)
        if ranges.ndim != 1 or ranges.shape[0] == 0:
            raise ValueError(f"ranges must be a non-empty 1-D array, got shape {ranges.shape}")
        ranges.flags.writeable = False
        object.__setattr__(self, "ranges", ranges)
        store(self, ("angle_min", "angle_increment", "range_max"), finite_real)
        store(self, ("range_min",), non_negative)
        if self.angle_increment == 0.0:
            raise ValueError("angle_increment must be non-zero")
        if not self.range_min < self.range_max:
            raise ValueError(f"need range_min < range_max, got {self.range_min}, {self.range_max}")

    def returns(self) -> NDArray[np.bool_]:
        """Beams with a return: finite, > 0 and in ``[range_min, range_max]`` (NaN fails every test)."""
        rho = self.ranges
        return (rho > 0.0) & (rho >= self.range_min) & (rho <= self.range_max)


def check_scan_layout(samples: int, angle_min: float, angle_max: float, angle_increment: float) -> None:
    """ValueError unless a scan's layout agrees with itself (sensor_msgs/LaserScan's fields).

    Beam ``b`` is at ``angle_min + b angle_increment`` (rad); the last, ``angle_min + (samples - 1)
    angle_increment``, must be ``angle_max`` to within one increment (drivers differ: the LDS-01's gives
    ``angle_max = 2 pi`` for 360 beams of 1 degree, one increment past its last beam; the LDS-02's last
    beam lies up to one increment before ``angle_max``) plus ``LAYOUT_SLACK_RAD`` for float32 rounding;
    the angles finite, the increment non-zero and both ends within one turn of zero. A scan that disagrees
    (a negated or doubled increment, twice the ranges) would put every beam in the wrong direction.
    Beams beyond one full turn (Gazebo's last beam repeats its first) do not make a layout wrong: the
    detector drops them (:func:`beams_in_one_turn`).
    """
    values = (angle_min, angle_max, angle_increment)
    if not all(math.isfinite(v) for v in values) or angle_increment == 0.0:
        raise ValueError(f"need finite angle_min, angle_max and angle_increment != 0, got {values}")
    if samples < 1:
        raise ValueError("a scan needs a non-empty ranges array")
    if max(abs(angle_min), abs(angle_max)) > 2.0 * math.pi + LAYOUT_SLACK_RAD:
        raise ValueError(f"angle_min {angle_min} or angle_max {angle_max} is more than a turn from 0")
    last = angle_min + (samples - 1) * angle_increment
    if abs(last - angle_max) > abs(angle_increment) + LAYOUT_SLACK_RAD:
        raise ValueError(
            f"{samples} ranges from angle_min {angle_min} by {angle_increment} rad end at {last:.6g} rad, "
            f"but angle_max is {angle_max}: the layout contradicts itself"
        )
