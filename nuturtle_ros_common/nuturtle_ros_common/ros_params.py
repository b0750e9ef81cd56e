"""Declare a frozen config dataclass as ROS parameters and build it from their values.

Config dataclasses (turtlelib's and the nodes') name their fields after the ROS parameters, so one
generic function serves every node: each field becomes parameter `<prefix><field>`, its default is the
dataclass default (or an override such as the robot model's constants from models.yaml), and the
dataclass's own validation raises `ValueError` for invalid values.

Parameters are a contract: each one is described (`ros2 param describe`) by the part of its dataclass's
docstring that names it (units, range, meaning), and is read-only unless the node applies a change at
run time (then it passes `read_only=False` and validates changes with `replace_from_parameters` in an
on-set callback). `ros2 param set` on a read-only parameter is refused with the reason, instead of
answering "successful" and changing nothing.
"""

from __future__ import annotations

import array
import dataclasses
import inspect
import re
from collections.abc import Iterable, Mapping
from typing import Any, TypeVar

from rcl_interfaces.msg import ParameterDescriptor
from rclpy.node import Node
from rclpy.parameter import Parameter

C = TypeVar("C")


# The annotation of a field that is a string array (as written under ``from __future__ import annotations``,
# or evaluated)
STRING_TUPLE = ("tuple[str, ...]", tuple[str, ...])


def _coerce(value: Any, like: Any, name: str, strings: bool = False) -> Any:
    """Convert a ROS parameter value to the type of the field default: ints are accepted where floats
    are expected and ROS arrays become tuples of floats, or of strings for a string-array field
    (``strings``: annotated ``tuple[str, ...]``) (an empty YAML list, which rcl leaves without a type,
    ``None``, an empty tuple); anything else of the wrong type is a ValueError."""
    is_number = isinstance(value, (int, float)) and not isinstance(value, bool)
    if strings and isinstance(value, (list, tuple)):
        if all(isinstance(v, str) for v in value):
            return tuple(value)
        raise ValueError(f"parameter {name} must be a list of strings, got {value!r}")
    if isinstance(like, bool) and isinstance(value, bool):
        return value
    if isinstance(like, float) and is_number:
        return float(value)
    if isinstance(like, int) and not isinstance(like, bool) and isinstance(value, int) and is_number:
        return value
    if isinstance(like, str) and isinstance(value, str):
        return value
    if isinstance(like, tuple) and value is None:
        return ()
    if isinstance(like, tuple) and isinstance(value, (list, tuple, array.array)):
        try:
            return tuple(float(v) for v in value)
        except (TypeError, ValueError):
            pass
    raise ValueError(f"parameter {name} must be of type {type(like).__name__}, got {value!r}")


def string_tuple_fields(cls: type) -> set[str]:
    """The fields of ``cls`` annotated ``tuple[str, ...]`` (ROS string arrays)."""
    return {field.name for field in dataclasses.fields(cls) if field.type in STRING_TUPLE}


def field_defaults(cls: type) -> dict[str, Any]:
    """Each field's default value (fields without one are not parameters)."""
    defaults = {}
    for field in dataclasses.fields(cls):
        if field.default is not dataclasses.MISSING:
            defaults[field.name] = field.default
        elif field.default_factory is not dataclasses.MISSING:
            defaults[field.name] = field.default_factory()
    return defaults


def _clauses(text: str) -> list[str]:
    """``text`` cut after each ``;`` and each sentence's ``.`` that stand outside parentheses and quotes
    (backticks), its whitespace collapsed: the clauses of one bullet."""
    clauses = []
    depth, quoted, start = 0, False, 0
    for i, char in enumerate(text):
        if char == "`":
            quoted = not quoted
        elif not quoted and char in "([":
            depth += 1
        elif not quoted and char in ")]":
            depth = max(depth - 1, 0)
        elif not quoted and depth == 0 and char in ".;" and text[i + 1 : i + 2] in (" ", ""):
            clauses.append(text[start : i + 1].strip())
            start = i + 1
    clauses.append(text[start:].strip())
    return [clause for clause in clauses if clause]


def field_descriptions(cls: type) -> dict[str, str]:
    """Each field's description, one sentence: the first clause of ``cls``'s docstring (a bullet, or a
    sentence or ``;``-separated part of one, cut outside parentheses and backticks) that opens with a
    backticked span naming the field, else the first clause that names it in backticks at all, else the
    docstring's summary line; ended with a full stop."""
    doc = inspect.getdoc(cls) or ""
    summary = doc.strip().splitlines()[0] if doc.strip() else cls.__name__
    clauses = []
    for bullet in re.split(r"\n\s*\*\s+", "\n" + doc):
        clauses += _clauses(" ".join(bullet.split()))
    # each clause's backticked spans (``name``, ``name > 0``, ``(x0, y0)``)
    spans = [re.findall(r"`+([^`]+)`+", clause) for clause in clauses]
    descriptions = {}
    for field in dataclasses.fields(cls):
        word = re.compile(rf"(?<![\w.]){re.escape(field.name)}\b")
        defining = [
            c for c, found in zip(clauses, spans, strict=True) if c.startswith("`") and word.search(found[0])
        ]
        naming = [c for c, found in zip(clauses, spans, strict=True) if any(word.search(f) for f in found)]
        named = next(iter(defining + naming), summary)
        ending = "" if named.endswith(".") else "."
        descriptions[field.name] = f"{cls.__name__}: {named.rstrip(';,:')}{ending}"
    return descriptions


def declare_dataclass(
    node: Node,
    cls: type[C],
    prefix: str = "",
    overrides: Mapping[str, Any] | None = None,
    fixed: Mapping[str, Any] | None = None,
    read_only: bool = True,
) -> C:
    """Declare every field of `cls` as parameter `prefix + name` and return `cls(**values)`.

    `overrides` replace field defaults; `fixed` fields are not parameters of their own but take the
    given values (e.g. the slam filter's sensor mount, which is the robot's `lidar_*` parameters).
    Each parameter is described by :func:`field_descriptions` and is read-only unless `read_only=False`
    (for a node that applies changes). Raises ValueError (from the dataclass or for a wrongly typed value)
    when a value is invalid.
    """
    fixed = dict(fixed or {})
    defaults = {name: value for name, value in field_defaults(cls).items() if name not in fixed}
    defaults.update({name: value for name, value in (overrides or {}).items() if name not in fixed})
    values = dict(fixed)
    descriptions = field_descriptions(cls)
    strings = string_tuple_fields(cls)
    for name, default in defaults.items():
        if isinstance(default, tuple):
            default = list(default)
        # dynamic typing: a YAML `0` for a float parameter is coerced below rather than refused by rclpy
        description = f"{prefix}{name}: {descriptions[name]}" if prefix else descriptions[name]
        descriptor = ParameterDescriptor(description=description, read_only=read_only, dynamic_typing=True)
        parameter = node.declare_parameter(prefix + name, default, descriptor)
        like = defaults[name]
        values[name] = _coerce(parameter.value, like, prefix + name, name in strings)
    return cls(**values)


def replace_from_parameters(config: C, parameters: Iterable[Parameter], prefix: str = "") -> C:
    """`config` with the fields named by `parameters` (`prefix + name`) set to their coerced values.

    For run-time changes: validate in an on-set-parameters callback (a ValueError means reject), apply in
    the post-set callback. Parameters that name no field are ignored.
    """
    current = {field.name: getattr(config, field.name) for field in dataclasses.fields(config)}
    changes = {}
    strings = string_tuple_fields(type(config))
    for parameter in parameters:
        name = parameter.name.removeprefix(prefix)
        if parameter.name.startswith(prefix) and name in current:
            changes[name] = _coerce(parameter.value, current[name], parameter.name, name in strings)
    return dataclasses.replace(config, **changes)
