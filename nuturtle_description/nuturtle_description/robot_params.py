"""The TurtleBot3 Burger's constants, loaded from `config/diff_params.yaml`: the one place they are written.

`RobotParams` is the one place these keys are named; nodes declare them as ROS parameters with
`declare_dataclass` (see `nuturtle_ros_common.ros_params`), using the YAML file's values as defaults, so
`ros2 run <pkg> <node>` with no arguments runs with the Burger's constants. The URDF (`urdf.py`), the
simulator's LiDAR and the SLAM filter's sensor mount all read the LiDAR mount from here.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from functools import partial
from pathlib import Path

from nuturtle_ros_common.ros_files import load_ros_yaml, share_file
from turtlelib import DiffDrive, Transform2D
from turtlelib.validation import finite_real, integer, non_negative, positive, store

PACKAGE = "nuturtle_description"


@dataclass(frozen=True)
class RobotParams:
    """Differential-drive constants (SI units; motor commands in Dynamixel units, mcu) and the LiDAR mount.

    ``wheel_radius``, ``track_width``, ``collision_radius`` (m), ``motor_cmd_per_rad_sec`` (mcu per
    rad/s), ``encoder_ticks_per_rad``: finite and > 0; ``motor_cmd_max`` (mcu): an integer >= 1.
    ``lidar_x``, ``lidar_y`` (m), ``lidar_yaw`` (rad): the pose ``T_body_scan`` of ``base_scan`` in
    ``base_footprint`` (finite); ``lidar_z`` (m, >= 0): its height above the floor (drawn only).
    """

    wheel_radius: float = 0.033
    track_width: float = 0.16
    motor_cmd_max: int = 265
    motor_cmd_per_rad_sec: float = 1.0 / 0.024
    encoder_ticks_per_rad: float = 4096.0 / (2.0 * math.pi)
    collision_radius: float = 0.11
    lidar_x: float = -0.032
    lidar_y: float = 0.0
    lidar_z: float = 0.182
    lidar_yaw: float = 0.0

    def __post_init__(self) -> None:
        positives = ("wheel_radius", "track_width", "motor_cmd_per_rad_sec", "encoder_ticks_per_rad")
        store(self, (*positives, "collision_radius"), positive)
        store(self, ("motor_cmd_max",), partial(integer, minimum=1))
        store(self, ("lidar_x", "lidar_y", "lidar_yaw"), finite_real)
        store(self, ("lidar_z",), non_negative)

    @property
    def max_wheel_speed(self) -> float:
        """Largest wheel speed the motors accept (rad/s): motor_cmd_max / motor_cmd_per_rad_sec."""
        return self.motor_cmd_max / self.motor_cmd_per_rad_sec

    @property
    def T_body_scan(self) -> Transform2D:
        """The planar pose of the LiDAR frame ``base_scan`` in ``base_footprint``."""
        return Transform2D(self.lidar_x, self.lidar_y, self.lidar_yaw)

    def diff_drive(self) -> DiffDrive:
        return DiffDrive(self.wheel_radius, self.track_width)


def diff_params_path() -> Path:
    return share_file(PACKAGE, "config", "diff_params.yaml")


def burger_params() -> RobotParams:
    """The Burger's constants as shipped in config/diff_params.yaml."""
    return RobotParams(**load_ros_yaml(diff_params_path()))
