"""The `parameters` lists launch files give their nodes, and how a node resolves such a list.

A `parameters` list holds YAML parameter files and dicts, and rcl applies them in order, so a later entry
wins over an earlier one. launch_ros writes each dict as a temporary `/**:` parameter file; a dict placed
before a node's YAML file therefore loses to it (`association:=known` then ran unknown association).
:func:`with_arguments` puts the launch arguments last. :func:`resolve` applies a list as rcl does, so tests
can check what a node gets without `ros2 launch` (which cannot run in CI).

No rclpy or launch here: the launch files import this.
"""

from __future__ import annotations

from collections.abc import Iterable, Mapping, Sequence
from pathlib import Path
from typing import Any

import yaml

from .ros_files import flatten


def with_arguments(files: Sequence[Path | str], arguments: Mapping[str, Any]) -> list[str | dict[str, Any]]:
    """``[*files, arguments]``: the parameter files in order, then the launch arguments, which win."""
    return [*(str(path) for path in files), dict(arguments)]


def resolve(entries: Iterable[Path | str | Mapping[str, Any]], node_name: str) -> dict[str, Any]:
    """The parameter values node ``node_name`` gets from ``entries``: each dict, and each YAML file's
    ``/**``, ``node_name`` and ``/node_name`` sections, in order, a later value replacing an earlier one
    (dotted names for nested groups)."""
    values: dict[str, Any] = {}
    for entry in entries:
        if isinstance(entry, Mapping):
            values.update(flatten(entry))
            continue
        with open(entry, encoding="utf-8") as stream:
            document = yaml.safe_load(stream) or {}
        for key in ("/**", node_name, f"/{node_name}"):
            section = document.get(key)
            if isinstance(section, Mapping) and isinstance(section.get("ros__parameters"), Mapping):
                values.update(flatten(section["ros__parameters"]))
    return values
