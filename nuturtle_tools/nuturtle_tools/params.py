"""ROS parameter files for in-process nodes (the demo's and the replay's): build parameter overrides, and
write the effective configuration back out as a params file.
"""

from __future__ import annotations

import array
from collections.abc import Iterable, Mapping
from typing import Any

import yaml
from rclpy.node import Node
from rclpy.parameter import Parameter

from nuturtle_ros_common.ros_files import nest


def _ros_value(value: Any) -> Any:
    """A YAML value as rclpy takes it: lists of numbers with any float become lists of floats."""
    if isinstance(value, (list, tuple)):
        values = list(value)
        if any(isinstance(v, float) for v in values) and all(
            isinstance(v, (int, float)) and not isinstance(v, bool) for v in values
        ):
            return [float(v) for v in values]
        return values
    return value


def to_parameters(values: Mapping[str, Any]) -> list[Parameter]:
    """rclpy Parameters (for ``parameter_overrides=``) from ``{name: value}``."""
    return [Parameter(name, value=_ros_value(value)) for name, value in values.items()]


def _plain(value: Any) -> Any:
    if isinstance(value, array.array):
        return value.tolist()
    if isinstance(value, (list, tuple)):
        return [_plain(v) for v in value]
    return value


def node_parameters(node: Node) -> dict[str, Any]:
    """Every parameter of ``node`` and its current value, by name."""
    names = node.list_parameters([], 0).names
    return {parameter.name: _plain(parameter.value) for parameter in node.get_parameters(names)}


class _ParamsDumper(yaml.SafeDumper):
    """Mappings in block style, lists in flow style (``x: [1.4, -1.4]``), like hand-written params files."""


_ParamsDumper.add_representer(
    list, lambda dumper, data: dumper.represent_sequence("tag:yaml.org,2002:seq", data, flow_style=True)
)


def params_file(nodes: Iterable[Node], replace: Mapping[str, Mapping[str, Any]] | None = None) -> str:
    """A ROS params file (YAML) holding every parameter of every node, usable with ``--params-file``;
    ``replace`` maps a node's name to values written instead of its own (e.g. how fast a run went)."""
    replace = replace or {}
    document = {}
    for node in nodes:
        name = node.get_fully_qualified_name().lstrip("/")
        values = {**node_parameters(node), **replace.get(name, {})}
        document[name] = {"ros__parameters": nest(values)}
    return yaml.dump(document, Dumper=_ParamsDumper, sort_keys=False, width=110)
