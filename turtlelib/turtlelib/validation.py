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

T = TypeVar("T")


def finite_real(name: str, value: object) -> float:
    """``value`` as a float; ValueError unless it is a finite real number (bools excluded)."""
    if isinstance(value, bool) or not isinstance(value, Real) or not math.isfinite(value):
        raise ValueError(f"{name} must be a finite number, got {value!r}")
    return float(value)


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


def integer(name: str, value: object, minimum: int | None = None) -> int:
    """``value`` as an int; ValueError unless it is an integer (bools excluded) and ``>= minimum``."""
    if isinstance(value, bool) or not isinstance(value, Integral):
        raise ValueError(f"{name} must be an integer, got {value!r}")
    if minimum is not None and value < minimum:
        raise ValueError(f"{name} must be >= {minimum}, got {value!r}")
    return int(value)


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


def store(config: object, fields: Iterable[str], check: Callable[[str, object], object]) -> None:
    """Check each field of a (frozen) dataclass with ``check(name, value)`` and store what it returns."""
    for name in fields:
        object.__setattr__(config, name, check(name, getattr(config, name)))
