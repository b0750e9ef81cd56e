"""Process noise of one motion step along a constant-twist arc, independent of how the motion is split.

Model
-----
A step moves the body for unit time ``s`` in [0, 1] at the constant body displacement twist
``xi = [omega, vx, vy]`` (rad, m, m: the twist over the step), from pose ``q = [x, y, theta]`` to
``q(1) = q (+) exp([xi])``. The twist is perturbed by white noise of intensity
``Sigma = Cov([dvx, dvy, domega])`` (per unit ``s``: the variances the whole step adds to the twist), with
``dvy`` independent of the others (``Sigma_vx_vy = Sigma_vy_omega = 0``). Through the linearised error
dynamics along the arc ``theta(s) = theta + omega s``, ``p(s)``::

    Q = integral_0^1 A(s) Sigma A(s)^T ds,   A(s) = [[cos(theta(s)), -sin(theta(s)), -(y(1) - y(s))],
                                                     [sin(theta(s)),  cos(theta(s)),   x(1) - x(s) ],
                                                     [0,              0,               1           ]]

(``A(s)`` is the transition ``[[1, 0, -dy], [0, 1, dx], [0, 0, 1]]`` from ``s`` to the step's end applied
to the noise input ``[R(theta(s)) [dvx, dvy], domega]``). Because these transitions compose and the
intensities of a noise proportional to travel, turn or time add up along the path, one step of a
constant-twist motion gives exactly the covariance of any number of shorter steps along it.

The integral is evaluated by composite Gauss-Legendre quadrature with ``GAUSS_LEGENDRE_NODES`` nodes per
radian of heading change (at least one panel), exact to ~1e-13 relative.
"""

from __future__ import annotations

import math

import numpy as np
from numpy.typing import NDArray

GAUSS_LEGENDRE_NODES = 8
# Largest heading change of one step (rad) the quadrature takes: a turn of more than a thousand rad between
# two readings is a corrupt reading, not a motion (and would need that many panels).
MAX_STEP_TURN_RAD = 1000.0
# Below this turn (rad) a step is straight: the arc's deviation from the line is below 1e-15 of its length,
# and the closed forms below would divide by a (subnormal) omega
STRAIGHT_TURN_RAD = 1e-15
# Gauss-Legendre nodes and weights mapped to [0, 1]: constants of the quadrature rule, not state.
_NODES_ON_UNIT, _WEIGHTS_ON_UNIT = np.polynomial.legendre.leggauss(GAUSS_LEGENDRE_NODES)
_NODES_ON_UNIT = 0.5 * (_NODES_ON_UNIT + 1.0)
_WEIGHTS_ON_UNIT = 0.5 * _WEIGHTS_ON_UNIT


def arc_covariance(
    theta_rad: float,
    omega: float,
    vx: float,
    vy: float,
    var_vx: float,
    cov_vx_omega: float,
    var_omega: float,
    var_vy: float = 0.0,
) -> NDArray[np.float64]:
    """The (3, 3) covariance of ``[x, y, theta]`` added by a step of twist ``[omega, vx, vy]`` from heading
    ``theta_rad``, for twist noise ``Sigma`` with entries ``var_vx``, ``cov_vx_omega``, ``var_omega``,
    ``var_vy`` (module docstring).

    ValueError for a step that turns the body by more than ``MAX_STEP_TURN_RAD``.
    """
    if not abs(omega) <= MAX_STEP_TURN_RAD:
        raise ValueError(
            f"a step turning the body by {omega!r} rad is not a motion (> {MAX_STEP_TURN_RAD} rad)"
        )
    panels = max(1, math.ceil(abs(omega)))
    if panels == 1:
        s, weights = _NODES_ON_UNIT, _WEIGHTS_ON_UNIT
    else:
        s = ((np.arange(panels)[:, None] + _NODES_ON_UNIT) / panels).ravel()
        weights = np.tile(_WEIGHTS_ON_UNIT / panels, panels)
    heading = theta_rad + omega * s
    c, sn = np.cos(heading), np.sin(heading)
    # the rest of the arc from s to 1 in the frame of heading(s): (1 - s) [[a, -b], [b, a]] [vx, vy] with
    # a = sin(w)/w, b = (1 - cos(w))/w, w = omega (1 - s) (in closed form [sin(w), 2 sin^2(w/2)] / omega,
    # without cancellation)
    rest = 1.0 - s
    if abs(omega) < STRAIGHT_TURN_RAD:
        along, across = vx * rest, vy * rest
    else:
        half = (0.5 * omega) * rest
        sine, versine = np.sin(2.0 * half), 2.0 * np.sin(half) ** 2
        along = (vx / omega) * sine
        across = (vx / omega) * versine
        if vy != 0.0:
            along = along - (vy / omega) * versine
            across = across + (vy / omega) * sine
    # the columns of A(s), scaled by sqrt(w_i): a_vx = [cos, sin, 0] (forward noise) and
    # a_w = [-dy, dx, 1] (turn noise) with [dx, dy] = R(heading(s)) [along, across] = p(1) - p(s)
    root_w = np.sqrt(weights)
    V = np.empty((6, len(s)))
    V[0], V[1], V[2] = c * root_w, sn * root_w, 0.0
    V[3] = -(sn * along + c * across) * root_w
    V[4] = (c * along - sn * across) * root_w
    V[5] = root_w
    # all weighted second moments at once, M = sum_i w_i [a_vx; a_w] [a_vx; a_w]^T (exactly symmetric)
    M = V @ V.T
    # Q = var_vx M_vv + cov_vx_omega (M_vw + M_wv) + var_omega M_ww
    Q = var_vx * M[:3, :3] + cov_vx_omega * (M[:3, 3:] + M[3:, :3]) + var_omega * M[3:, 3:]
    if var_vy != 0.0:
        # sideways noise along a_vy = [-sin, cos, 0]: Q += var_vy sum_i w_i a_vy a_vy^T
        lateral = np.vstack([-sn * root_w, c * root_w])
        Q[:2, :2] += var_vy * (lateral @ lateral.T)
    return Q
