"""Declare a frozen config dataclass as ROS parameters and build it from their values.

Config dataclasses (turtlelib's and the nodes') name their fields after the ROS parameters, so one
generic function serves every node: each field becomes parameter `<prefix><field>`, its default is the
dataclass default (or an override such as the Burger's constants from diff_params.yaml), and the
dataclass's own validation raises `ValueError` for invalid values.
"""

from __future__ import annotations

import array
import dataclasses
from collections.abc import Iterable, Mapping
from typing import Any, TypeVar

from rcl_interfaces.msg import ParameterDescriptor
from rclpy.node import Node
from rclpy.parameter import Parameter

C = TypeVar("C")


def _coerce(value: Any, like: Any, name: str) -> Any:
    """Convert a ROS parameter value to the type of the field default: ints are accepted where floats
    are expected and ROS arrays become tuples of floats; anything else of the wrong type is a ValueError."""
    is_number = isinstance(value, (int, float)) and not isinstance(value, bool)
    if isinstance(like, bool) and isinstance(value, bool):
        return value
    if isinstance(like, float) and is_number:
        return float(value)
    if isinstance(like, int) and not isinstance(like, bool) and isinstance(value, int) and is_number:
        return value
    if isinstance(like, str) and isinstance(value, str):
        return value
    if isinstance(like, tuple) and isinstance(value, (list, tuple, array.array)):
        try:
            return tuple(float(v) for v in value)
        except (TypeError, ValueError):
            pass
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
    node: Node,
    cls: type[C],
    prefix: str = "",
    overrides: Mapping[str, Any] | None = None,
    fixed: Mapping[str, Any] | None = None,
) -> C:
    """Declare every field of `cls` as parameter `prefix + name` and return `cls(**values)`.

    `overrides` replace field defaults; `fixed` fields are not parameters of their own but take the
    given values (e.g. the slam filter's sensor mount, which is the robot's `lidar_*` parameters).
    Raises ValueError (from the dataclass or for a wrongly typed value) when a value is invalid.
    """
    fixed = dict(fixed or {})
    defaults = {name: value for name, value in field_defaults(cls).items() if name not in fixed}
    defaults.update({name: value for name, value in (overrides or {}).items() if name not in fixed})
    values = dict(fixed)
    for name, default in defaults.items():
        if isinstance(default, tuple):
            default = list(default)
        parameter = node.declare_parameter(prefix + name, default, ParameterDescriptor(dynamic_typing=True))
        like = defaults[name]
        values[name] = _coerce(parameter.value, like, prefix + name)
    return cls(**values)


def replace_from_parameters(config: C, parameters: Iterable[Parameter], prefix: str = "") -> C:
    """`config` with the fields named by `parameters` (`prefix + name`) set to their coerced values.

    For run-time changes: validate in an on-set-parameters callback (a ValueError means reject), apply in
    the post-set callback. Parameters that name no field are ignored.
    """
    current = {field.name: getattr(config, field.name) for field in dataclasses.fields(config)}
    changes = {}
    for parameter in parameters:
        name = parameter.name.removeprefix(prefix)
        if parameter.name.startswith(prefix) and name in current:
            changes[name] = _coerce(parameter.value, current[name], parameter.name)
    return dataclasses.replace(config, **changes)
