"""The ``model`` launch argument every launch file of the suite declares (imported by launch files only).

``model:=burger|waffle|waffle_pi``; default: the TURTLEBOT3_MODEL environment variable, as in ROBOTIS'
launch files, else burger. launch refuses another value, naming the choices.
"""

from __future__ import annotations

from launch.actions import DeclareLaunchArgument
from launch.substitutions import EnvironmentVariable

from .robot_params import DEFAULT_MODEL, MODEL_ENV, model_names


def model_argument() -> DeclareLaunchArgument:
    return DeclareLaunchArgument(
        "model",
        default_value=EnvironmentVariable(MODEL_ENV, default_value=DEFAULT_MODEL),
        choices=list(model_names()),
        description=f"TurtleBot3 model: its constants are the nodes' defaults (default ${MODEL_ENV}, "
        f"else {DEFAULT_MODEL})",
    )
