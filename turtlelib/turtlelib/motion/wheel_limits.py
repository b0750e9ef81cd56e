"""Curvature-preserving saturation of differential-drive wheel speeds.

A wheel command beyond the motors' limit cannot be clipped wheel by wheel without changing the path:
the body twist is linear in the wheel speeds, ``V_b = F [phi_dot_left, phi_dot_right]``, so clipping
one wheel changes the ratio ``omega / vx``, i.e. the curvature. Scaling both wheels by the same factor
``s`` scales the twist to ``s V_b``: the robot follows the same arc, only slower.
"""

from __future__ import annotations

import math


def limit_wheel_speeds(left_rad_s: float, right_rad_s: float, max_rad_s: float) -> tuple[float, float, float]:
    """``(left', right', s)``: both wheel speeds (rad/s) scaled by ``s = min(1, max / max(|l|, |r|))``.

    ``|left'|, |right'| <= max_rad_s`` exactly (each wheel is ``max * (w / peak)`` with
    ``|w / peak| <= 1``), the faster wheel lands on the limit, and ``left' / right' = left / right``, so
    the body twist keeps its curvature ``omega / vx``. ``s == 1`` (and the speeds are returned
    unchanged) when neither wheel exceeds the limit. ValueError for non-finite speeds or a limit that is
    not finite and > 0.
    """
    if not (math.isfinite(max_rad_s) and max_rad_s > 0.0):
        raise ValueError(f"max_rad_s must be finite and > 0, got {max_rad_s!r}")
    if not (math.isfinite(left_rad_s) and math.isfinite(right_rad_s)):
        raise ValueError(f"wheel speeds must be finite, got ({left_rad_s!r}, {right_rad_s!r})")
    peak_rad_s = max(abs(left_rad_s), abs(right_rad_s))
    if peak_rad_s <= max_rad_s:
        return left_rad_s, right_rad_s, 1.0
    # w' = s w with s = max / peak, written as max * (w / peak) so that |w'| <= max after rounding
    return (
        max_rad_s * (left_rad_s / peak_rad_s),
        max_rad_s * (right_rad_s / peak_rad_s),
        max_rad_s / peak_rad_s,
    )
