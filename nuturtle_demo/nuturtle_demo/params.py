"""ROS parameter files for the demo: build in-process parameter overrides, write the
effective configuration back out as a params file, and match SLAM's process noise to the world's slip.
"""

from __future__ import annotations

import array
import math
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


def matched_wheel_noise(slip_fraction: float, wheel_speed_rad_s: float, physics_rate_hz: float) -> float:
    """SLAM's ``wheel_noise`` (sqrt(rad)) for nusim's slip at a steady wheel speed.

    nusim slips each physics step of ``dt = 1 / rate`` s by ``s ~ U(-f, f)`` of that step's wheel travel
    ``|w| dt``: variance ``(|w| dt)^2 f^2 / 3`` per step. Over a travel ``|dphi|`` (``|dphi| / (|w| dt)``
    steps) the variances add to ``|dphi| |w| dt f^2 / 3``, which is SLAM's ``wheel_noise^2 |dphi|``::

        wheel_noise = f sqrt(|w| dt / 3)
    """
    if not (slip_fraction >= 0.0 and wheel_speed_rad_s >= 0.0 and physics_rate_hz > 0.0):
        raise ValueError(
            "need slip_fraction >= 0, wheel_speed_rad_s >= 0 and physics_rate_hz > 0, got "
            f"{slip_fraction!r}, {wheel_speed_rad_s!r}, {physics_rate_hz!r}"
        )
    return slip_fraction * math.sqrt(wheel_speed_rad_s / physics_rate_hz / 3.0)
