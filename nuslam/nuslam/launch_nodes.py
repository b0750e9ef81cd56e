"""The parameter lists of nuslam's launch files, and RViz2's arguments (plain functions: tests call them,
launch cannot run in CI).

Every list is the node's own defaults (config/<node>.yaml), then the launch arguments, which win
(`launch_parameters.with_arguments`); slam's robot constants are the defaults of its ``model`` argument.
Under a namespace RViz gets a copy of slam.rviz that shows that robot (:func:`namespaced_rviz_config`).
"""

from __future__ import annotations

import tempfile
from pathlib import Path
from typing import Any

import yaml

from nuslam.slam_node import MOTION_SOURCES
from nuturtle_ros_common.launch_parameters import LaunchArgument, RobotFrames, with_arguments
from nuturtle_ros_common.ros_files import share_file
from turtlelib import MODES

# slam's association (slam.launch.py, nusim_slam.launch.py)
ASSOCIATION = LaunchArgument(
    "unknown", ("unknown", "known"), "unknown: LiDAR landmarks (landmarks node); known: nusim's fake_sensor"
)
# slam's launch arguments besides association and use_sim_time
SLAM_ARGUMENTS: dict[str, LaunchArgument] = {
    "motion_source": LaunchArgument(
        "joint_states", MOTION_SOURCES, "slam's motion input: the wheel angles, or a base's odom"
    ),
    "mode": LaunchArgument("mapping", MODES, "mapping (SLAM), or localization in the map of map_file"),
    "map_file": LaunchArgument(
        "", None, "the map slam loads at start-up (if there; required by localization) and saves on save_map"
    ),
}

# managed:=true (slam.launch.py, turtlebot3.launch.py): the lifecycle variants of slam and landmarks
MANAGED_DESCRIPTION = (
    "true: slam_managed and landmarks_managed, lifecycle nodes that wait unconfigured for a lifecycle "
    "manager (docs/robot.md 'Managed nodes'); not with one_process"
)
# the one-process executables (robot_side, slam_side) run plain nodes only
MANAGED_ONE_PROCESS = (
    "managed:=true starts slam_managed and landmarks_managed, one process each; one_process:=true runs "
    "plain nodes only (they start working at once): choose one of the two"
)


def node_executable(node: str, managed: bool) -> str:
    """The executable of ``node`` (``slam`` or ``landmarks``): its managed variant (``slam_managed``,
    :mod:`nuslam.managed_nodes`) when ``managed``. ValueError for another node."""
    if node not in ("slam", "landmarks"):
        raise ValueError(f"only slam and landmarks have managed variants, not {node!r}")
    return f"{node}_managed" if managed else node


def slam_parameters(
    association: str, use_sim_time: bool, model: str, **arguments: Any
) -> list[str | dict[str, Any]]:
    """The `slam` node's list: ``association`` (known or unknown), ``use_sim_time``, the robot ``model``
    and any other parameter ``arguments`` given at launch."""
    files = [share_file("nuslam", "config", "slam.yaml")]
    values = {"association": association, "use_sim_time": use_sim_time, "model": model, **arguments}
    return with_arguments(files, values)


def slam_side_parameters(
    association: str, use_sim_time: bool, model: str, **arguments: Any
) -> list[str | dict[str, Any]]:
    """The `slam_side` process's list (turtlebot3.launch.py ``one_process:=true``): each node's own config
    file (its section is keyed by its node name, so it reaches that node only), then the launch arguments
    as one ``/**`` entry: each node takes those it declares (``association``, ``mode``, ... only slam), so
    every node gets what its own list gives it."""
    files = [share_file("nuslam", "config", "slam.yaml"), share_file("nuslam", "config", "landmarks.yaml")]
    values = {"association": association, "use_sim_time": use_sim_time, "model": model, **arguments}
    return with_arguments(files, values)


def robot_side_parameters(
    association: str, use_sim_time: bool, model: str, **arguments: Any
) -> list[str | dict[str, Any]]:
    """The `robot_side` process's list (slam.launch.py ``one_process:=true``): turtle_control's and
    odometry's config files, then :func:`slam_side_parameters`'s list."""
    files = [
        share_file("nuturtle_control", "config", "turtle_control.yaml"),
        share_file("nuturtle_control", "config", "odometry.yaml"),
    ]
    return [*map(str, files), *slam_side_parameters(association, use_sim_time, model, **arguments)]


def landmarks_parameters(use_sim_time: bool) -> list[str | dict[str, Any]]:
    """The `landmarks` node's list."""
    return with_arguments([share_file("nuslam", "config", "landmarks.yaml")], {"use_sim_time": use_sim_time})


# the keys of an RViz display's topics (each a mapping whose ``Value`` is the topic's name)
RVIZ_TOPIC_KEYS = ("Topic", "Update Topic", "Description Topic")


def namespaced_rviz_config(config: dict[str, Any], frames: RobotFrames) -> dict[str, Any]:
    """An RViz config (the parsed YAML of slam.rviz) showing the robot of ``frames``: every absolute
    topic ``/x`` of a display or tool as ``/<namespace>/x``, the fixed frame ``frames.map_id`` and the
    robot model's TF prefix ``<namespace>`` (robot_state_publisher's ``frame_prefix``); ``config`` is
    left as it is."""

    def rewritten(value: Any, key: str | None = None) -> Any:
        if isinstance(value, dict):
            if key in RVIZ_TOPIC_KEYS and str(value.get("Value", "")).startswith("/") and frames.namespace:
                return {**value, "Value": f"/{frames.namespace}{value['Value']}"}
            if value.get("Class") == "rviz_default_plugins/RobotModel":
                value = {**value, "TF Prefix": frames.namespace}
            return {k: rewritten(v, k) for k, v in value.items()}
        if isinstance(value, list):
            return [rewritten(item) for item in value]
        return frames.map_id if key == "Fixed Frame" else value

    return rewritten(config)


def rviz_arguments(frames: RobotFrames | None = None) -> list[str]:
    """rviz2's arguments for the SLAM view: ``-d`` and the installed ``share/nuslam/rviz/slam.rviz``;
    for a namespaced robot or a chosen map frame (``frames``), a copy of it rewritten by
    :func:`namespaced_rviz_config`, written to a new file in the temporary folder."""
    config = share_file("nuslam", "rviz", "slam.rviz")
    if frames is None or frames == RobotFrames(""):
        return ["-d", str(config)]
    text = yaml.safe_dump(namespaced_rviz_config(yaml.safe_load(config.read_text()), frames), sort_keys=False)
    name = frames.namespace.replace("/", "_") or "map"
    handle, path = tempfile.mkstemp(prefix=f"slam_{name}_", suffix=".rviz")
    with open(handle, "w", encoding="utf-8") as file:
        file.write(text)
    return ["-d", str(Path(path))]
