"""Checks of configuration values and inputs shared by turtlelib's modules (ValueError, never assert)."""

from __future__ import annotations

import math
from numbers import Integral, Real


def finite_real(name: str, value: object) -> float:
    """``value`` as a float; ValueError unless it is a finite real number (bools excluded)."""
    if isinstance(value, bool) or not isinstance(value, Real) or not math.isfinite(value):
        raise ValueError(f"{name} must be a finite number, got {value!r}")
    return float(value)


def integer(name: str, value: object) -> int:
    """``value`` as an int; ValueError unless it is an integer (bools excluded)."""
    if isinstance(value, bool) or not isinstance(value, Integral):
        raise ValueError(f"{name} must be an integer, got {value!r}")
    return int(value)
