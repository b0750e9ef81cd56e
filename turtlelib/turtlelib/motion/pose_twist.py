"""The body twist between consecutive poses of an odometry source (what a node publishes as its twist when
the motion comes as poses, not wheel angles).

From the reference sample ``(t_0, T_0)`` to ``(t_1, T_1)`` (``T = T_odom_body``, times in s)::

    V_body = log(T_0^-1 T_1) / (t_1 - t_0)      (rad/s, m/s, m/s; zero when t_1 = t_0)

the constant body twist that moves ``T_0`` to ``T_1`` along one arc in that time. Same interface as
:class:`turtlelib.motion.wheel_odometry.WheelOdometry`, with poses ``(x, y, theta)`` in place of wheel angles.
"""

from __future__ import annotations

import math

from ..geometry.se2 import Transform2D, Twist2D


class PoseTwist:
    """Twists from odometry poses ``(x_m, y_m, theta_rad)`` sampled at times ``t_s``."""

    def __init__(self) -> None:
        self._reference: tuple[float, Transform2D] | None = None

    @property
    def reference_time_s(self) -> float | None:
        """Time (s) of the last sample, None before the first."""
        return None if self._reference is None else self._reference[0]

    def set_reference(self, t_s: float, x_m: float, y_m: float, theta_rad: float) -> None:
        """Take this sample as the one the next twist is measured from; ValueError for non-finite values."""
        if not all(math.isfinite(float(value)) for value in (t_s, x_m, y_m, theta_rad)):
            raise ValueError(f"time and pose must be finite, got {(t_s, x_m, y_m, theta_rad)!r}")
        self._reference = (float(t_s), Transform2D(x_m, y_m, theta_rad))

    def step(self, t_s: float, x_m: float, y_m: float, theta_rad: float) -> Twist2D:
        """``V_body`` from the reference to this sample, which becomes the reference. ValueError before a
        reference, for non-finite values or a time before the reference (the state is then unchanged)."""
        if self._reference is None:
            raise ValueError("no reference sample yet: call set_reference first")
        t0_s, T0 = self._reference
        if float(t_s) < t0_s:
            raise ValueError(f"time went backwards: {t_s!r} s < {t0_s!r} s")
        T1 = Transform2D(x_m, y_m, theta_rad)
        dt_s = float(t_s) - t0_s
        # V_body = log(T_0^-1 T_1) / dt
        V_body = Twist2D() if dt_s == 0.0 else (T0.inverse() @ T1).log() * (1.0 / dt_s)
        self.set_reference(t_s, x_m, y_m, theta_rad)
        return V_body
