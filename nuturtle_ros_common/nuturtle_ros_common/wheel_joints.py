"""The two wheel joints of a differential drive, as named in sensor_msgs/JointState.

`WheelJoints` holds the joint names (ROS parameters `wheel_left`, `wheel_right`; the Burger's URDF names
are the defaults) and `wheel_values` picks the left and right entries out of a JointState's parallel
arrays, refusing anything a node should not integrate.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass

from turtlelib.util.validation import names


@dataclass(frozen=True)
class WheelJoints:
    """Joint names of the wheels, ``wheel_left`` and ``wheel_right``: non-empty and distinct (ValueError
    otherwise)."""

    wheel_left: str = "wheel_left_joint"
    wheel_right: str = "wheel_right_joint"

    def __post_init__(self) -> None:
        names("joint name", wheel_left=self.wheel_left, wheel_right=self.wheel_right)

    @property
    def names(self) -> list[str]:
        """``[wheel_left, wheel_right]``, the order of every wheel pair in this package."""
        return [self.wheel_left, self.wheel_right]


def wheel_values(joints: WheelJoints, names: Sequence[str], values: Sequence[float]) -> tuple[float, float]:
    """``(left, right)``: the entries of ``values`` at the wheel joints' positions in ``names``.

    ``names`` and ``values`` are a JointState's parallel arrays (e.g. ``name`` and ``position``); other
    joints are ignored. ValueError when the arrays differ in length, a wheel joint is missing or listed
    twice, or a wheel value is not finite.
    """
    if len(values) != len(names):
        raise ValueError(f"{len(names)} joint names but {len(values)} values")
    names = list(names)
    wheel = []
    for joint in joints.names:
        count = names.count(joint)
        if count != 1:
            raise ValueError(
                f"joint {joint!r} is {'missing' if count == 0 else 'listed more than once'} (joints: {names})"
            )
        value = float(values[names.index(joint)])
        if not math.isfinite(value):
            raise ValueError(f"joint {joint!r} has non-finite value {value!r}")
        wheel.append(value)
    return wheel[0], wheel[1]
