"""SLAM's noise models matched to the simulated world's: wheel slip, LiDAR range noise."""

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


def matched_point_std(range_noise_m: float, resolution_m: float) -> float:
    """The registration's ``point_std_m`` (m) for nusim's LiDAR: a range is the true one plus
    ``N(0, noise^2)``, rounded to ``resolution`` (a uniform error of variance ``resolution^2 / 12``)::

        point_std_m = sqrt(noise^2 + resolution^2 / 12)
    """
    if not (range_noise_m >= 0.0 and resolution_m >= 0.0 and range_noise_m + resolution_m > 0.0):
        raise ValueError(
            f"need range_noise_m, resolution_m >= 0, not both 0, got {range_noise_m!r}, {resolution_m!r}"
        )
    return math.sqrt(range_noise_m**2 + resolution_m**2 / 12.0)
