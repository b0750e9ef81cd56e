"""Known-association batches for the tests that compare the fast filter with a dense textbook one
(test_ekf_update: the standard EKF; test_ekf_invariant: the right-invariant EKF).

A dense reference has ``update(ids, z, R)`` for landmarks it holds and ``augment(landmark_id, z, R)`` for a
new one; :func:`fuse_known_batch` feeds one batch to both filters the same way.
"""

import numpy as np

from turtlelib.ekf_slam import Association, EkfSlam, ObservationStatus


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
