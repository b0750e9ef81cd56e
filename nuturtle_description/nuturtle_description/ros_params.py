"""Declare a frozen config dataclass as ROS parameters and build it from their values.

Config dataclasses (turtlelib's and the nodes') name their fields after the ROS parameters, so one
generic function serves every node: each field becomes parameter `<prefix><field>`, its default is the
dataclass default (or an override such as the Burger's constants from diff_params.yaml), and the
dataclass's own validation raises `ValueError` for invalid values.
"""

from __future__ import annotations

import dataclasses
from collections.abc import Mapping
from typing import Any, TypeVar

from rcl_interfaces.msg import ParameterDescriptor
from rclpy.node import Node

C = TypeVar("C")


def _coerce(value: Any, like: Any, name: str) -> Any:
    """Convert a ROS parameter value to the type of the field default (ints where floats are expected,
    ROS arrays to tuples); anything else of the wrong type is a ValueError."""
    if isinstance(like, bool):
        if not isinstance(value, bool):
            raise ValueError(f"parameter {name} must be a bool, got {value!r}")
        return value
    if isinstance(like, float) and isinstance(value, (int, float)) and not isinstance(value, bool):
        return float(value)
    if isinstance(like, int) and isinstance(value, int) and not isinstance(value, bool):
        return value
    if isinstance(like, str) and isinstance(value, str):
        return value
    if isinstance(like, tuple) and isinstance(value, (list, tuple)) or (
        isinstance(like, tuple) and hasattr(value, "tolist")
    ):
        return tuple(float(v) for v in value)
    raise ValueError(f"parameter {name} must be of type {type(like).__name__}, got {value!r}")


def field_defaults(cls: type) -> dict[str, Any]:
    """Each field's default value (fields without one are not parameters)."""
    defaults = {}
    for field in dataclasses.fields(cls):
        if field.default is not dataclasses.MISSING:
            defaults[field.name] = field.default
        elif field.default_factory is not dataclasses.MISSING:
            defaults[field.name] = field.default_factory()
    return defaults


def declare_dataclass(
    node: Node, cls: type[C], prefix: str = "", overrides: Mapping[str, Any] | None = None
) -> C:
    """Declare every field of `cls` as parameter `prefix + name` and return `cls(**values)`.

    Raises ValueError (from the dataclass or for a wrongly typed value) when a value is invalid.
    """
    defaults = field_defaults(cls)
    defaults.update(overrides or {})
    values = {}
    for name, default in defaults.items():
        if isinstance(default, tuple):
            default = list(default)
        parameter = node.declare_parameter(
            prefix + name, default, ParameterDescriptor(dynamic_typing=True)
        )
        like = defaults[name]
        values[name] = _coerce(parameter.value, like, prefix + name)
    return cls(**values)
