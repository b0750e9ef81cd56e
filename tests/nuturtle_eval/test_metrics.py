"""Unit tests of nuturtle_eval.metrics: hand-computed cases, properties, Monte Carlo NEES."""

import math

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from nuturtle_eval.metrics import (
    PoseSeries,
    RunData,
    associate_landmarks,
    ate_rmse,
    ate_rmse_aligned,
    evaluate_run,
    landmarks_within_range,
    nees_band,
    odom_in_world,
    pose_errors,
    pose_nees,
)
from turtlelib import Transform2D

finite = st.floats(-10.0, 10.0, allow_nan=False)


def test_pose_series_rejects_bad_input():
    with pytest.raises(ValueError, match="stamps but"):
        PoseSeries(np.array([0.0, 1.0]), np.zeros((3, 3)))
    with pytest.raises(ValueError, match="increasing"):
        PoseSeries(np.array([0.0, 0.0]), np.zeros((2, 3)))
    with pytest.raises(ValueError, match="finite"):
        PoseSeries(np.array([0.0, 1.0]), np.array([[0.0, 0.0, np.nan], [0.0, 0.0, 0.0]]))


def test_interpolate_hand_computed_and_across_the_angle_wrap():
    series = PoseSeries(np.array([0.0, 1.0]), np.array([[0.0, 0.0, 0.0], [1.0, 2.0, 0.2]]))
    np.testing.assert_allclose(series.interpolate(np.array([0.5])), [[0.5, 1.0, 0.1]], atol=1e-12)
    # 3.1 -> -3.1 is a turn of 2 pi - 6.2 through pi, not -6.2 through 0
    wrapping = PoseSeries(np.array([0.0, 1.0]), np.array([[0.0, 0.0, 3.1], [0.0, 0.0, -3.1]]))
    (theta,) = wrapping.interpolate(np.array([0.5]))[:, 2]
    assert abs(abs(theta) - math.pi) < 1e-12
    with pytest.raises(ValueError, match="within"):
        series.interpolate(np.array([1.5]))


@given(st.lists(st.tuples(finite, finite, st.floats(-3.0, 3.0)), min_size=2, max_size=20))
def test_interpolate_at_own_stamps_returns_own_poses(rows):
    poses = np.array(rows)
    series = PoseSeries(np.arange(len(rows), dtype=float), poses)
    np.testing.assert_allclose(series.interpolate(series.t_s), poses, atol=1e-9)


def test_odom_in_world_composes_with_the_start_pose():
    odom = PoseSeries(np.array([0.0, 1.0]), np.array([[0.0, 0.0, 0.0], [1.0, 0.0, 0.3]]))
    world = odom_in_world(odom, Transform2D(1.0, 2.0, math.pi / 2))
    np.testing.assert_allclose(
        world.poses, [[1.0, 2.0, math.pi / 2], [1.0, 3.0, math.pi / 2 + 0.3]], atol=1e-12
    )


def test_pose_errors_and_ate_hand_computed():
    truth = PoseSeries(
        np.array([0.0, 1.0, 2.0]), np.array([[0.0, 0.0, 3.1], [1.0, 0.0, 3.1], [2.0, 0.0, 3.1]])
    )
    estimate = PoseSeries(
        np.array([0.5, 2.0, 3.0]), np.array([[0.5, 0.0, 3.1], [5.0, 4.0, -3.1]] + [[0.0, 0.0, 0.0]])
    )
    e = pose_errors(estimate, truth)
    # the estimate at t = 3 s lies beyond the truth and is left out
    assert e.shape == (2, 3)
    np.testing.assert_allclose(e, [[0.0, 0.0, 0.0], [3.0, 4.0, 2 * math.pi - 6.2]], atol=1e-12)
    # sqrt((0 + 25) / 2)
    assert ate_rmse(e) == pytest.approx(math.sqrt(12.5), abs=1e-12)
    with pytest.raises(ValueError):
        ate_rmse(np.zeros((0, 3)))


def test_aligned_ate_removes_a_rigid_motion_and_keeps_what_none_explains():
    t = np.arange(4.0)
    truth = PoseSeries(t, np.array([[0, 0, 0], [1, 0, 0], [1, 1, 0], [0, 1, 0]], dtype=float))
    T = Transform2D(3.0, -2.0, 1.0)
    moved = PoseSeries(t, np.array([(T @ Transform2D(*pose)).as_array() for pose in truth.poses]))
    assert ate_rmse(pose_errors(moved, truth)) > 1.0
    assert ate_rmse_aligned(moved, truth) == pytest.approx(0.0, abs=1e-12)
    # a square 1.2 times as large: the best rigid fit leaves 0.1 m at each corner (the centroids coincide)
    scaled = PoseSeries(t, np.column_stack([1.2 * truth.xy - 0.1, truth.poses[:, 2]]))
    assert ate_rmse_aligned(scaled, truth) == pytest.approx(0.1 * math.sqrt(2.0))
    assert math.isnan(ate_rmse_aligned(PoseSeries(t[:1], truth.poses[:1]), truth))


def test_association_hand_case_with_duplicate_and_spurious():
    true_xy = np.array([[0.0, 0.0], [1.0, 0.0], [0.0, 1.0]])
    mapped_xy = np.array([[1.02, 0.0], [0.0, 0.03], [3.0, 3.0], [0.99, 0.05]])
    association = associate_landmarks(mapped_xy, true_xy, gate_m=0.2)
    pairs = dict(zip(association.mapped_index.tolist(), association.true_index.tolist(), strict=True))
    assert pairs == {0: 1, 1: 0}
    assert association.spurious.tolist() == [2]
    assert association.duplicates.tolist() == [3]
    assert association.rmse_m == pytest.approx(math.sqrt((0.02**2 + 0.03**2) / 2), abs=1e-12)
    with pytest.raises(ValueError, match="gate"):
        associate_landmarks(mapped_xy, true_xy, gate_m=0.0)


def test_association_of_nothing():
    association = associate_landmarks(np.zeros((0, 2)), np.array([[0.0, 0.0]]), gate_m=0.2)
    assert association.true_index.size == 0 and math.isnan(association.rmse_m)
    association = associate_landmarks(np.array([[0.0, 0.0]]), np.zeros((0, 2)), gate_m=0.2)
    assert association.spurious.tolist() == [0]


@settings(max_examples=50)
@given(st.integers(1, 12), st.integers(0, 2**32 - 1))
def test_association_recovers_a_noisy_permutation(n, seed):
    rng = np.random.default_rng(seed)
    # centres on a 0.5 m grid, mapped with 2 cm noise: the Hungarian pairs are the permutation
    true_xy = 0.5 * rng.permutation(np.array([(i, j) for i in range(4) for j in range(4)], dtype=float))[:n]
    order = rng.permutation(n)
    mapped_xy = true_xy[order] + rng.uniform(-0.02, 0.02, size=(n, 2))
    association = associate_landmarks(mapped_xy, true_xy, gate_m=0.2)
    assert association.spurious.size == 0 and association.duplicates.size == 0
    np.testing.assert_array_equal(association.true_index, order[association.mapped_index])
    assert association.mapped_index.size == n


def test_landmarks_within_range():
    true_xy = np.array([[0.0, 2.0], [5.0, 0.0], [1.0, 1.0]])
    path_xy = np.array([[0.0, 0.0], [1.0, 0.0]])
    assert landmarks_within_range(true_xy, path_xy, 1.5).tolist() == [False, False, True]
    assert landmarks_within_range(true_xy, path_xy, 2.0).tolist() == [True, False, True]
    assert not landmarks_within_range(true_xy, np.zeros((0, 2)), 10.0).any()
    # one range per landmark (closest approaches 2, 4, 1 m)
    assert landmarks_within_range(true_xy, path_xy, np.array([2.0, 3.9, 0.9])).tolist() == [
        True,
        False,
        False,
    ]


def test_pose_nees_monte_carlo_matches_chi2():
    rng = np.random.default_rng(4)
    A = rng.normal(size=(3, 3))
    P = A @ A.T + 0.1 * np.eye(3)
    k = 20000
    errors = rng.multivariate_normal(np.zeros(3), P, size=k)
    eps = pose_nees(errors, np.broadcast_to(P, (k, 3, 3)))
    # E[eps] = 3, Var[eps] = 6: the mean of 20000 is within 5 sigma = 5 sqrt(6 / 20000)
    assert abs(eps.mean() - 3.0) < 5 * math.sqrt(6.0 / k)
    low, high = nees_band()
    assert low == pytest.approx(0.2158, abs=1e-3) and high == pytest.approx(9.348, abs=1e-3)
    assert abs(np.mean((eps >= low) & (eps <= high)) - 0.95) < 0.01
    assert pose_nees(np.zeros((0, 3)), np.zeros((0, 3, 3))).size == 0


def test_pose_nees_of_a_singular_covariance_is_nan():
    P = np.stack([np.zeros((3, 3)), np.diag([1e-4, 1e-4, 1e-14]), np.diag([1e-4, 4e-4, 1e-6])])
    e = np.array([[0.0, 0.0, 0.0], [0.01, 0.0, 0.0], [0.01, 0.02, 0.001]])
    eps = pose_nees(e, P)
    assert np.isnan(eps[:2]).all()
    # 1 + 1 + 1
    assert eps[2] == pytest.approx(3.0, rel=1e-12)


def _circle(t_s, radius_m=0.5):
    phi = t_s / 5.0
    return np.column_stack([radius_m * np.sin(phi), radius_m * (1 - np.cos(phi)), phi])


def test_evaluate_run_on_a_synthetic_run():
    rng = np.random.default_rng(7)
    t_truth = np.arange(0.0, 60.0, 0.05)
    truth = PoseSeries(t_truth, _circle(t_truth))
    # odometry: a heading that drifts linearly to 0.2 rad, as seen in its own frame started at T_world_start
    T_world_start = Transform2D(0.0, 0.0, 0.0)
    t_odom = t_truth[::2]
    odom_poses = _circle(t_odom) + np.column_stack([0.004 * t_odom, np.zeros_like(t_odom), 0.2 * t_odom / 60])
    odom = odom_in_world(PoseSeries(t_odom, odom_poses), T_world_start)
    # SLAM: the truth plus Gaussian errors drawn from its reported covariance
    t_slam = t_truth[1::4]
    sigmas = np.array([0.01, 0.01, 0.005])
    P = np.diag(sigmas**2)
    slam = PoseSeries(t_slam, _circle(t_slam) + rng.normal(0.0, sigmas, size=(t_slam.size, 3)))
    true_xy = np.array([[1.0, 0.5], [-1.0, 0.5], [4.0, 4.0]])
    mapped_xy = np.array([[1.01, 0.5], [-1.0, 0.52], [-0.98, 0.5], [0.0, -3.0]])
    data = RunData(truth, odom, slam, np.broadcast_to(P, (t_slam.size, 3, 3)), mapped_xy, true_xy, 1.5, 0.15)
    metrics = evaluate_run(data, sim_seconds=60.0, wall_seconds=20.0)
    # odometry's last sample (t = 59.9 s) is off by 0.004 * 59.9 m in x and 0.2 * 59.9 / 60 rad
    assert metrics.final_position_error_odom_m == pytest.approx(0.004 * 59.9, abs=1e-9)
    assert metrics.final_heading_error_odom_rad == pytest.approx(0.2 * 59.9 / 60, abs=1e-9)
    assert metrics.final_position_error_slam_m < 5 * 0.01
    assert metrics.ate_rmse_slam_m == pytest.approx(math.sqrt(2) * 0.01, rel=0.1)
    # the best rigid fit can only lower the error
    assert metrics.ate_rmse_aligned_slam_m <= metrics.ate_rmse_slam_m
    assert metrics.ate_rmse_aligned_odom_m <= metrics.ate_rmse_odom_m
    # relative error over 1-10 m of the true path: the drifting odometry's exceeds SLAM's unbiased noise
    assert metrics.rpe_pairs > 1000
    assert metrics.rpe_translation_odom_m > metrics.rpe_translation_slam_m
    assert metrics.rpe_rotation_odom_deg > metrics.rpe_rotation_slam_deg
    assert metrics.landmarks_true == 3 and metrics.landmarks_in_range == 2 and metrics.landmarks_mapped == 4
    assert metrics.landmarks_paired == 2 and metrics.landmarks_in_range_unmapped == 0
    assert metrics.landmarks_duplicate == 1 and metrics.landmarks_spurious == 1
    assert metrics.landmark_rmse_m == pytest.approx(math.sqrt((0.01**2 + 0.02**2) / 2), abs=1e-9)
    assert metrics.nees_pose_mean == pytest.approx(3.0, abs=0.5)
    assert metrics.nees_pose_within_95_fraction > 0.9
    d = metrics.as_dict()
    assert d["sim_seconds"] == 60.0 and d["wall_seconds"] == 20.0 and len(d["nees_pose_band_95"]) == 2
    with pytest.raises(ValueError, match="covariances"):
        RunData(truth, odom, slam, np.zeros((2, 3, 3)), mapped_xy, true_xy, 1.5, 0.15)
    # a run whose SLAM covariance is singular throughout (it ended before the robot moved) has no NEES
    singular = RunData(truth, odom, slam, np.zeros((t_slam.size, 3, 3)), mapped_xy, true_xy, 1.5, 0.15)
    unmeasured = evaluate_run(singular, sim_seconds=60.0, wall_seconds=20.0)
    assert math.isnan(unmeasured.nees_pose_mean) and math.isnan(unmeasured.nees_pose_within_95_fraction)
    assert unmeasured.ate_rmse_slam_m == metrics.ate_rmse_slam_m
    # without the true landmarks (a recording of another world) the map is counted, never judged
    unknown = RunData(truth, odom, slam, data.slam_covariances, mapped_xy, None, 1.5, 0.15)
    unjudged = evaluate_run(unknown, sim_seconds=60.0, wall_seconds=20.0)
    assert unjudged.landmarks_mapped == 4 and math.isnan(unjudged.landmark_rmse_m)
    for count in ("true", "in_range", "paired", "in_range_unmapped", "duplicate", "spurious"):
        assert getattr(unjudged, f"landmarks_{count}") is None, count
    assert unjudged.ate_rmse_slam_m == metrics.ate_rmse_slam_m


def test_a_landmark_hidden_behind_another_is_not_in_range():
    """Three cylinders of radius 0.15 m in a row along x = 1.1 (as in turtlebot3_world), seen from a path
    along that row: the two behind the first are hidden (the sight line to a centre passes 0 m from the
    first's centre); from (0, 0) the line to (1.1, 1.1) passes (1.1, 0) at 0.778 m and (1.1, -1.1) is far
    behind: all in sight; from (0.9, -2.2) the line to (1.1, 0) passes (1.1, -1.1) at 0.22 / sqrt(4.88) =
    0.0996 m < 0.15 m, and the line to (1.1, 1.1) passes (1.1, 0) at 0.22 / sqrt(10.93) = 0.0665 m."""
    true_xy = np.array([[1.1, -1.1], [1.1, 0.0], [1.1, 1.1]])
    radii = np.full(3, 0.15)
    row = np.array([[1.1, -2.2], [1.1, -2.5]])
    assert landmarks_within_range(true_xy, row, 4.0).tolist() == [True, True, True]
    assert landmarks_within_range(true_xy, row, 4.0, radii).tolist() == [True, False, False]
    assert landmarks_within_range(true_xy, np.array([[0.0, 0.0]]), 4.0, radii).tolist() == [True] * 3
    assert landmarks_within_range(true_xy, np.array([[0.9, -2.2]]), 4.0, radii).tolist() == [
        True,
        False,
        False,
    ]
    # a thinner first cylinder (0.05 m) no longer hides the second from there
    thin = np.array([0.05, 0.15, 0.15])
    assert landmarks_within_range(true_xy, np.array([[0.9, -2.2]]), 4.0, thin).tolist() == [True, True, False]
