"""The `parameters` lists launch files give their nodes, and the record of a launch argument.

A `parameters` list holds YAML parameter files and dicts; launch_ros passes each file as
`--params-file` and writes each dict as a temporary `/**:` parameter file, in the list's order. rcl merges
them by node-name key in the order in which each key first appears, so a `/**` entry placed before a node's
own YAML file loses to it (`association:=known` then ran unknown association), and one placed after it
wins. :func:`with_arguments` therefore puts the launch arguments last. The tests check this by parsing the
exact command line with rcl itself (`tests/packaging/test_launch_parameters.py`).

:func:`ros_arguments` is that command line, for starting a node the way launch does without launch (the
tests and bench/robot_nodes.py). No rclpy or launch here: the launch files import this.
"""

from __future__ import annotations

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
