"""The `parameters` lists launch files give their nodes, and the record of a launch argument.

A `parameters` list holds YAML parameter files and dicts; launch_ros passes each file as
`--params-file` and writes each dict as a temporary `/**:` parameter file, in the list's order. rcl merges
them by node-name key in the order in which each key first appears, so a `/**` entry placed before a node's
own YAML file loses to it (`association:=known` then ran unknown association), and one placed after it
wins. :func:`with_arguments` therefore puts the launch arguments last. The tests check this by parsing the
exact command line with rcl itself (`tests/packaging/test_launch_parameters.py`).

:func:`ros_arguments` is that command line, for starting a node the way launch does without launch (the
tests and bench/robot_nodes.py). No rclpy or launch here: the launch files import this.

:func:`robot_frames` is a namespaced robot's frame ids (TurtleBot3's convention for several robots: the
prefix ``<namespace>/`` on every frame, robot_state_publisher's ``frame_prefix``), which the launch files
pass to the nodes' frame-id parameters.
"""

from __future__ import annotations

import re
from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any


@dataclass(frozen=True)
class LaunchArgument:
    """A launch argument's ``default``, its ``choices`` (None: any value) and its ``description``
    (``ros2 launch --show-args`` shows it: ValueError when empty, or when the default is not a choice)."""

    default: str
    choices: tuple[str, ...] | None
    description: str

    def __post_init__(self) -> None:
        if not self.description.strip():
            raise ValueError("a launch argument needs a description")
        if self.choices is not None and self.default not in self.choices:
            raise ValueError(f"default {self.default!r} is not one of {self.choices}")


def with_arguments(files: Sequence[Path | str], arguments: Mapping[str, Any]) -> list[str | dict[str, Any]]:
    """``[*files, arguments]``: the node's parameter files in order, then the launch arguments (a `/**`
    entry after the node's own keys), which win."""
    return [*(str(path) for path in files), dict(arguments)]


def ros_arguments(parameters: Sequence[Path | str | Mapping[str, Any]], folder: Path) -> list[str]:
    """``--ros-args --params-file ...`` as launch_ros builds it from a Node's ``parameters`` list: each YAML
    file as it is, each dict written (into ``folder``, created if needed) as a ``/**`` parameter file, in
    the list's order."""
    import yaml

    arguments = ["--ros-args"]
    for k, entry in enumerate(parameters):
        if isinstance(entry, Mapping):
            folder.mkdir(parents=True, exist_ok=True)
            path = folder / f"launch_params_{k}.yaml"
            path.write_text(yaml.safe_dump({"/**": {"ros__parameters": dict(entry)}}))
            entry = path
        arguments += ["--params-file", str(entry)]
    return arguments


# the robot's namespace and its map frame (every launch file that starts a robot's nodes)
NAMESPACE = LaunchArgument(
    "",
    None,
    "the robot's namespace (e.g. tb3_0): its nodes and topics under /tb3_0, its frames tb3_0/odom, ...",
)
MAP_FRAME = LaunchArgument(
    "",
    None,
    "slam's map frame; empty: the robot's own (<namespace>/map, map without a namespace); map: shared",
)
# a ROS name token (rcl's rule): a letter or underscore, then letters, digits, underscores
_TOKEN = re.compile(r"[A-Za-z_][A-Za-z0-9_]*")


@dataclass(frozen=True)
class RobotFrames:
    """The frame ids of the robot in ``namespace`` (``""``: none): ``prefix + "odom"``, ... with
    ``prefix = namespace + "/"``; slam's map frame is ``map_frame`` when chosen, else ``prefix + "map"``.
    Build it with :func:`robot_frames`, which checks both."""

    namespace: str
    map_frame: str = ""

    @property
    def prefix(self) -> str:
        """robot_state_publisher's ``frame_prefix``: ``"tb3_0/"``, or ``""`` without a namespace."""
        return f"{self.namespace}/" if self.namespace else ""

    @property
    def map_id(self) -> str:
        return self.map_frame or self.prefix + "map"

    @property
    def odom_id(self) -> str:
        return self.prefix + "odom"

    @property
    def body_id(self) -> str:
        return self.prefix + "base_footprint"

    @property
    def sensor_id(self) -> str:
        return self.prefix + "base_scan"

    def odometry(self) -> dict[str, str]:
        """The odometry node's frame parameters, ``odom_id`` and ``body_id``, when namespaced; none
        without a namespace (its config file's: a run without a namespace is today's)."""
        return {"odom_id": self.odom_id, "body_id": self.body_id} if self.namespace else {}

    def slam(self) -> dict[str, str]:
        """slam's: :meth:`odometry`'s and ``sensor_id`` when namespaced, ``map_id`` when namespaced or
        chosen."""
        own = {**self.odometry(), "sensor_id": self.sensor_id} if self.namespace else {}
        return {**own, "map_id": self.map_id} if self.namespace or self.map_frame else own


def robot_frames(namespace: str, map_frame: str = "") -> RobotFrames:
    """The frames of the robot in ``namespace`` (``tb3_0``, ``/tb3_0`` or ``fleet/tb3_0``; slashes at
    either end dropped); ``map_frame`` empty: its own ``<namespace>/map``, else that frame (``map``: one
    map frame shared by several robots). ValueError for a namespace that is not a ROS name or a map frame
    with spaces around it or a leading slash."""
    cleaned = namespace.strip("/")
    if cleaned and not all(_TOKEN.fullmatch(token) for token in cleaned.split("/")):
        raise ValueError(
            f"namespace {namespace!r}: each part must start with a letter or underscore, then letters, "
            "digits or underscores (e.g. tb3_0)"
        )
    if map_frame.strip() != map_frame or map_frame.startswith("/"):
        raise ValueError(f"map frame {map_frame!r}: no surrounding spaces and no leading slash (e.g. map)")
    return RobotFrames(cleaned, map_frame)
