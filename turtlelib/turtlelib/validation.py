"""The one way config values and inputs are checked in this suite (ValueError, never assert).

Every config dataclass (turtlelib's, the nodes', the simulator's) validates its fields in
``__post_init__`` with these functions, so every message reads ``<name> must be ..., got <value>``. Each
returns the value converted (``float`` or ``int``); a frozen dataclass stores it back with
:func:`store`.
"""

from __future__ import annotations

import math
from collections.abc import Callable, Collection, Iterable
from numbers import Integral, Real
from typing import TypeVar

import numpy as np

T = TypeVar("T")
_FLOATS = (float, np.float64)


def finite_real(name: str, value: object) -> float:
    """``value`` as a float; ValueError unless it is a real number (bools excluded) whose float is finite
    (so an int beyond the float range, about 1.8e308, is refused too)."""
    # floats (and numpy's float64, a float subclass) first: the numbers.Real check costs about 1 us
    if type(value) in _FLOATS:
        if math.isfinite(value):
            return float(value)
    elif not isinstance(value, bool) and isinstance(value, Real):
        try:
            as_float = float(value)
        except OverflowError:  # an int beyond the float range
            as_float = math.inf
        if math.isfinite(as_float):
            return as_float
    raise ValueError(f"{name} must be a finite number, got {value!r}")


def positive(name: str, value: object) -> float:
    """``value`` as a float; ValueError unless it is finite and > 0."""
    if finite_real(name, value) <= 0.0:
        raise ValueError(f"{name} must be finite and > 0, got {value!r}")
    return float(value)


def non_negative(name: str, value: object) -> float:
    """``value`` as a float; ValueError unless it is finite and >= 0."""
    if finite_real(name, value) < 0.0:
        raise ValueError(f"{name} must be finite and >= 0, got {value!r}")
    return float(value)


def integer(name: str, value: object, minimum: int | None = None, maximum: int | None = None) -> int:
    """``value`` as an int; ValueError unless it is an integer (bools excluded) with
    ``minimum <= value <= maximum`` (a bound left None is not checked)."""
    if isinstance(value, bool) or not isinstance(value, Integral):
        raise ValueError(f"{name} must be an integer, got {value!r}")
    if minimum is not None and value < minimum:
        raise ValueError(f"{name} must be >= {minimum}, got {value!r}")
    if maximum is not None and value > maximum:
        raise ValueError(f"{name} must be <= {maximum}, got {value!r}")
    return int(value)


def in_range(
    name: str, value: object, low: float, high: float, *, open_low: bool = False, open_high: bool = False
) -> float:
    """``value`` as a float; ValueError unless it is finite and in the interval from ``low`` to ``high``:
    ``[low, high]``, without ``low`` if ``open_low`` and without ``high`` if ``open_high``."""
    x = finite_real(name, value)
    if (x <= low if open_low else x < low) or (x >= high if open_high else x > high):
        interval = f"{'(' if open_low else '['}{low}, {high}{')' if open_high else ']'}"
        raise ValueError(f"{name} must be in {interval}, got {value!r}")
    return x


def one_of(name: str, value: T, choices: Collection[T]) -> T:
    """``value``; ValueError unless it is one of ``choices``."""
    if value not in choices:
        raise ValueError(f"{name} must be one of {tuple(choices)}, got {value!r}")
    return value


def names(kind: str, **values: object) -> None:
    """ValueError unless every value is a non-empty string and no two are equal (frame ids, joint
    names: ``kind`` says which, for the message)."""
    for name, value in values.items():
        if not isinstance(value, str) or not value:
            raise ValueError(f"{name} must be a non-empty {kind}, got {value!r}")
    if len(set(values.values())) != len(values):
        raise ValueError(f"{', '.join(values)} must be distinct {kind}s, got {list(values.values())}")


def store(
    config: object, fields: Iterable[str], check: Callable[[str, object], object], prefix: str = ""
) -> None:
    """Check each field of a (frozen) dataclass with ``check(prefix + name, value)`` and store what it
    returns (``prefix`` says whose field it is in the message, e.g. ``"lidar "``)."""
    for name in fields:
        object.__setattr__(config, name, check(prefix + name, getattr(config, name)))
