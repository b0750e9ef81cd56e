"""The launch arguments the suite's launch files declare (imported by launch files only: launch is not
installable where the tests run).

- :func:`model_argument`: ``model:=burger|waffle|waffle_pi``; default: the TURTLEBOT3_MODEL environment
  variable, as in ROBOTIS' launch files, else burger. launch refuses another value, naming the choices.
- :func:`declare_argument`: an argument from its record
  (:class:`nuturtle_ros_common.launch_parameters.LaunchArgument`, written once beside the functions that
  use its value).
- :func:`switch_argument`: a ``true|false`` argument.
- :func:`launched_frames`: the robot's frame ids for the ``namespace`` and ``map_frame`` arguments
  (``NAMESPACE``, ``MAP_FRAME`` of ``nuturtle_ros_common.launch_parameters``), and :func:`in_namespace`: a
  file's nodes under the namespace (``PushRosNamespace``): every node a file starts lives under
  ``/<namespace>`` and writes the prefixed frames it is given.
"""

from __future__ import annotations

from launch import Action, LaunchContext
from launch.actions import DeclareLaunchArgument, GroupAction
from launch.substitutions import EnvironmentVariable, LaunchConfiguration
from launch_ros.actions import PushRosNamespace

from nuturtle_ros_common.launch_parameters import LaunchArgument, RobotFrames, robot_frames

from .robot_params import DEFAULT_MODEL, MODEL_ENV, model_names


def model_argument() -> DeclareLaunchArgument:
    return DeclareLaunchArgument(
        "model",
        default_value=EnvironmentVariable(MODEL_ENV, default_value=DEFAULT_MODEL),
        choices=list(model_names()),
        description=f"TurtleBot3 model: its constants are the nodes' defaults (default ${MODEL_ENV}, "
        f"else {DEFAULT_MODEL})",
    )


def declare_argument(name: str, argument: LaunchArgument) -> DeclareLaunchArgument:
    """``name`` with the default, choices (if any) and description of ``argument``."""
    choices = {} if argument.choices is None else {"choices": list(argument.choices)}
    return DeclareLaunchArgument(
        name, default_value=argument.default, description=argument.description, **choices
    )


def switch_argument(name: str, default: bool, description: str) -> DeclareLaunchArgument:
    """``name:=true|false``, ``default`` when not given."""
    return declare_argument(name, LaunchArgument(str(default).lower(), ("true", "false"), description))


def launched_frames(context: LaunchContext) -> RobotFrames:
    """The robot's frames for the ``namespace`` and ``map_frame`` arguments (empty when not declared)."""
    namespace = LaunchConfiguration("namespace", default="").perform(context)
    return robot_frames(namespace, LaunchConfiguration("map_frame", default="").perform(context))


def in_namespace(frames: RobotFrames, actions: list[Action]) -> list[Action]:
    """``actions`` under ``frames.namespace`` (one scoped group pushing it), or as they are without one."""
    if not frames.namespace:
        return actions
    return [GroupAction([PushRosNamespace(frames.namespace), *actions])]
