"""Known-association batches for the tests that compare the fast filter with a dense textbook one
(test_ekf_update: the standard EKF; test_ekf_invariant: the right-invariant EKF).

A dense reference has ``update(ids, z, R)`` for landmarks it holds and ``augment(landmark_id, z, R)`` for a
new one; :func:`fuse_known_batch` feeds one batch to both filters the same way. Both build their update
from :func:`stacked_observations` and their new landmarks by :func:`augmented`, in standard coordinates
``x = [x, y, theta, m_0x, m_0y, ...]`` with the landmarks in creation order.
"""

import numpy as np

from turtlelib import Transform2D
from turtlelib.estimation.ekf_slam import Association, EkfSlam, ObservationStatus
from turtlelib.estimation.range_bearing import landmarks_from_observations, predict_observations, residual


def stacked_observations(x, order: list[int], ids, z, R, sensor: Transform2D):
    """The stacked update of observations ``z`` (K, 2) of landmarks ``ids`` (``order``: the ids in state
    order) from the mean ``x`` (N,): ``H`` (2K, N), the innovation ``nu`` (2K,) and ``blockdiag(R_k)``."""
    N, K = len(x), len(ids)
    H = np.zeros((2 * K, N))
    nu = np.zeros(2 * K)
    R_full = np.zeros((2 * K, 2 * K))
    for k, landmark_id in enumerate(ids):
        i = 3 + 2 * order.index(landmark_id)
        z_hat, H_robot, H_landmark = predict_observations(x[:3], x[None, i : i + 2], sensor)
        H[2 * k : 2 * k + 2, :3] = H_robot[0]
        H[2 * k : 2 * k + 2, i : i + 2] = H_landmark[0]
        nu[2 * k : 2 * k + 2] = residual(z[k], z_hat[0])
        R_full[2 * k : 2 * k + 2, 2 * k : 2 * k + 2] = R[k]
    return H, nu, R_full


def augmented(x, P, z, R, sensor: Transform2D):
    """``(x, P)`` (standard coordinates) with a landmark initialised from observation ``z`` (2,) with noise
    ``R`` (2, 2) by the inverse model, its full cross-covariance included."""
    N = len(x)
    p_map, G_robot, G_z = landmarks_from_observations(x[:3], z[None], sensor)
    G_x = np.zeros((2, N))
    G_x[:, :3] = G_robot[0]
    P_new = np.zeros((N + 2, N + 2))
    P_new[:N, :N] = P
    P_new[N:, :N] = G_x @ P
    P_new[:N, N:] = P_new[N:, :N].T
    P_new[N:, N:] = G_x @ P @ G_x.T + G_z[0] @ R @ G_z[0].T
    return np.concatenate([x, p_map[0]]), P_new


def random_noise(rng, count):
    """Per-observation noise covariances with different scales and correlations."""
    R = np.empty((count, 2, 2))
    for k in range(count):
        A = rng.normal(size=(2, 2)) * [[0.03], [0.02]]
        R[k] = A @ A.T + np.diag([1e-4, 1e-4])
    return R


def fuse_known_batch(slam: EkfSlam, dense, seen: set[int], ids, z, R) -> Association:
    """``slam.update_known(ids, z, R)`` and the same batch into ``dense``: the ids in ``seen`` update, the
    others are added (and join ``seen``); checks that the filter matched exactly the seen ids. Returns the
    filter's association."""
    result = slam.update_known(ids, z, R)
    old = np.array([int(i) in seen for i in ids], dtype=bool)
    np.testing.assert_array_equal(
        result.status, np.where(old, ObservationStatus.MATCHED, ObservationStatus.NEW)
    )
    if old.any():
        dense.update(ids[old], z[old], R[old])
    for k in np.flatnonzero(~old):
        dense.augment(int(ids[k]), z[k], R[k])
        seen.add(int(ids[k]))
    return result
