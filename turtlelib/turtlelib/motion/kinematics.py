"""Kinematics of a differential-drive robot (Modern Robotics, Lynch & Park, ch. 13.3).

Conventions
-----------
* The body frame sits midway between the wheels, x forward, y to the left; theta counter-clockwise.
* Wheel quantities are ordered left, right everywhere. They are either wheel speeds (rad/s, giving a
  body twist in rad/s, m/s) or wheel increments ``dphi`` (rad, the change of each wheel angle over a
  step, giving the body displacement twist for unit time).
* With wheel radius ``r`` and track width ``d`` (wheel separation, m), the body twist
  ``V_b = [omega, vx, vy] = F dphi`` with ``F = pinv(H(0))``::

      omega = r (dphi_right - dphi_left) / d
      vx    = r (dphi_left + dphi_right) / 2
      vy    = 0

  and the inverse ``dphi = H(0) V_b``: ``dphi_left = (vx - omega d / 2) / r``,
  ``dphi_right = (vx + omega d / 2) / r``.
* A step moves the pose along the exact arc: ``T_world_body' = T_world_body @ exp([V_b])``.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

from ..geometry.se2 import SMALL_ANGLE_RAD, Transform2D, Twist2D, integrate_twist
from ..util.validation import finite_real, positive, store


@dataclass(frozen=True)
class DiffDrive:
    """A differential drive with ``wheel_radius`` (m) and ``track_width`` (m, wheel separation).

    Both must be finite and > 0 (ValueError otherwise). See the module docstring for the model.
    """

    wheel_radius: float
    track_width: float

    def __post_init__(self) -> None:
        store(self, ("wheel_radius", "track_width"), positive)

    def body_twist(self, dphi_left: float, dphi_right: float) -> Twist2D:
        """Forward kinematics ``V_b = F dphi``.

        Wheel increments (rad) give the body displacement twist for unit time; wheel speeds (rad/s) give
        the body twist (rad/s, m/s).

        Non-finite wheel values raise ValueError.
        """
        dphi_left, dphi_right = finite_real("dphi_left", dphi_left), finite_real("dphi_right", dphi_right)
        r, d = self.wheel_radius, self.track_width
        # omega = r (dphi_r - dphi_l) / d,  vx = r (dphi_l + dphi_r) / 2,  vy = 0
        return Twist2D(r * (dphi_right - dphi_left) / d, 0.5 * r * (dphi_left + dphi_right), 0.0)

    def wheel_speeds(self, twist: Twist2D) -> tuple[float, float]:
        """Inverse kinematics ``dphi = H(0) V_b``: (left, right) wheel speeds in rad/s for a body twist.

        A differential drive cannot slide sideways: ValueError unless ``twist.vy == 0``.
        """
        if twist.vy != 0.0:
            raise ValueError(f"a differential drive cannot follow vy != 0 (got vy = {twist.vy!r} m/s)")
        r, half_d = self.wheel_radius, 0.5 * self.track_width
        # dphi_l = (vx - omega d/2) / r,  dphi_r = (vx + omega d/2) / r
        return (twist.vx - twist.omega * half_d) / r, (twist.vx + twist.omega * half_d) / r

    def step(self, T_world_body: Transform2D, dphi_left: float, dphi_right: float) -> Transform2D:
        """The pose after wheel increments (rad): ``T_world_body' = T_world_body @ exp([F dphi])``."""
        return T_world_body @ integrate_twist(self.body_twist(dphi_left, dphi_right))

    def step_jacobians(
        self, theta_or_T: float | Transform2D, dphi_left: float, dphi_right: float
    ) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
        """Jacobians of :meth:`step` on the pose vector ``q = [x, y, theta]`` (theta not wrapped).

        With ``u = vx``, ``omega`` from :meth:`body_twist` and the arc functions ``a = sin(w)/w``,
        ``b = (1 - cos(w))/w`` of :func:`integrate_twist`, the step is::

            [x', y'] = [x, y] + u R(theta) [a(omega), b(omega)],   theta' = theta + omega

        Returns ``(G_pose, G_wheels)``:

        * ``G_pose = dq'/dq = [[1, 0, -dy], [0, 1, dx], [0, 0, 1]]`` (3x3) with
          ``[dx, dy] = [x', y'] - [x, y]``;
        * ``G_wheels = dq'/d[dphi_left, dphi_right]`` (3x2) = ``dq'/d[u, omega] @ d[u, omega]/d dphi`` with
          ``dq'/du = [R [a, b], 0]``, ``dq'/domega = [u R [a', b'], 1]``,
          ``d[u, omega]/d dphi = [[r/2, r/2], [-r/d, r/d]]``.

        ``a'``, ``b'`` use their Taylor series for ``|omega| < SMALL_ANGLE_RAD``, so straight-line motion
        (``dphi_left == dphi_right``) is smooth. ``theta_or_T`` is the old heading (rad) or the old pose;
        non-finite headings or wheel increments raise ValueError.
        """
        if isinstance(theta_or_T, Transform2D):
            theta = theta_or_T.theta
        else:
            theta = finite_real("heading", theta_or_T)
        twist = self.body_twist(dphi_left, dphi_right)
        u, omega = twist.vx, twist.omega
        c, s = math.cos(theta), math.sin(theta)
        rotation = np.array([[c, -s], [s, c]])
        # [a, b]: the arc travelled at unit forward speed, exp([omega, 1, 0]).translation
        arc = integrate_twist(Twist2D(omega, 1.0, 0.0)).translation
        darc_domega = _arc_derivative(omega)
        delta_xy = u * (rotation @ arc)

        # G_pose = [[1, 0, -dy], [0, 1, dx], [0, 0, 1]]
        G_pose = np.eye(3)
        G_pose[0, 2] = -delta_xy[1]
        G_pose[1, 2] = delta_xy[0]

        # dq'/d[u, omega]
        dq_du_domega = np.zeros((3, 2))
        dq_du_domega[:2, 0] = rotation @ arc
        dq_du_domega[:2, 1] = u * (rotation @ darc_domega)
        dq_du_domega[2, 1] = 1.0
        r, d = self.wheel_radius, self.track_width
        # d[u, omega]/d[dphi_l, dphi_r]
        du_domega_dphi = np.array([[0.5 * r, 0.5 * r], [-r / d, r / d]])
        G_wheels = dq_du_domega @ du_domega_dphi
        return G_pose, G_wheels


def _arc_derivative(omega: float) -> NDArray[np.float64]:
    """``[a'(w), b'(w)]`` for ``a = sin(w)/w``, ``b = (1 - cos(w))/w``.

    ``a' = (w cos w - sin w) / w^2``, ``b' = (w sin w - (1 - cos w)) / w^2``; below SMALL_ANGLE_RAD the
    closed forms cancel, so ``a' = -w/3 + w^3/30 - w^5/840`` and ``b' = 1/2 - w^2/8 + w^4/144 - w^6/5760``.
    """
    if abs(omega) < SMALL_ANGLE_RAD:
        omega2 = omega * omega
        da = omega * (-1.0 / 3.0 + omega2 * (1.0 / 30.0 - omega2 / 840.0))
        db = 0.5 - omega2 * (1.0 / 8.0 - omega2 * (1.0 / 144.0 - omega2 / 5760.0))
        return np.array([da, db])
    omega2 = omega * omega
    one_minus_cos = 2.0 * math.sin(0.5 * omega) ** 2
    return np.array(
        [
            (omega * math.cos(omega) - math.sin(omega)) / omega2,
            (omega * math.sin(omega) - one_minus_cos) / omega2,
        ]
    )
