"""A node's robot: the ``model`` ROS parameter, declared first, decides the defaults of the robot's constants.

    model  (string, read-only)  burger | waffle | waffle_pi; default: the TURTLEBOT3_MODEL environment
                                variable, else burger
    then every `RobotParams` field (wheel_radius, track_width, ..., lidar_yaw), defaulting to that model's
    value in config/models.yaml

So ``-p model:=waffle`` (or ``TURTLEBOT3_MODEL=waffle``) gives a node the Waffle's 0.287 m track, and an
explicitly set ``track_width`` still beats the model's. One parameter to say which robot it is, instead of
a file of constants that would outrank the node's own parameters (rcl merges parameter files by node name
in the order each name first appears, docs/robot.md).
"""

from __future__ import annotations

from dataclasses import dataclass

from rclpy.node import Node

from nuturtle_ros_common.ros_params import declare_dataclass
from turtlelib.util.validation import one_of

from .robot_params import DEFAULT_MODEL, MODEL_ENV, RobotParams, environment_model, model_names, model_params


@dataclass(frozen=True)
class RobotModel:
    """Which TurtleBot3 a node runs: ``model`` (burger, waffle or waffle_pi; default: the
    TURTLEBOT3_MODEL environment variable, else burger) sets the defaults of the robot's constants.
    ValueError, naming the models, for another name."""

    model: str = DEFAULT_MODEL

    def __post_init__(self) -> None:
        one_of("model", self.model, model_names())


def declare_robot(node: Node) -> RobotParams:
    """Declare ``model`` (default :func:`environment_model`), then the `RobotParams` fields with that model's
    constants as defaults; return the constants. ValueError (the node stops at start-up) for an unknown model
    or an invalid constant."""
    try:
        model = declare_dataclass(node, RobotModel, overrides={"model": environment_model()}).model
    except ValueError as error:
        raise ValueError(f"{error} (the model parameter, else ${MODEL_ENV}, else {DEFAULT_MODEL})") from None
    return declare_dataclass(node, RobotParams, overrides=vars(model_params(model)))
