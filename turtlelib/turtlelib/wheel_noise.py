"""Process noise of a differential-drive step from random-walk wheel slip, independent of the step rate.

Model
-----
The ground travel of each wheel differs from its encoder increment ``dphi`` (rad) by slip that
accumulates along the travel as a Wiener process: over an increment ``dphi`` the slip is
``N(0, wheel_noise^2 |dphi|)``, independent for the left and right wheel. ``wheel_noise`` is in sqrt(rad):
the slip standard deviation after 1 rad of wheel travel. Variances add along the path, so splitting a
motion into more, smaller prediction steps leaves the noise unchanged.

Within one step ``s`` in [0, 1] runs from the old to the new pose at constant wheel rates, and the slip
enters as white noise of intensity ``Q_w = wheel_noise^2 diag(|dphi_left|, |dphi_right|)``. Through the
kinematics ``[dv, domega] = M [dphi_left, dphi_right]`` with ``M = [[r/2, r/2], [-r/d, r/d]]``, and the
linearised error dynamics along the arc ``theta(s) = theta + omega s``, ``p(s)``::

    Q = integral_0^1 A(s) M Q_w M^T A(s)^T ds,   A(s) = [[cos(theta(s)), -(y(1) - y(s))],
                                                        [sin(theta(s)),   x(1) - x(s) ],
                                                        [0,               1           ]]

(``A(s)`` is the transition ``[[1, 0, -dy], [0, 1, dx], [0, 0, 1]]`` from ``s`` to the step's end applied
to the noise input ``[cos(theta) dv, sin(theta) dv, domega]``). Because these transitions compose, one
step of a constant-curvature motion gives exactly the covariance of any number of shorter steps along it.
The integral is evaluated by composite Gauss-Legendre quadrature with ``GAUSS_LEGENDRE_NODES`` nodes per
radian of heading change (at least one panel), exact to ~1e-13 relative.
"""

from __future__ import annotations

import math

import numpy as np
from numpy.typing import NDArray

from .kinematics import DiffDrive

GAUSS_LEGENDRE_NODES = 8
# Largest heading change of one step (rad) the quadrature takes: a turn of more than a thousand rad between
# two encoder readings is a corrupt reading, not a motion (and would need that many panels).
MAX_STEP_TURN_RAD = 1000.0
# Gauss-Legendre nodes and weights mapped to [0, 1]: constants of the quadrature rule, not state.
_NODES_ON_UNIT, _WEIGHTS_ON_UNIT = np.polynomial.legendre.leggauss(GAUSS_LEGENDRE_NODES)
_NODES_ON_UNIT = 0.5 * (_NODES_ON_UNIT + 1.0)
_WEIGHTS_ON_UNIT = 0.5 * _WEIGHTS_ON_UNIT


def wheel_slip_covariance(
    diff_drive: DiffDrive, theta_rad: float, dphi_left: float, dphi_right: float, wheel_noise: float
) -> NDArray[np.float64]:
    """The (3, 3) covariance of ``[x, y, theta]`` added by a step ``dphi`` (rad) from heading ``theta_rad``.

    See the module docstring for the model; ``wheel_noise`` in sqrt(rad), >= 0. ValueError for a step that
    turns the body by more than ``MAX_STEP_TURN_RAD``.
    """
    twist = diff_drive.body_twist(dphi_left, dphi_right)
    u, omega = twist.vx, twist.omega
    if not abs(omega) <= MAX_STEP_TURN_RAD:
        raise ValueError(
            f"a step turning the body by {omega!r} rad is not a motion (> {MAX_STEP_TURN_RAD} rad)"
        )
    r, d = diff_drive.wheel_radius, diff_drive.track_width
    q_left, q_right = wheel_noise**2 * abs(dphi_left), wheel_noise**2 * abs(dphi_right)
    # Q_v = M Q_w M^T with M = [[r/2, r/2], [-r/d, r/d]]
    var_v = 0.25 * r * r * (q_left + q_right)
    cov_vw = 0.5 * r * r / d * (q_right - q_left)
    var_w = r * r / (d * d) * (q_left + q_right)

    panels = max(1, math.ceil(abs(omega)))
    if panels == 1:
        s, weights = _NODES_ON_UNIT, _WEIGHTS_ON_UNIT
    else:
        s = ((np.arange(panels)[:, None] + _NODES_ON_UNIT) / panels).ravel()
        weights = np.tile(_WEIGHTS_ON_UNIT / panels, panels)
    heading = theta_rad + omega * s
    c, sn = np.cos(heading), np.sin(heading)
    # the rest of the arc from s to 1 in the frame of heading(s): u (1 - s) [sin(w)/w, (1 - cos(w))/w],
    # w = omega (1 - s) (in closed form u [sin(w), 2 sin^2(w/2)] / omega, without cancellation)
    rest = 1.0 - s
    if omega == 0.0:
        along, across = u * rest, 0.0 * rest
    else:
        half = (0.5 * omega) * rest
        along = (u / omega) * np.sin(2.0 * half)
        across = (2.0 * u / omega) * np.sin(half) ** 2
    # the columns of A(s), scaled by sqrt(w_i): a_v = [cos, sin, 0] (speed noise) and
    # a_w = [-dy, dx, 1] (turn-rate noise) with [dx, dy] = R(heading(s)) [along, across] = p(1) - p(s)
    root_w = np.sqrt(weights)
    V = np.empty((6, len(s)))
    V[0], V[1], V[2] = c * root_w, sn * root_w, 0.0
    V[3] = -(sn * along + c * across) * root_w
    V[4] = (c * along - sn * across) * root_w
    V[5] = root_w
    # all weighted second moments at once, M = sum_i w_i [a_v; a_w] [a_v; a_w]^T (exactly symmetric)
    M = V @ V.T
    # Q = var_v M_vv + cov_vw (M_vw + M_wv) + var_w M_ww
    return var_v * M[:3, :3] + cov_vw * (M[:3, 3:] + M[3:, :3]) + var_w * M[3:, 3:]
