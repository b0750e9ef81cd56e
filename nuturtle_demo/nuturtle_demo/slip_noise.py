"""SLAM's process noise matched to the simulated world's wheel slip."""

from __future__ import annotations

import math


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
