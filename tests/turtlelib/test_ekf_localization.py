"""Localization against a fixed map (SlamConfig.mode = 'localization'): the Schmidt-Kalman update, loading and
exporting maps (EkfSlam.load_map / landmark_map), UNMAPPED observations.

The world (slam_world.py): a TurtleBot3 Burger drives one loop of a circle of radius 0.5 m among seven
landmarks (at least 0.6 m apart), its wheels slipping as the filter's model says, the LDS-01 reporting
range and bearing of every landmark within range with Gaussian noise, in random order. The map is
made by the same filter in mapping mode (known association, exact start pose), then the robot drives the
loop again localising against it. An eighth landmark, never mapped, is seen on the second drive only.
"""

import dataclasses
import functools
import math

import numpy as np
import pytest
from slam_world import CONFIG, MOTION, N_SCANS, PI, World

from turtlelib import MODES, LandmarkMap, Transform2D, load_map, save_map
from turtlelib.estimation.consistency import chi2_bounds, nees
from turtlelib.estimation.ekf_slam import EkfSlam, ObservationStatus, SlamConfig
from turtlelib.estimation.range_bearing import predict_observations, residual

LANDMARKS = np.array(
    [[1.2, 0.0], [0.9, 1.3], [-1.0, 0.6], [-0.6, -0.9], [0.6, -1.1], [-0.3, 1.7], [1.5, 0.6]]
)
UNMAPPED_LANDMARK = np.array([[-1.4, 1.6]])  # beyond gate_new of every mapped landmark, always in range
UNMAPPED_ID = 99
LOCALIZATION = dataclasses.replace(CONFIG, mode="localization")
START_COVARIANCE = np.diag([0.05**2, 0.05**2, 0.03**2])
MS = 1_000_000


@functools.cache
def mapped() -> LandmarkMap:
    """The map of one loop of SLAM with known association from the exact start pose (ids 0..6)."""
    slam = EkfSlam(CONFIG, MOTION)
    world = World(seed=1, landmarks=LANDMARKS)
    for _ in range(N_SCANS):
        world.step(slam)
        index, z = world.observe()
        slam.update_known(index, z)
    assert slam.landmark_ids.tolist() == list(range(len(LANDMARKS)))
    return slam.landmark_map("map", 123 * MS, {"linearization": CONFIG.linearization})


def pose_error(slam: EkfSlam, truth: Transform2D) -> np.ndarray:
    error = truth.as_array() - slam.pose.as_array()
    error[2] = math.remainder(error[2], 2.0 * PI)
    return error


def assert_map_unchanged(slam: EkfSlam, landmark_map: LandmarkMap) -> None:
    again = slam.landmark_map(landmark_map.frame_id, landmark_map.stamp_ns, landmark_map.parameters)
    assert again.equals(landmark_map)


def assert_symmetric_psd(P: np.ndarray) -> None:
    np.testing.assert_array_equal(P, P.T)
    assert np.linalg.eigvalsh(P).min() >= -1e-12 * np.abs(P).max()


def dense_schmidt(x, P, columns, z, R):
    """The textbook Schmidt update: stacked ``H`` (2k, N), ``K = P H^T S^-1`` with its landmark rows set to
    zero, ``x + K nu`` and the Joseph form ``(I - K H) P (I - K H)^T + K R K^T``. ``columns`` (k,): the
    state index of each observed landmark's x."""
    N, k = len(x), len(columns)
    H = np.zeros((2 * k, N))
    nu = np.zeros(2 * k)
    R_full = np.zeros((2 * k, 2 * k))
    for i, column in enumerate(columns):
        z_hat, H_robot, H_landmark = predict_observations(
            x[:3], x[None, column : column + 2], CONFIG.T_body_sensor
        )
        H[2 * i : 2 * i + 2, :3] = H_robot[0]
        H[2 * i : 2 * i + 2, column : column + 2] = H_landmark[0]
        nu[2 * i : 2 * i + 2] = residual(z[i], z_hat[0])
        R_full[2 * i : 2 * i + 2, 2 * i : 2 * i + 2] = R[i]
    S = H @ P @ H.T + R_full
    K = P @ H.T @ np.linalg.inv(S)
    K[3:] = 0.0
    x_new = x + K @ nu
    x_new[2] = math.remainder(x_new[2], 2.0 * PI)
    A = np.eye(N) - K @ H
    return x_new, A @ P @ A.T + K @ R_full @ K.T


# --- the config --------------------------------------------------------------------------------------------


def test_mode_defaults_to_mapping_and_is_checked():
    assert SlamConfig().mode == "mapping" and MODES == ("mapping", "localization")
    assert LOCALIZATION.mode == "localization"
    with pytest.raises(ValueError, match="mode must be one of"):
        SlamConfig(mode="navigation")
    assert int(ObservationStatus.UNMAPPED) == 3


# --- load_map and landmark_map -----------------------------------------------------------------------------


@pytest.mark.parametrize("config", [CONFIG, LOCALIZATION])
def test_load_map_then_landmark_map_is_bit_for_bit(config, tmp_path):
    landmark_map = mapped()
    save_map(tmp_path / "map.json", landmark_map)
    loaded = load_map(tmp_path / "map.json")
    slam = EkfSlam(config, MOTION)
    start = Transform2D(0.1, -0.2, 0.3)
    slam.load_map(loaded, start, START_COVARIANCE)
    assert_map_unchanged(slam, landmark_map)
    np.testing.assert_array_equal(slam.landmark_ids, landmark_map.ids)
    np.testing.assert_array_equal(slam.landmarks, landmark_map.xy)
    # P = blockdiag(P_pose, P_map)
    P = slam.covariance
    np.testing.assert_array_equal(P[:3, :3], START_COVARIANCE)
    np.testing.assert_array_equal(P[3:, 3:], landmark_map.covariance)
    assert not P[:3, 3:].any() and not P[3:, :3].any()
    np.testing.assert_array_equal(slam.state[:3], start.as_array())
    assert slam.tentative_ids.size == 0
    # the joint covariance carries the cross-covariances of SLAM
    assert np.abs(landmark_map.covariance[0, 2:]).max() > 0.0


def test_load_map_defaults_to_the_reset_pose_and_takes_any_id_order():
    slam = EkfSlam(dataclasses.replace(CONFIG, initial_xy_std=0.1), MOTION)
    covariance = np.diag([1e-4, 2e-4, 3e-4, 4e-4])
    landmark_map = LandmarkMap("map", 0, [7, 2], [[1.0, 2.0], [3.0, 4.0]], covariance)
    slam.load_map(landmark_map)
    np.testing.assert_array_equal(slam.pose.as_array(), np.zeros(3))
    np.testing.assert_array_equal(slam.pose_covariance, slam.config.initial_pose_covariance())
    # the public views are in id order
    np.testing.assert_array_equal(slam.landmark_ids, [2, 7])
    np.testing.assert_array_equal(slam.landmarks, [[3.0, 4.0], [1.0, 2.0]])
    exported = slam.landmark_map("map", 0)
    np.testing.assert_array_equal(exported.covariance, np.diag([3e-4, 4e-4, 1e-4, 2e-4]))


def test_load_map_refuses_too_many_landmarks_and_leaves_the_filter_unchanged():
    slam = EkfSlam(dataclasses.replace(CONFIG, max_landmarks=3), MOTION)
    slam.update_known([0], [[1.0, 0.2]])
    state, P = slam.state, slam.covariance
    with pytest.raises(ValueError, match="more than max_landmarks = 3"):
        slam.load_map(mapped())
    with pytest.raises(ValueError, match="must be a LandmarkMap"):
        slam.load_map({"ids": [0]})
    with pytest.raises(ValueError, match="T_map_body"):
        slam.load_map(LandmarkMap("map", 0, [], [], []), T_map_body=(0.0, 0.0, 0.0))
    np.testing.assert_array_equal(slam.state, state)
    np.testing.assert_array_equal(slam.covariance, P)


def test_an_empty_map_starts_ids_at_zero_and_the_filter_maps_on():
    slam = EkfSlam(dataclasses.replace(CONFIG, confirm_count=1), MOTION)
    slam.update_known([4], [[1.0, 0.2]])
    slam.load_map(LandmarkMap("map", 0, [], [], []))
    assert slam.landmark_ids.size == 0
    result = slam.update_unknown([[1.0, 0.2]], stamp_ns=0)  # the association mode is free again
    assert result.status.tolist() == [ObservationStatus.NEW] and result.landmark_ids.tolist() == [0]


def test_mapping_continues_from_a_loaded_map_with_new_ids_after_the_largest():
    landmark_map = LandmarkMap(
        "map", 0, [3, 10], [[1.0, 0.0], [0.0, 1.0]], np.diag([1e-4, 1e-4, 2e-4, 2e-4]).tolist()
    )
    # unknown association: a far observation starts landmark 11
    slam = EkfSlam(dataclasses.replace(CONFIG, confirm_count=1), MOTION)
    slam.load_map(landmark_map)
    z, _, _ = predict_observations(np.zeros(3), np.array([[1.0, 0.0], [-1.0, -1.0]]), CONFIG.T_body_sensor)
    result = slam.update_unknown(z, stamp_ns=0)
    assert result.status.tolist() == [ObservationStatus.MATCHED, ObservationStatus.NEW]
    assert result.landmark_ids.tolist() == [3, 11]
    assert slam.landmark_ids.tolist() == [3, 10, 11]
    # mapping refines the loaded landmarks
    assert slam.landmark_estimate(3)[1][0, 0] < 1e-4
    # known association observes the map's ids; a new id is a new landmark
    slam = EkfSlam(CONFIG, MOTION)
    slam.load_map(landmark_map)
    result = slam.update_known([10, 42], z)
    assert result.status.tolist() == [ObservationStatus.REJECTED, ObservationStatus.NEW]  # 10 is not at z[0]
    result = slam.update_known([3], z[:1])
    assert result.status.tolist() == [ObservationStatus.MATCHED]
    assert slam.landmark_ids.tolist() == [3, 10, 42]


# --- localization with known association ------------------------------------------------------------------


@pytest.mark.parametrize("linearization", ["standard", "fej", "oc"])
def test_localization_keeps_the_map_bit_for_bit_and_converges(linearization):
    landmark_map = mapped()
    slam = EkfSlam(dataclasses.replace(LOCALIZATION, linearization=linearization), MOTION)
    offset = Transform2D(0.08, -0.06, 0.04)
    slam.load_map(landmark_map, offset, np.diag([0.1**2, 0.1**2, 0.05**2]))
    world = World(seed=2, landmarks=np.vstack([LANDMARKS, UNMAPPED_LANDMARK]))
    ids = np.array([*range(len(LANDMARKS)), UNMAPPED_ID])
    errors, values = [], []
    for scan in range(N_SCANS):
        world.step(slam)
        index, z = world.observe()
        result = slam.update_known(ids[index], z)
        unmapped = ids[index] == UNMAPPED_ID
        assert unmapped.any()
        np.testing.assert_array_equal(result.status[unmapped], ObservationStatus.UNMAPPED)
        np.testing.assert_array_equal(result.landmark_ids[unmapped], -1)
        assert (result.status[~unmapped] == ObservationStatus.MATCHED).mean() > 0.9
        assert result.nis_dof == 2 * np.count_nonzero(result.status == ObservationStatus.MATCHED)
        if scan % 10 == 0:
            assert_map_unchanged(slam, landmark_map)
            assert_symmetric_psd(slam.covariance)
        errors.append(pose_error(slam, world.T_world_body))
        values.append(nees(errors[-1], slam.pose_covariance))
    assert_map_unchanged(slam, landmark_map)
    assert UNMAPPED_ID not in slam.landmark_ids and slam.tentative_ids.size == 0
    assert_symmetric_psd(slam.covariance)
    # from 0.1 m and 0.04 rad off (0.1 m and 0.05 rad standard deviations) to within the map's own error
    # (its heading is known to 0.019 rad), and the filter knows how well
    errors = np.array(errors)
    assert np.abs(errors[N_SCANS // 4 :, :2]).max() < 0.03
    assert np.abs(errors[N_SCANS // 4 :, 2]).max() < 0.05
    assert np.sqrt(slam.pose_covariance[[0, 1], [0, 1]]).max() < 0.01
    assert max(values[N_SCANS // 4 :]) < 21.1  # chi2_3^-1(0.9999)


def test_the_schmidt_update_equals_the_dense_textbook_update():
    landmark_map = mapped()
    config = dataclasses.replace(LOCALIZATION, gate_known=1.0)
    slam = EkfSlam(config, MOTION)
    slam.load_map(landmark_map, Transform2D(0.03, -0.02, 0.01), START_COVARIANCE)
    world = World(seed=3, landmarks=LANDMARKS)
    rng = np.random.default_rng(4)
    for _ in range(20):
        world.step(slam)
        index, z = world.observe()
        R = np.empty((len(z), 2, 2))
        for k in range(len(z)):  # different scales and correlations per observation
            A = rng.normal(size=(2, 2)) * [[0.03], [0.02]]
            R[k] = A @ A.T + np.diag([1e-4, 1e-4])
        x, P = slam.state, slam.covariance
        expected_x, expected_P = dense_schmidt(x, P, 3 + 2 * index, z, R)
        result = slam.update_known(index, z, R)
        assert (result.status == ObservationStatus.MATCHED).all()
        np.testing.assert_allclose(slam.state[:2], expected_x[:2], rtol=0.0, atol=1e-12)
        assert math.remainder(slam.state[2] - expected_x[2], 2.0 * PI) == pytest.approx(0.0, abs=1e-12)
        np.testing.assert_array_equal(slam.state[3:], x[3:])
        np.testing.assert_allclose(slam.covariance, expected_P, rtol=0.0, atol=1e-12)
        np.testing.assert_array_equal(slam.covariance[3:, 3:], P[3:, 3:])
        assert_symmetric_psd(slam.covariance)
        # the pose-map cross-covariance is estimated (the update correlates them)
        assert np.abs(slam.covariance[:3, 3:]).max() > 0.0


def test_the_schmidt_update_is_the_full_update_on_the_pose_when_the_map_is_exact():
    """With P_mm = 0 the landmarks are known: the optimal gain has zero landmark rows, so the Schmidt and
    the mapping update agree."""
    landmark_map = LandmarkMap("map", 0, [0, 1], [[1.0, 0.5], [-0.5, 1.5]], np.zeros((4, 4)))
    fixed, mapping = EkfSlam(LOCALIZATION, MOTION), EkfSlam(CONFIG, MOTION)
    for slam in (fixed, mapping):
        slam.load_map(landmark_map, Transform2D(0.05, 0.0, 0.02), START_COVARIANCE)
        slam.predict((3.0, 4.0))
    z, _, _ = predict_observations(np.array([0.1, 0.02, 0.05]), landmark_map.xy, CONFIG.T_body_sensor)
    a, b = fixed.update_known([0, 1], z), mapping.update_known([0, 1], z)
    assert a.nis == pytest.approx(b.nis, rel=1e-12)
    np.testing.assert_allclose(fixed.state, mapping.state, rtol=0.0, atol=1e-12)
    np.testing.assert_allclose(fixed.covariance, mapping.covariance, rtol=0.0, atol=1e-15)


def test_reset_keeping_the_map_relocalizes_in_localization():
    landmark_map = mapped()
    slam = EkfSlam(LOCALIZATION, MOTION)
    slam.load_map(landmark_map, Transform2D(), START_COVARIANCE)
    world = World(seed=5, landmarks=LANDMARKS)
    for _ in range(10):
        world.step(slam)
        slam.update_known(*world.observe())
    # kidnapped: the robot is carried elsewhere, the filter restarted near it with the map kept
    world.T_world_body = Transform2D(-0.3, 0.4, 2.0)
    slam.reset(Transform2D(-0.25, 0.37, 1.97), np.diag([0.1**2, 0.1**2, 0.05**2]), keep_map=True)
    assert_map_unchanged(slam, landmark_map)
    assert not slam.covariance[:3, 3:].any()
    for _ in range(20):
        world.step(slam)
        result = slam.update_known(*world.observe())
        assert (result.status == ObservationStatus.MATCHED).mean() > 0.5
    assert_map_unchanged(slam, landmark_map)
    assert np.abs(pose_error(slam, world.T_world_body)[:2]).max() < 0.03
    # reset without the map empties it: everything is unmapped then
    slam.reset(world.T_world_body)
    _, z = world.observe()
    result = slam.update_known(np.arange(len(z)), z)
    # unmapped, or rejected when the noise took the range past max_range
    assert set(result.status.tolist()) <= {ObservationStatus.UNMAPPED, ObservationStatus.REJECTED}
    assert (result.status == ObservationStatus.UNMAPPED).sum() >= len(z) - 1
    assert slam.landmark_ids.size == 0


# --- localization with unknown association ----------------------------------------------------------------


@pytest.mark.parametrize("matcher", ["nn", "jcbb"])
def test_unknown_association_localization_fuses_mapped_landmarks_only(matcher):
    landmark_map = mapped()
    slam = EkfSlam(dataclasses.replace(LOCALIZATION, matcher=matcher, confirm_count=1), MOTION)
    slam.load_map(landmark_map, Transform2D(0.05, -0.04, 0.03), np.diag([0.08**2, 0.08**2, 0.04**2]))
    world = World(seed=6, landmarks=np.vstack([LANDMARKS, UNMAPPED_LANDMARK]))
    shuffle = np.random.default_rng(7)
    matched = 0
    for scan in range(N_SCANS):
        world.step(slam)
        index, z = world.observe()
        order = shuffle.permutation(len(z))
        index, z = index[order], z[order]
        result = slam.update_unknown(z, stamp_ns=scan * 200 * MS)
        mapped_ones = index < len(LANDMARKS)
        is_matched = result.status == ObservationStatus.MATCHED
        # every match is the right landmark (the map's ids are the landmark indices)
        np.testing.assert_array_equal(result.landmark_ids[is_matched], index[is_matched])
        matched += int(is_matched.sum())
        assert not is_matched[~mapped_ones].any()
        np.testing.assert_array_equal(result.status[~mapped_ones], ObservationStatus.UNMAPPED)
        np.testing.assert_array_equal(result.landmark_ids[~mapped_ones], -1)
        assert result.confirmed_ids.size == 0 and result.dropped_ids.size == 0
        assert slam.tentative_ids.size == 0
    assert matched > 0.9 * N_SCANS * 4
    assert_map_unchanged(slam, landmark_map)
    assert_symmetric_psd(slam.covariance)
    assert np.abs(pose_error(slam, world.T_world_body)[:2]).max() < 0.03


def test_localization_without_a_map_adds_nothing():
    slam = EkfSlam(LOCALIZATION, MOTION)
    z = [[1.0, 0.2], [2.0, -1.0], [0.05, 0.0]]  # the last nearer than min_range
    result = slam.update_unknown(z, stamp_ns=0)
    assert result.status.tolist() == [ObservationStatus.UNMAPPED] * 2 + [ObservationStatus.REJECTED]
    assert result.landmark_ids.tolist() == [-1, -1, -1]
    assert slam.landmark_ids.size == 0 and slam.tentative_ids.size == 0
    np.testing.assert_array_equal(slam.covariance, np.zeros((3, 3)))


# --- consistency -------------------------------------------------------------------------------------------


def test_localization_pose_nees_is_consistent_when_the_map_error_is_drawn_from_its_covariance():
    """200 runs: the true map is the map estimate plus an error drawn from its joint covariance, the true
    start pose the estimate plus an error drawn from the start covariance; the pose NEES after a few steps
    averages to chi2_3 (the Schmidt update accounts for the map's uncertainty it does not estimate)."""
    landmark_map = mapped()
    config = dataclasses.replace(LOCALIZATION, gate_known=1.0)
    rng = np.random.default_rng(8)
    eigenvalues, vectors = np.linalg.eigh(landmark_map.covariance)
    map_root = vectors * np.sqrt(np.clip(eigenvalues, 0.0, None))
    pose_root = np.linalg.cholesky(START_COVARIANCE)
    start = Transform2D(0.0, 0.0, 0.0)
    n_runs, n_scans, checked = 200, 6, (2, 5)
    values = {scan: [] for scan in checked}
    for run in range(n_runs):
        true_map = landmark_map.xy + (map_root @ rng.normal(size=len(eigenvalues))).reshape(-1, 2)
        true_start = Transform2D(*(start.as_array() + pose_root @ rng.normal(size=3)))
        world = World(seed=1000 + run, landmarks=true_map, T_world_body=true_start)
        slam = EkfSlam(config, MOTION)
        slam.load_map(landmark_map, start, START_COVARIANCE)
        for scan in range(n_scans):
            world.step(slam)
            slam.update_known(*world.observe())
            if scan in checked:
                values[scan].append(nees(pose_error(slam, world.T_world_body), slam.pose_covariance))
    low, high = chi2_bounds(3, n_runs, 0.99)
    for scan in checked:
        assert low < np.mean(values[scan]) < high, (scan, np.mean(values[scan]), (low, high))


def test_a_large_loaded_map_outgrows_the_initial_storage_and_survives_a_dropped_tentative_landmark():
    rng = np.random.default_rng(9)
    n = 40
    A = rng.normal(0.0, 0.01, (2 * n, 2 * n))
    landmark_map = LandmarkMap(
        "map", 0, np.sort(rng.choice(1000, n, replace=False)), rng.uniform(5.0, 9.0, (n, 2)), A @ A.T / n
    )
    slam = EkfSlam(CONFIG, MOTION)
    slam.load_map(landmark_map, pose_covariance=START_COVARIANCE)
    assert_map_unchanged(slam, landmark_map)
    # a detection far from every landmark (all beyond max_range) starts a tentative landmark, which expires
    result = slam.update_unknown([[1.0, 0.3]], stamp_ns=0)
    assert result.status.tolist() == [ObservationStatus.NEW]
    assert result.landmark_ids.tolist() == [int(landmark_map.ids.max()) + 1]
    assert slam.tentative_ids.tolist() == result.landmark_ids.tolist()
    assert slam.update_unknown([], stamp_ns=3000 * MS).dropped_ids.tolist() == result.landmark_ids.tolist()
    assert_map_unchanged(slam, landmark_map)
    for landmark_id, xy in zip(landmark_map.ids, landmark_map.xy, strict=True):
        np.testing.assert_array_equal(slam.landmark_estimate(int(landmark_id))[0], xy)
