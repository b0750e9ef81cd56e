"""The TurtleBot3 models' constants, loaded from `config/models.yaml`: the one place they are written.

A model (``burger``, ``waffle``, ``waffle_pi``: the names ROBOTIS' ``TURTLEBOT3_MODEL`` environment variable
takes) is chosen explicitly (the nodes' ``model`` parameter, the ``model`` launch argument, ``--model`` of the
demo and the replay), else by ``TURTLEBOT3_MODEL``, else it is the Burger (:func:`resolve_model`).

`RobotParams` is the one place these keys are named; nodes declare them as ROS parameters after ``model``,
with that model's values as their defaults (`nuturtle_description.robot_declaration`), so an explicitly set
parameter still beats the model. The URDF (`urdf.py`), the simulator's LiDAR and the SLAM filter's sensor
mount all read the LiDAR mount from here. No rclpy here: launch files and command lines read it too.
"""

from __future__ import annotations

import argparse
import math
import os
from collections.abc import Mapping
from dataclasses import dataclass, fields
from functools import partial
from pathlib import Path

import yaml

from nuturtle_ros_common.ros_files import share_file
from turtlelib import DiffDrive, Transform2D
from turtlelib.util.validation import finite_real, integer, non_negative, one_of, positive, store

PACKAGE = "nuturtle_description"
# The environment variable ROBOTIS' launch files read the model from, and the model when it is unset
MODEL_ENV = "TURTLEBOT3_MODEL"
DEFAULT_MODEL = "burger"


@dataclass(frozen=True)
class RobotParams:
    """Differential-drive constants (SI units; motor commands in Dynamixel units, mcu) and the LiDAR mount.
    The defaults are the Burger's (``models.yaml`` holds every model's).

    ``wheel_radius``, ``track_width``, ``collision_radius`` (m), ``motor_cmd_per_rad_sec`` (mcu per
    rad/s), ``encoder_ticks_per_rad``: finite and > 0; ``motor_cmd_max`` (mcu): an integer >= 1.
    ``max_linear_speed`` (m/s), ``max_angular_speed`` (rad/s): the fastest the robot is driven (the stock
    teleop's bounds), finite and > 0.
    ``lidar_x``, ``lidar_y`` (m), ``lidar_yaw`` (rad): the pose ``T_body_scan`` of ``base_scan`` in
    ``base_footprint`` (finite); ``lidar_z`` (m, >= 0): its height above the floor (drawn only).
    """

    wheel_radius: float = 0.033
    track_width: float = 0.16
    max_linear_speed: float = 0.22
    max_angular_speed: float = 2.84
    motor_cmd_max: int = 265
    motor_cmd_per_rad_sec: float = 1.0 / 0.024
    encoder_ticks_per_rad: float = 4096.0 / (2.0 * math.pi)
    collision_radius: float = 0.11
    lidar_x: float = -0.032
    lidar_y: float = 0.0
    lidar_z: float = 0.182
    lidar_yaw: float = 0.0

    def __post_init__(self) -> None:
        positives = ("wheel_radius", "track_width", "max_linear_speed", "max_angular_speed")
        store(
            self, (*positives, "motor_cmd_per_rad_sec", "encoder_ticks_per_rad", "collision_radius"), positive
        )
        store(self, ("motor_cmd_max",), partial(integer, minimum=1))
        store(self, ("lidar_x", "lidar_y", "lidar_yaw"), finite_real)
        store(self, ("lidar_z",), non_negative)

    @property
    def max_wheel_speed(self) -> float:
        """Largest wheel speed the motors accept (rad/s): motor_cmd_max / motor_cmd_per_rad_sec."""
        return self.motor_cmd_max / self.motor_cmd_per_rad_sec

    @property
    def wheel_speed_bound(self) -> float:
        """The fastest a wheel turns (rad/s): ``max(max_wheel_speed, (max_linear_speed + max_angular_speed
        track_width / 2) / wheel_radius)``. The motors' limit on the robot; a simulated robot (Gazebo's
        diff-drive has no motor limit) driven at both teleop bounds at once turns its outer wheel faster."""
        teleop = (self.max_linear_speed + 0.5 * self.max_angular_speed * self.track_width) / self.wheel_radius
        return max(self.max_wheel_speed, teleop)

    @property
    def T_body_scan(self) -> Transform2D:
        """The planar pose of the LiDAR frame ``base_scan`` in ``base_footprint``."""
        return Transform2D(self.lidar_x, self.lidar_y, self.lidar_yaw)

    def diff_drive(self) -> DiffDrive:
        return DiffDrive(self.wheel_radius, self.track_width)


def models_path() -> Path:
    return share_file(PACKAGE, "config", "models.yaml")


def _models() -> dict[str, dict]:
    with open(models_path(), encoding="utf-8") as stream:
        return yaml.safe_load(stream)


def model_names() -> tuple[str, ...]:
    """The models of ``models.yaml``, in its order: ``('burger', 'waffle', 'waffle_pi')``."""
    return tuple(_models())


def model_params(model: str) -> RobotParams:
    """The constants of ``model``; ValueError naming the models for another name, or when models.yaml does
    not give the model every `RobotParams` field (none may fall back to the Burger's default)."""
    models = _models()
    one_of("model", model, tuple(models))
    values = models[model]
    names = {field.name for field in fields(RobotParams)}
    if set(values) != names:
        raise ValueError(
            f"{models_path()}: {model} must give exactly {sorted(names)}; missing "
            f"{sorted(names - set(values))}, unknown {sorted(set(values) - names)}"
        )
    return RobotParams(**values)


def burger_params() -> RobotParams:
    """The Burger's constants (``model_params('burger')``)."""
    return model_params("burger")


def environment_model(environ: Mapping[str, str] = os.environ) -> str:
    """The model named by ``TURTLEBOT3_MODEL`` in ``environ`` (unset or empty: the Burger), unchecked."""
    return environ.get(MODEL_ENV) or DEFAULT_MODEL


def resolve_model(model: str | None, environ: Mapping[str, str] = os.environ) -> str:
    """``model`` when given, else :func:`environment_model`; ValueError naming the models (and, for the
    environment's, the variable) when it is not one of them."""
    name = model if model is not None else environment_model(environ)
    choices = model_names()
    if name not in choices:
        source = "model" if model is not None else f"{MODEL_ENV} (the environment variable)"
        raise ValueError(f"{source} must be one of {choices}, got {name!r}")
    return name


def add_model_argument(parser: argparse.ArgumentParser) -> None:
    """``--model {burger,waffle,waffle_pi}`` of a command line (None when absent: :func:`resolve_model`)."""
    parser.add_argument("--model", choices=model_names(), default=None,
                        help=f"the TurtleBot3 model, whose constants every node takes "
                        f"(default: ${MODEL_ENV}, else {DEFAULT_MODEL})")  # fmt: skip
