"""Measurement models of EKF SLAM: how a sensor on the robot sees a 2D point landmark.

A measurement model is passed into :class:`turtlelib.estimation.ekf_slam.EkfSlam` like the motion model (and,
for a second sensor, into one update). It observes a point landmark ``m = [mx, my]`` (m, map frame) from the
robot pose ``q = [x, y, theta]`` (``T_map_body``) with a 2-vector ``z`` and gives the filter what it needs::

    predict:   z_hat = h(q, m),  H_robot = dh/dq,  H_landmark = dh/dm     (z = h(q, m) + v, v ~ N(0, R))
    inverse:   m = g(q, z),  G_robot = dg/dq,  G_z = dg/dz               (a landmark from one observation)
    residual:  nu = z (-) z_hat                                          (the one place angles are wrapped)
    noise:     the default R(z)

and which observations are usable at all (the sensor's range limits) and where the sensor is (the viewpoint
of correlated observation errors). Shapes: ``pose`` (3,), landmarks (k, 2), observations (K, 2), ``R``
(K, 2, 2), ``H_robot`` (k, 2, 3), ``H_landmark`` (k, 2, 2). A model whose ``h`` does not change when pose and
landmark move together rigidly (every relative measurement) keeps the consistency remedies of
:mod:`turtlelib.estimation.linearization` exact.

:class:`RangeBearing` is the LiDAR / landmark-sensor model of :mod:`turtlelib.estimation.range_bearing` with
its sensor mount ``T_body_sensor`` and its default noise.
"""

from __future__ import annotations

import math
from typing import Protocol

import numpy as np
from numpy.typing import NDArray

from ..geometry.se2 import Transform2D
from .range_bearing import landmarks_from_observations, predict_observations, residual


class MeasurementModel(Protocol):
    """What :class:`turtlelib.estimation.ekf_slam.EkfSlam` asks of a measurement model (module docstring)."""

    def predict(
        self, pose: NDArray[np.float64], p_map: NDArray[np.float64]
    ) -> tuple[NDArray[np.float64], NDArray[np.float64], NDArray[np.float64]]:
        """``(z_hat (k, 2), H_robot (k, 2, 3), H_landmark (k, 2, 2))`` of landmarks ``p_map`` (k, 2)."""
        ...

    def inverse(
        self, pose: NDArray[np.float64], z: NDArray[np.float64]
    ) -> tuple[NDArray[np.float64], NDArray[np.float64], NDArray[np.float64]]:
        """``(p_map (K, 2), G_robot (K, 2, 3), G_z (K, 2, 2))`` of observations ``z`` (K, 2)."""
        ...

    def residual(self, z: NDArray[np.float64], z_hat: NDArray[np.float64]) -> NDArray[np.float64]:
        """``nu = z (-) z_hat`` (..., 2); ``z`` and ``z_hat`` broadcast."""
        ...

    def noise(self, z: NDArray[np.float64]) -> NDArray[np.float64]:
        """The default ``R`` (K, 2, 2) of observations ``z`` (K, 2)."""
        ...

    def check(self, z: NDArray[np.float64]) -> None:
        """ValueError for finite observations ``z`` (K, 2) the model cannot take (e.g. a range <= 0)."""
        ...

    def usable(self, z: NDArray[np.float64]) -> NDArray[np.bool_]:
        """(K,) whether each observation lies where the sensor sees anything real (else rejected)."""
        ...

    def sensor_xy(self, pose: NDArray[np.float64]) -> NDArray[np.float64]:
        """The sensor's map position (2,) at robot pose ``pose`` (3,)."""
        ...


def range_bearing_noise(
    range_m: NDArray[np.float64], range_std: float, bearing_std: float, range_std_per_m: float = 0.0
) -> NDArray[np.float64]:
    """``R = diag((range_std + range_std_per_m r)^2, bearing_std^2)`` (K, 2, 2) at ranges ``range_m`` (K,)."""
    R = np.zeros((len(range_m), 2, 2))
    R[:, 0, 0] = (
        (range_std + range_std_per_m * np.asarray(range_m)) ** 2 if range_std_per_m > 0.0 else range_std**2
    )
    R[:, 1, 1] = bearing_std**2
    return R


class RangeBearing:
    """``z = [range_m, bearing_rad]`` of a point landmark from a sensor at ``T_body_sensor``
    (:mod:`turtlelib.estimation.range_bearing` has the model and its Jacobians).

    Default noise ``R = diag((range_std + range_std_per_m r)^2, bearing_std^2)``; observations with a range
    outside ``[min_range, max_range]`` (m) are not usable. The parameters are validated by
    :class:`turtlelib.estimation.ekf_slam.SlamConfig`, which builds this model from the slam node's
    parameters.
    """

    def __init__(
        self,
        T_body_sensor: Transform2D,
        range_std: float,
        bearing_std: float,
        range_std_per_m: float = 0.0,
        min_range: float = 0.0,
        max_range: float = math.inf,
    ) -> None:
        self.T_body_sensor = T_body_sensor
        self.range_std, self.bearing_std, self.range_std_per_m = range_std, bearing_std, range_std_per_m
        self.min_range, self.max_range = min_range, max_range

    def predict(
        self, pose: NDArray[np.float64], p_map: NDArray[np.float64]
    ) -> tuple[NDArray[np.float64], NDArray[np.float64], NDArray[np.float64]]:
        return predict_observations(pose, p_map, self.T_body_sensor)

    def inverse(
        self, pose: NDArray[np.float64], z: NDArray[np.float64]
    ) -> tuple[NDArray[np.float64], NDArray[np.float64], NDArray[np.float64]]:
        return landmarks_from_observations(pose, z, self.T_body_sensor)

    def residual(self, z: NDArray[np.float64], z_hat: NDArray[np.float64]) -> NDArray[np.float64]:
        return residual(z, z_hat)

    def noise(self, z: NDArray[np.float64]) -> NDArray[np.float64]:
        return range_bearing_noise(z[:, 0], self.range_std, self.bearing_std, self.range_std_per_m)

    def check(self, z: NDArray[np.float64]) -> None:
        if not (z[:, 0] > 0.0).all():
            raise ValueError("observed ranges must be > 0")

    def usable(self, z: NDArray[np.float64]) -> NDArray[np.bool_]:
        # min_range <= range <= max_range
        return (z[:, 0] >= self.min_range) & (z[:, 0] <= self.max_range)

    def sensor_xy(self, pose: NDArray[np.float64]) -> NDArray[np.float64]:
        # p + R(theta) [sensor_x, sensor_y]
        x, y, theta = pose[0], pose[1], pose[2]
        c, s = math.cos(theta), math.sin(theta)
        sx, sy = self.T_body_sensor.x, self.T_body_sensor.y
        return np.array([x + c * sx - s * sy, y + s * sx + c * sy])
