"""Dead reckoning of a differential drive from its wheel angles.

State: the pose ``T_odom_body`` and the reference sample ``(t_s, phi_left_rad, phi_right_rad)`` of the
last integrated wheel angles. Each new sample integrates the wheel-angle increments along the exact arc
(``turtlelib.DiffDrive.step``)::

    dphi = phi_k - phi_{k-1}
    T_odom_body_k = T_odom_body_{k-1} @ exp([F dphi])
    V_body = F dphi / (t_k - t_{k-1})

Angles, not speeds, are integrated, so the pose is exact whatever the sampling rate and no velocity
estimate's error accumulates. The first sample only sets the reference.
"""

from __future__ import annotations

import math

from ..geometry.se2 import Transform2D, Twist2D
from .kinematics import DiffDrive


class WheelOdometry:
    """Wheel odometry: the pose ``T_odom_body`` from wheel angles (rad) sampled at times ``t_s`` (s)."""

    def __init__(self, drive: DiffDrive, T_odom_body: Transform2D | None = None) -> None:
        self.drive = drive
        self.T_odom_body = T_odom_body if T_odom_body is not None else Transform2D()
        self._reference: tuple[float, float, float] | None = None

    @property
    def reference_time_s(self) -> float | None:
        """Time (s) of the last integrated sample, None before the first."""
        return None if self._reference is None else self._reference[0]

    def set_reference(self, t_s: float, phi_left_rad: float, phi_right_rad: float) -> None:
        """Take this sample as the one the next increment is measured from (the pose is unchanged)."""
        sample = (float(t_s), float(phi_left_rad), float(phi_right_rad))
        if not all(math.isfinite(value) for value in sample):
            raise ValueError(f"time and wheel angles must be finite, got {sample!r}")
        self._reference = sample

    def step(self, t_s: float, phi_left_rad: float, phi_right_rad: float) -> Twist2D:
        """Integrate the wheel increments since the reference; returns the mean body twist ``V_body``.

        ``V_body = F dphi / dt`` (rad/s, m/s); zero when ``dt = 0`` (the pose still moves by the
        increments). ValueError before a reference is set, for non-finite values, or when ``t_s`` is
        earlier than the reference (the state is then unchanged).
        """
        if self._reference is None:
            raise ValueError("no reference sample yet: call set_reference first")
        t0_s, phi0_left_rad, phi0_right_rad = self._reference
        if float(t_s) < t0_s:
            raise ValueError(f"time went backwards: {t_s!r} s < {t0_s!r} s")
        # dphi = phi_k - phi_{k-1}
        dphi_left = float(phi_left_rad) - phi0_left_rad
        dphi_right = float(phi_right_rad) - phi0_right_rad
        # T_odom_body_k = T_odom_body_{k-1} @ exp([F dphi])
        T_odom_body = self.drive.step(self.T_odom_body, dphi_left, dphi_right)
        dt_s = float(t_s) - t0_s
        if dt_s == 0.0:
            V_body = Twist2D()
        else:
            # V_body = F dphi / dt
            V_body = self.drive.body_twist(dphi_left, dphi_right) * (1.0 / dt_s)
        # commit only once everything is computed (a ValueError above leaves the state unchanged)
        self.set_reference(t_s, phi_left_rad, phi_right_rad)
        self.T_odom_body = T_odom_body
        return V_body
