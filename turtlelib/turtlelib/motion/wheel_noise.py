"""Process noise of a differential-drive step from random-walk wheel slip, independent of the step rate.

Model
-----
The ground travel of each wheel differs from its encoder increment ``dphi`` (rad) by slip that
accumulates along the travel as a Wiener process: over an increment ``dphi`` the slip is
``N(0, wheel_noise^2 |dphi|)``, independent for the left and right wheel. ``wheel_noise`` is in sqrt(rad):
the slip standard deviation after 1 rad of wheel travel. Variances add along the path, so splitting a
motion into more, smaller prediction steps leaves the noise unchanged.

Within one step the wheels turn at constant rates and the slip enters as white noise of intensity
``Q_w = wheel_noise^2 diag(|dphi_left|, |dphi_right|)``. Through the kinematics
``[dvx, domega] = M [dphi_left, dphi_right]`` with ``M = [[r/2, r/2], [-r/d, r/d]]`` that is the twist noise
``Sigma = M Q_w M^T`` (no sideways noise), propagated along the step's arc by
:func:`turtlelib.motion.arc_noise.arc_covariance`.
"""

from __future__ import annotations

import numpy as np
from numpy.typing import NDArray

from ..geometry.se2 import Twist2D
from .arc_noise import arc_covariance
from .kinematics import DiffDrive


def wheel_slip_covariance(
    diff_drive: DiffDrive,
    theta_rad: float,
    dphi_left: float,
    dphi_right: float,
    wheel_noise: float,
    twist: Twist2D | None = None,
) -> NDArray[np.float64]:
    """The (3, 3) covariance of ``[x, y, theta]`` added by a step ``dphi`` (rad) from heading ``theta_rad``.

    See the module docstring for the model; ``wheel_noise`` in sqrt(rad), >= 0; ``twist`` the step's
    ``diff_drive.body_twist(dphi_left, dphi_right)`` if the caller has it. ValueError for a step that
    turns the body by more than ``arc_noise.MAX_STEP_TURN_RAD``.
    """
    if twist is None:
        twist = diff_drive.body_twist(dphi_left, dphi_right)
    r, d = diff_drive.wheel_radius, diff_drive.track_width
    q_left, q_right = wheel_noise**2 * abs(dphi_left), wheel_noise**2 * abs(dphi_right)
    # Sigma = M Q_w M^T with M = [[r/2, r/2], [-r/d, r/d]]
    var_v = 0.25 * r * r * (q_left + q_right)
    cov_vw = 0.5 * r * r / d * (q_right - q_left)
    var_w = r * r / (d * d) * (q_left + q_right)
    return arc_covariance(theta_rad, twist.omega, twist.vx, 0.0, var_v, cov_vw, var_w)
