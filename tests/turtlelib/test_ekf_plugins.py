"""A measurement model and a matcher of the test's own plug into EkfSlam without touching it.

* ``CartesianSensor``: a sensor that reports a landmark's position in the body frame,
  ``z = R(theta)^T (m - p)``; the filter with it must be the EKF of that model, computed here densely
  (``K = P H^T S^-1``, Joseph form), to rounding, also when it is the second sensor of one update
  sequence beside the default range-bearing LiDAR.
* ``OptimalAssignment``: the minimum-cost assignment (Hungarian, scipy) instead of greedy nearest
  neighbour; in a scan where greedy pairs the first observation with the landmark the second one needs,
  the filter must follow the matcher it was given.
"""

from __future__ import annotations

import math

import numpy as np
from numpy.typing import NDArray
from scipy.optimize import linear_sum_assignment

from turtlelib import LandmarkMap, TwistNoise, UnicycleMotion
from turtlelib.estimation.association_policies import Gating, SlamView
from turtlelib.estimation.ekf_slam import EkfSlam, ObservationStatus, SlamConfig
from turtlelib.estimation.range_bearing import predict_observations, residual

MOTION = UnicycleMotion(TwistNoise(forward_m2_per_m=0.01, heading_rad2_per_m=0.01))
SIGMA_M = 0.05


class CartesianSensor:
    """``z = R(theta)^T (m - p)`` (body frame, m) with noise ``SIGMA_M^2 I``."""

    def predict(
        self, pose: NDArray[np.float64], p_map: NDArray[np.float64]
    ) -> tuple[NDArray[np.float64], NDArray[np.float64], NDArray[np.float64]]:
        c, s = math.cos(pose[2]), math.sin(pose[2])
        R_T = np.array([[c, s], [-s, c]])
        d = p_map - pose[:2]
        z_hat = d @ R_T.T
        H_landmark = np.broadcast_to(R_T, (len(d), 2, 2)).copy()
        H_robot = np.empty((len(d), 2, 3))
        H_robot[:, :, :2] = -R_T
        # d/dtheta R(theta)^T d = [[-s, c], [-c, -s]] d
        H_robot[:, :, 2] = d @ np.array([[-s, c], [-c, -s]]).T
        return z_hat, H_robot, H_landmark

    def inverse(
        self, pose: NDArray[np.float64], z: NDArray[np.float64]
    ) -> tuple[NDArray[np.float64], NDArray[np.float64], NDArray[np.float64]]:
        c, s = math.cos(pose[2]), math.sin(pose[2])
        rotation = np.array([[c, -s], [s, c]])
        rotated = z @ rotation.T
        G_robot = np.zeros((len(z), 2, 3))
        G_robot[:, 0, 0] = G_robot[:, 1, 1] = 1.0
        # d/dtheta R(theta) z = J R(theta) z
        G_robot[:, 0, 2], G_robot[:, 1, 2] = -rotated[:, 1], rotated[:, 0]
        return pose[:2] + rotated, G_robot, np.broadcast_to(rotation, (len(z), 2, 2)).copy()

    def residual(self, z: NDArray[np.float64], z_hat: NDArray[np.float64]) -> NDArray[np.float64]:
        return np.subtract(z, z_hat)

    def noise(self, z: NDArray[np.float64]) -> NDArray[np.float64]:
        return np.broadcast_to(SIGMA_M**2 * np.eye(2), (len(z), 2, 2)).copy()

    def check(self, z: NDArray[np.float64]) -> None:
        pass

    def usable(self, z: NDArray[np.float64]) -> NDArray[np.bool_]:
        return np.ones(len(z), dtype=bool)

    def sensor_xy(self, pose: NDArray[np.float64]) -> NDArray[np.float64]:
        return pose[:2].copy()


def dense_update(
    x: NDArray[np.float64], P: NDArray[np.float64], nu: NDArray[np.float64], H: NDArray[np.float64], R
) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
    """``x + K nu``, ``(I - K H) P (I - K H)^T + K R K^T`` with ``K = P H^T S^-1``, ``S = H P H^T + R``."""
    S = H @ P @ H.T + R
    K = np.linalg.solve(S, H @ P).T
    A = np.eye(len(x)) - K @ H
    return x + K @ nu, A @ P @ A.T + K @ R @ K.T


def test_a_measurement_model_of_its_own_is_the_dense_ekf_of_that_model():
    rng = np.random.default_rng(3)
    config = SlamConfig(initial_xy_std=0.1, initial_theta_std=0.05)
    sensor = CartesianSensor()
    slam = EkfSlam(config, MOTION, measurement=sensor)
    landmark = np.array([1.5, -0.7])

    # initialisation by the model's inverse: m = p + R z, P_mm = G_r P_qq G_r^T + G_z R G_z^T
    z0 = sensor.predict(np.zeros(3), landmark[None])[0] + rng.normal(0.0, SIGMA_M, (1, 2))
    assert slam.update_known([4], z0).status.tolist() == [ObservationStatus.NEW]
    P_qq = config.initial_pose_covariance()
    m0, G_robot, G_z = sensor.inverse(np.zeros(3), z0)
    x = np.concatenate([np.zeros(3), m0[0]])
    P = np.zeros((5, 5))
    P[:3, :3] = P_qq
    P[3:, :3] = G_robot[0] @ P_qq
    P[:3, 3:] = P[3:, :3].T
    P[3:, 3:] = G_robot[0] @ P_qq @ G_robot[0].T + SIGMA_M**2 * G_z[0] @ G_z[0].T
    np.testing.assert_allclose(slam.state, x, rtol=0.0, atol=1e-15)
    np.testing.assert_allclose(slam.covariance, P, rtol=0.0, atol=1e-15)

    # an update of the model's own
    z1 = sensor.predict(np.zeros(3), landmark[None])[0] + rng.normal(0.0, SIGMA_M, (1, 2))
    result = slam.update_known([4], z1)
    z_hat, H_robot, H_landmark = sensor.predict(x[:3], x[None, 3:])
    x, P = dense_update(x, P, (z1 - z_hat)[0], np.hstack([H_robot[0], H_landmark[0]]), SIGMA_M**2 * np.eye(2))
    assert result.status.tolist() == [ObservationStatus.MATCHED]
    np.testing.assert_allclose(slam.state, x, rtol=0.0, atol=1e-13)
    np.testing.assert_allclose(slam.covariance, P, rtol=0.0, atol=1e-13)

    # a second sensor, for one update: the filter's default range-bearing model
    z2, _, _ = predict_observations(np.zeros(3), landmark[None], config.T_body_sensor)
    R2 = config.observation_covariances(z2[:, 0])
    slam.update_known([4], z2, R2, measurement=config.measurement_model())
    z_hat, H_robot, H_landmark = predict_observations(x[:3], x[None, 3:], config.T_body_sensor)
    x, P = dense_update(x, P, residual(z2, z_hat)[0], np.hstack([H_robot[0], H_landmark[0]]), R2[0])
    np.testing.assert_allclose(slam.state, x, rtol=0.0, atol=1e-13)
    np.testing.assert_allclose(slam.covariance, P, rtol=0.0, atol=1e-13)


class OptimalAssignment:
    """The compatible pairs of least total ``D2 + ln det S`` (scipy's linear_sum_assignment)."""

    def match(
        self, gating: Gating, compatible: NDArray[np.bool_], R: NDArray[np.float64], view: SlamView
    ) -> NDArray[np.int64]:
        cost = np.where(compatible, gating.d2 + gating.log_det, 1e9)
        rows, columns = linear_sum_assignment(cost)
        match = np.full(len(compatible), -1, dtype=np.int64)
        kept = compatible[rows, columns]
        match[rows[kept]] = columns[kept]
        return match


def test_a_matcher_of_its_own_decides_the_pairs():
    # two mapped landmarks 2 m ahead, 0.1 rad apart (2.5 bearing sigmas); observation 0 lies near landmark 0
    # and within the gate of landmark 1, observation 1 within the gate of landmark 0 only
    config = SlamConfig(bearing_std=0.04, range_std=0.02)
    xy = 2.0 * np.array([[1.0, 0.0], [math.cos(0.1), math.sin(0.1)]])
    landmark_map = LandmarkMap("map", 0, np.array([10, 11]), xy, 1e-10 * np.eye(4))
    z = np.array([[2.0, 0.02], [2.0, -0.05]])

    greedy = EkfSlam(config, MOTION)
    greedy.load_map(landmark_map)
    # nearest neighbour pairs the closest pair first and leaves observation 1 nothing it may join
    result = greedy.update_unknown(z, stamp_ns=0)
    assert result.status.tolist() == [ObservationStatus.MATCHED, ObservationStatus.REJECTED]
    assert result.landmark_ids.tolist() == [10, -1]

    optimal = EkfSlam(config, MOTION, matcher=OptimalAssignment())
    optimal.load_map(landmark_map)
    result = optimal.update_unknown(z, stamp_ns=0)
    assert result.status.tolist() == [ObservationStatus.MATCHED, ObservationStatus.MATCHED]
    assert result.landmark_ids.tolist() == [11, 10]


def test_association_counts_tally_the_statuses():
    result = EkfSlam(SlamConfig(confirm_count=1), MOTION).update_unknown(
        [[1.0, 0.0], [1.0, 0.001], [9.0, 0.0], [2.0, 1.0]], stamp_ns=0
    )
    # two new landmarks, one observation on the spot of the first, one beyond max_range
    assert result.counts == {"matched": 0, "new": 2, "rejected": 2, "unmapped": 0}
