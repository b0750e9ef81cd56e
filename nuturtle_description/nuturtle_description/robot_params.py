"""The TurtleBot3 Burger's constants, loaded from `config/diff_params.yaml`.

`RobotParams` is the one place these keys are named; nodes declare them as ROS parameters with
`declare_dataclass` (see `ros_params`), using the YAML file's values as defaults, so
`ros2 run <pkg> <node>` with no arguments runs with the Burger's constants.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from numbers import Real
from pathlib import Path

import yaml
from turtlelib import DiffDrive

PACKAGE = "nuturtle_description"


@dataclass(frozen=True)
class RobotParams:
    """Differential-drive constants (SI units; motor commands in Dynamixel units, mcu)."""

    wheel_radius: float = 0.033
    track_width: float = 0.16
    motor_cmd_max: int = 265
    motor_cmd_per_rad_sec: float = 1.0 / 0.024
    encoder_ticks_per_rad: float = 4096.0 / (2.0 * math.pi)
    collision_radius: float = 0.11

    def __post_init__(self) -> None:
        for name in (
            "wheel_radius",
            "track_width",
            "motor_cmd_max",
            "motor_cmd_per_rad_sec",
            "encoder_ticks_per_rad",
            "collision_radius",
        ):
            value = getattr(self, name)
            is_number = isinstance(value, Real) and not isinstance(value, bool)
            if not (is_number and math.isfinite(value) and value > 0):
                raise ValueError(f"{name} must be finite and > 0, got {value!r}")

    @property
    def max_wheel_speed(self) -> float:
        """Largest wheel speed the motors accept (rad/s): motor_cmd_max / motor_cmd_per_rad_sec."""
        return self.motor_cmd_max / self.motor_cmd_per_rad_sec

    def diff_drive(self) -> DiffDrive:
        return DiffDrive(self.wheel_radius, self.track_width)


def share_file(*parts: str) -> Path:
    """A file of this package's share folder: from the ament index (colcon install) or the source tree."""
    try:
        from ament_index_python.packages import (
            PackageNotFoundError,
            get_package_share_directory,
        )

        try:
            candidate = Path(get_package_share_directory(PACKAGE)).joinpath(*parts)
            if candidate.exists():
                return candidate
        except (PackageNotFoundError, OSError):
            pass  # not installed, or no ament index at all (AMENT_PREFIX_PATH unset: OSError)
    except ImportError:
        pass
    return Path(__file__).resolve().parents[1].joinpath(*parts)


def diff_params_path() -> Path:
    return share_file("config", "diff_params.yaml")


def load_ros_yaml(path: Path) -> dict:
    """The `ros__parameters` of a ROS parameter file (wildcard `/**` or the first node entry)."""
    with open(path, encoding="utf-8") as stream:
        document = yaml.safe_load(stream) or {}
    for entry in document.values():
        if isinstance(entry, dict) and "ros__parameters" in entry:
            return dict(entry["ros__parameters"])
    raise ValueError(f"{path} holds no ros__parameters")


def burger_params() -> RobotParams:
    """The Burger's constants as shipped in config/diff_params.yaml."""
    return RobotParams(**load_ros_yaml(diff_params_path()))
