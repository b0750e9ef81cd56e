"""Range-bearing observations of 2D point landmarks from a sensor mounted on a planar robot.

Model
-----
Robot pose ``q = [x, y, theta]`` (``T_map_body``; m, m, rad), sensor mounted at
``T_body_sensor = (sx, sy, sphi)`` (the LDS-01 of a TurtleBot3 Burger at ``(-0.032, 0, 0)``), landmark
``m = [mx, my]`` (m, map frame). With ``R(theta)`` the rotation and ``t = R'(theta) [sx, sy]``::

    p_sensor = [x, y] + R(theta) [sx, sy]
    d = m - p_sensor,   rho^2 = d . d
    h(q, m) = [range_m, bearing_rad] = [rho, atan2(d_y, d_x) - theta - sphi]

The predicted bearing is left unwrapped: :func:`residual` is the one place where angle residuals are
wrapped. Jacobians (rows range, bearing)::

    H_landmark = dh/dm = [[ d_x / rho,    d_y / rho  ],
                          [-d_y / rho^2,  d_x / rho^2]]
    H_robot    = dh/dq = [-H_landmark,  -H_landmark t - [0, 1]^T]

The inverse observation model places a landmark seen at ``z = [r, b]``::

    g(q, z) = p_sensor + r [cos(phi), sin(phi)],   phi = theta + sphi + b
    G_robot = dg/dq = [I_2,  t + r [-sin(phi), cos(phi)]^T]
    G_z     = dg/dz = [[cos(phi), -r sin(phi)],
                       [sin(phi),  r cos(phi)]]

All functions are vectorised over landmarks / observations (leading axis).
"""

from __future__ import annotations

import math

import numpy as np
from numpy.typing import NDArray

from ..geometry.se2 import Transform2D


def _sensor_position(
    pose: NDArray[np.float64], T_body_sensor: Transform2D
) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
    """``p_sensor = [x, y] + R(theta) [sx, sy]`` and its heading derivative ``t = R'(theta) [sx, sy]``."""
    x, y, theta = pose.tolist()
    c, s = math.cos(theta), math.sin(theta)
    sx, sy = T_body_sensor.x, T_body_sensor.y
    p_sensor = np.array([x + c * sx - s * sy, y + s * sx + c * sy])
    dp_dtheta = np.array([-s * sx - c * sy, c * sx - s * sy])
    return p_sensor, dp_dtheta


def predict_observations(
    pose: NDArray[np.float64], p_map: NDArray[np.float64], T_body_sensor: Transform2D
) -> tuple[NDArray[np.float64], NDArray[np.float64], NDArray[np.float64]]:
    """``h(q, m)`` and its Jacobians for landmarks ``p_map`` (n, 2) seen from robot pose ``pose`` (3,).

    Returns ``(z_hat (n, 2) [range_m, bearing_rad], H_robot (n, 2, 3), H_landmark (n, 2, 2))``. Landmarks
    must not sit on the sensor (``rho > 0``).
    """
    p_sensor, dp_dtheta = _sensor_position(pose, T_body_sensor)
    # d = m - p_sensor
    d = p_map - p_sensor
    d_x, d_y = d[:, 0], d[:, 1]
    rho2 = d_x * d_x + d_y * d_y
    rho = np.sqrt(rho2)
    z_hat = np.empty_like(d)
    z_hat[:, 0] = rho
    # bearing = atan2(d_y, d_x) - theta - sphi
    np.subtract(np.arctan2(d_y, d_x), pose[2] + T_body_sensor.theta, out=z_hat[:, 1])

    # H_landmark = [[d_x/rho, d_y/rho], [-d_y/rho^2, d_x/rho^2]] = [d / rho; J d / rho^2], J d = [-d_y, d_x]
    H_landmark = np.empty((len(d), 2, 2))
    np.divide(d, rho[:, None], out=H_landmark[:, 0])
    np.divide(d[:, ::-1], rho2[:, None], out=H_landmark[:, 1])
    H_landmark[:, 1, 0] *= -1.0
    # H_robot = [-H_landmark, -H_landmark t - [0, 1]]
    H_robot = np.empty((len(d), 2, 3))
    np.negative(H_landmark, out=H_robot[:, :, :2])
    np.matmul(H_robot[:, :, :2], dp_dtheta, out=H_robot[:, :, 2])
    H_robot[:, 1, 2] -= 1.0
    return z_hat, H_robot, H_landmark


def landmarks_from_observations(
    pose: NDArray[np.float64], z: NDArray[np.float64], T_body_sensor: Transform2D
) -> tuple[NDArray[np.float64], NDArray[np.float64], NDArray[np.float64]]:
    """The inverse model ``g(q, z)`` for observations ``z`` (K, 2) [range_m, bearing_rad] from ``pose`` (3,).

    Returns ``(p_map (K, 2), G_robot (K, 2, 3), G_z (K, 2, 2))``.
    """
    p_sensor, dp_dtheta = _sensor_position(pose, T_body_sensor)
    range_m = z[:, 0]
    # phi = theta + sphi + b
    phi = pose[2] + T_body_sensor.theta + z[:, 1]
    c, s = np.cos(phi), np.sin(phi)
    # g = p_sensor + r [cos(phi), sin(phi)]
    p_map = p_sensor + range_m[:, None] * np.column_stack([c, s])

    # G_robot = [I, t + r [-sin(phi), cos(phi)]]
    G_robot = np.zeros((len(z), 2, 3))
    G_robot[:, 0, 0] = 1.0
    G_robot[:, 1, 1] = 1.0
    G_robot[:, 0, 2] = dp_dtheta[0] - range_m * s
    G_robot[:, 1, 2] = dp_dtheta[1] + range_m * c
    # G_z = [[cos(phi), -r sin(phi)], [sin(phi), r cos(phi)]]
    G_z = np.empty((len(z), 2, 2))
    G_z[:, 0, 0] = c
    G_z[:, 1, 0] = s
    G_z[:, 0, 1] = -range_m * s
    G_z[:, 1, 1] = range_m * c
    return p_map, G_robot, G_z


def residual(z: NDArray[np.float64], z_hat: NDArray[np.float64]) -> NDArray[np.float64]:
    """The innovation ``nu = z - z_hat`` (..., 2) with its bearing wrapped into (-pi, pi].

    The only place where range-bearing residual angles are wrapped; ``z`` and ``z_hat`` broadcast.
    """
    # a stack of stacks (gating's (K, n, 2)) is wrapped as one strided run of bearings: C order whatever the
    # inputs' layout, so that the flattened bearings are a view
    nu = np.subtract(z, z_hat, order="C")
    bearing = nu[..., 1] if nu.ndim < 3 else nu.reshape(-1, 2)[:, 1]
    # nu_bearing <- wrap(b - b_hat) as normalize_angles does it (exact): the remainder by 2 pi, then one
    # shift by 2 pi where it lies beyond pi (the others untouched). The remainder leaves |b| < 2 pi as it
    # is and takes 2 pi off 2 pi <= |b| < 3 pi exactly (Sterbenz), as the shift does: below 3 pi the
    # shift alone gives the same, and below pi (the usual case) nothing changes. NaN and inf fail both
    # bounds and are refused below.
    largest = np.abs(bearing).max() if bearing.size else 0.0
    if largest < math.pi:
        return nu
    if not largest < 3.0 * math.pi:
        if not np.isfinite(bearing).all():
            raise ValueError("angles must be finite")
        np.fmod(bearing, math.tau, out=bearing)
    np.subtract(bearing, math.tau, out=bearing, where=bearing > math.pi)
    np.add(bearing, math.tau, out=bearing, where=bearing <= -math.pi)
    return nu


def observations_from_points(
    p_sensor: NDArray[np.float64], covariance: NDArray[np.float64]
) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
    """Range-bearing observations of points measured in the sensor frame as Cartesian positions.

    ``p_sensor`` (K, 2) (m) with covariances ``covariance`` (K, 2, 2) (m^2), e.g. a landmark sensor that
    reports positions. With ``rho = |p|``::

        z = [rho, atan2(p_y, p_x)]
        J = dz/dp = [[ p_x / rho,    p_y / rho  ],
                     [-p_y / rho^2,  p_x / rho^2]]
        R = J Sigma J^T

    Returns ``(z (K, 2), R (K, 2, 2))``. ValueError for mismatched shapes, non-finite values or a point
    at the sensor's origin (``rho = 0``: no bearing).
    """
    p = np.asarray(p_sensor, dtype=np.float64)
    if p.size == 0:
        p = p.reshape(0, 2)
    if p.ndim != 2 or p.shape[1] != 2:
        raise ValueError(f"points must have shape (K, 2), got {p.shape}")
    sigma = np.asarray(covariance, dtype=np.float64)
    if sigma.shape != (len(p), 2, 2):
        raise ValueError(f"covariance must have shape ({len(p)}, 2, 2), got {sigma.shape}")
    if not (np.isfinite(p).all() and np.isfinite(sigma).all()):
        raise ValueError("points and covariances must be finite")
    rho2 = p[:, 0] * p[:, 0] + p[:, 1] * p[:, 1]
    if np.any(rho2 == 0.0):
        raise ValueError("a point at the sensor's origin has no bearing")
    rho = np.sqrt(rho2)
    # z = [rho, atan2(p_y, p_x)]
    z = np.column_stack([rho, np.arctan2(p[:, 1], p[:, 0])])
    # J = [[p_x / rho, p_y / rho], [-p_y / rho^2, p_x / rho^2]]
    J = np.empty((len(p), 2, 2))
    J[:, 0, 0] = p[:, 0] / rho
    J[:, 0, 1] = p[:, 1] / rho
    J[:, 1, 0] = -p[:, 1] / rho2
    J[:, 1, 1] = p[:, 0] / rho2
    # R = J Sigma J^T
    R = J @ sigma @ J.transpose(0, 2, 1)
    return z, 0.5 * (R + R.transpose(0, 2, 1))


def observations_in_sensor_frame(
    p_frame: NDArray[np.float64], R_frame: NDArray[np.float64], T_sensor_frame: Transform2D
) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
    """Points ``p_frame`` (K, 2) (m) observed in range and bearing about another frame's origin with noise
    ``R_frame`` (K, 2, 2), as range-bearing observations about the sensor's. With ``r = |p|`` the point's
    covariance is ``G R_frame G^T``, ``G = dp/dz = [[p_x / r, -p_y], [p_y / r, p_x]]``; moved into the
    sensor frame, ``p_sensor = T_sensor_frame p``, ``Sigma_sensor = C G R_frame G^T C^T`` (``C`` its
    rotation); then :func:`observations_from_points`. Returns ``(z (K, 2), R (K, 2, 2))``; ValueError as
    :func:`observations_from_points` (and for a point at the frame's origin)."""
    p = np.asarray(p_frame, dtype=np.float64).reshape(-1, 2)
    r = np.hypot(p[:, 0], p[:, 1])
    if np.any(r == 0.0):
        raise ValueError("a point at the frame's origin has no bearing")
    G = np.empty((len(p), 2, 2))
    G[:, 0, 0], G[:, 0, 1] = p[:, 0] / r, -p[:, 1]
    G[:, 1, 0], G[:, 1, 1] = p[:, 1] / r, p[:, 0]
    C = T_sensor_frame.rotation_matrix()
    # Sigma_sensor = C G R G^T C^T
    sigma = C @ G @ np.asarray(R_frame, dtype=np.float64) @ G.transpose(0, 2, 1) @ C.T
    return observations_from_points(T_sensor_frame @ p if len(p) else p, sigma)
