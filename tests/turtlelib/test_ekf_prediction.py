"""EKF SLAM prediction: the wheel-slip process noise (turtlelib.motion.wheel_noise) and EkfSlam.predict.

Hand-computed integrals for a straight line and a spin in place, rate independence (one step equals many
along the same arc), the first-order agreement with DiffDrive.step_jacobians, and Monte Carlo sampling of
the slip random walk for the pose covariance and the pose-landmark cross-covariance.
"""

import math

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from turtlelib import DiffDrive, Transform2D
from turtlelib.estimation.ekf_slam import EkfSlam, SlamConfig
from turtlelib.motion.arc_noise import MAX_STEP_TURN_RAD
from turtlelib.motion.motion_models import DiffDriveMotion
from turtlelib.motion.wheel_noise import wheel_slip_covariance

PI = math.pi
BURGER = DiffDrive(wheel_radius=0.033, track_width=0.16)
R_WHEEL, TRACK = 0.033, 0.16

wheel_rad = st.floats(-40.0, 40.0, allow_nan=False)
headings = st.floats(-PI, PI, allow_nan=False)


def filter_at(pose: Transform2D, pose_std=(0.01, 0.02, 0.03), wheel_noise=0.05) -> EkfSlam:
    config = SlamConfig(sensor_x=-0.032, confirm_count=1)
    slam = EkfSlam(config, DiffDriveMotion(BURGER, wheel_noise), pose)
    # a correlated, full-rank starting covariance
    A = np.array([[1.0, 0.3, -0.2], [0.0, 1.0, 0.5], [0.0, 0.0, 1.0]]) * np.array(pose_std)
    slam.reset(pose, A @ A.T, keep_map=True)
    return slam


# --- process noise: hand cases -----------------------------------------------------------------------------


def test_straight_line_noise_is_the_integrated_random_walk():
    # both wheels dphi from heading 0: u = r dphi, slip variance q = k^2 dphi per wheel,
    # Q_v = q M M^T = q diag(r^2/2, 2 r^2/d^2), A(s) = [[1, 0], [0, u (1 - s)], [0, 1]]
    k, dphi = 0.07, 12.0
    q, u = k * k * dphi, R_WHEEL * dphi
    var_v, var_w = q * R_WHEEL**2 / 2.0, 2.0 * q * R_WHEEL**2 / TRACK**2
    expected = np.array(
        [
            [var_v, 0.0, 0.0],
            [0.0, var_w * u * u / 3.0, var_w * u / 2.0],
            [0.0, var_w * u / 2.0, var_w],
        ]
    )
    Q = wheel_slip_covariance(BURGER, 0.0, dphi, dphi, k)
    np.testing.assert_allclose(Q, expected, rtol=1e-13, atol=1e-20)


@pytest.mark.parametrize("omega", [1e-3, 0.3, 0.999, 1.0, 2.5, 6.0])
def test_spin_in_place_noise(omega):
    # dphi = (-a, a) from heading 0: omega = 2 r a / d, u = 0, A(s) = [[cos, 0], [sin, 0], [0, 1]];
    # turtlelib.motion.arc_noise must match the hand-computed integrals to ~1e-13
    k = 0.05
    a = omega * TRACK / (2.0 * R_WHEEL)
    q = k * k * a
    var_v, var_w = q * R_WHEEL**2 / 2.0, 2.0 * q * R_WHEEL**2 / TRACK**2
    # integral_0^1 cos^2(w s) ds, sin^2, sin cos
    cc = 0.5 + math.sin(2.0 * omega) / (4.0 * omega)
    ss = 0.5 - math.sin(2.0 * omega) / (4.0 * omega)
    sc = math.sin(omega) ** 2 / (2.0 * omega)
    expected = np.array([[var_v * cc, var_v * sc, 0.0], [var_v * sc, var_v * ss, 0.0], [0.0, 0.0, var_w]])
    Q = wheel_slip_covariance(BURGER, 0.0, -a, a, k)
    np.testing.assert_allclose(Q, expected, rtol=1e-12, atol=1e-13 * np.abs(expected).max())


def test_no_motion_no_noise():
    np.testing.assert_array_equal(wheel_slip_covariance(BURGER, 0.4, 0.0, 0.0, 0.1), np.zeros((3, 3)))


@given(headings, wheel_rad, wheel_rad)
def test_noise_agrees_with_the_step_jacobian_to_first_order(theta, left, right):
    # For a short step the slip is, to first order, a constant wheel perturbation: Q ~ G_w Q_w G_w^T.
    # Shrinking the step by 1e-3 shrinks Q by 1e-3 and their difference (the u^2 terms) by 1e-9.
    k, scale = 0.05, 1e-3
    left, right = left * scale, right * scale
    _, G_wheels = BURGER.step_jacobians(theta, left, right)
    first_order = G_wheels @ np.diag([k * k * abs(left), k * k * abs(right)]) @ G_wheels.T
    Q = wheel_slip_covariance(BURGER, theta, left, right, k)
    norm = k * k * (abs(left) + abs(right)) * R_WHEEL**2 / TRACK**2
    np.testing.assert_allclose(Q, first_order, rtol=0.0, atol=1e-4 * norm + 1e-300)


def test_noise_is_symmetric_positive_semidefinite_for_large_turns():
    for left, right in [(0.0, 200.0), (-150.0, 150.0), (80.0, -3.0)]:
        Q = wheel_slip_covariance(BURGER, 1.0, left, right, 0.05)
        np.testing.assert_array_equal(Q, Q.T)
        assert np.linalg.eigvalsh(Q).min() > -1e-15 * np.abs(Q).max()


# --- prediction: rate independence and the robot-only touch -------------------------------------------------


@settings(deadline=None)
@given(headings, wheel_rad, wheel_rad, st.integers(2, 12))
def test_prediction_does_not_depend_on_the_rate(theta, left, right, n):
    start = Transform2D(0.5, -1.0, theta)
    one, many = filter_at(start), filter_at(start)
    one.predict((left, right))
    for _ in range(n):
        many.predict((left / n, right / n))
    np.testing.assert_allclose(many.pose.as_matrix(), one.pose.as_matrix(), rtol=0.0, atol=1e-10)
    scale = np.abs(one.pose_covariance).max()
    np.testing.assert_allclose(many.pose_covariance, one.pose_covariance, rtol=0.0, atol=1e-10 * scale)


def test_prediction_touches_only_robot_rows_and_columns():
    slam = filter_at(Transform2D(0.2, 0.1, 0.3))
    slam.update_known([4, 9], [[1.0, 0.3], [2.0, -1.0]])
    before = slam.covariance
    slam.predict((2.0, 3.0))
    after = slam.covariance
    np.testing.assert_array_equal(after[3:, 3:], before[3:, 3:])
    assert not np.allclose(after[:3, 3:], before[:3, 3:])
    np.testing.assert_array_equal(after, after.T)


# --- Monte Carlo -------------------------------------------------------------------------------------------


def sample_slip_walk(rng, poses, left, right, wheel_noise, substeps):
    """Drive every sampled pose (S, 3) along the step with independent slip on each of `substeps` parts."""
    x, y, theta = poses.T.copy()
    r, d = R_WHEEL, TRACK
    for _ in range(substeps):
        dl = left / substeps + rng.normal(0.0, wheel_noise * math.sqrt(abs(left) / substeps), len(x))
        dr = right / substeps + rng.normal(0.0, wheel_noise * math.sqrt(abs(right) / substeps), len(x))
        u, w = 0.5 * r * (dl + dr), r * (dr - dl) / d
        # exact arc: p += u R(theta) [sin(w)/w, (1 - cos(w))/w]
        along = u * np.sinc(w / PI)
        across = u * np.sin(0.5 * w) * np.sinc(w / (2.0 * PI))
        x += np.cos(theta) * along - np.sin(theta) * across
        y += np.sin(theta) * along + np.cos(theta) * across
        theta = theta + w
    return np.column_stack([x, y, theta])


def assert_covariance_matches(sample_cov, cov, tolerance):
    """|C_ij - P_ij| <= tolerance sqrt(P_ii P_jj): a correlation-scaled comparison."""
    std = np.sqrt(np.diag(cov))
    np.testing.assert_array_less(np.abs(sample_cov - cov) / np.outer(std, std), tolerance)


@pytest.mark.parametrize("left, right", [(30.0, 30.0), (20.0, 35.0), (-12.0, 12.0), (40.0, 5.0)])
def test_prediction_covariance_matches_monte_carlo(left, right):
    rng = np.random.default_rng(7)
    start = Transform2D(0.3, -0.4, 0.7)
    slam = filter_at(start, pose_std=(0.01, 0.01, 0.01), wheel_noise=0.04)
    # a landmark correlated with the pose, so the cross-covariance P_qm' = G P_qm is exercised
    slam.update_known([0], [[1.2, 0.4]])
    prior_mean, prior_cov = slam.state, slam.covariance
    slam.predict((left, right))

    n_samples = 20_000
    prior = rng.multivariate_normal(prior_mean, prior_cov, n_samples)
    moved = sample_slip_walk(rng, prior[:, :3], left, right, wheel_noise=0.04, substeps=100)
    joint = np.column_stack([moved, prior[:, 3:]])
    error = joint - slam.state
    error[:, 2] = np.remainder(error[:, 2] + PI, 2.0 * PI) - PI
    np.testing.assert_allclose(error.mean(axis=0), 0.0, atol=5e-3)
    # sampling error of a covariance over 20000 samples: ~ sqrt(2 / 20000) = 1 %
    assert_covariance_matches(np.cov(error.T), slam.covariance, tolerance=0.05)


def test_prediction_rejects_non_finite_increments_and_keeps_the_filter():
    slam = filter_at(Transform2D(0.2, 0.1, 0.3))
    slam.update_known([1], [[1.0, 0.3]])
    state, cov = slam.state, slam.covariance
    for bad in (math.nan, math.inf, -math.inf):
        with pytest.raises(ValueError):
            slam.predict((bad, 1.0))
        with pytest.raises(ValueError):
            slam.predict((1.0, bad))
    np.testing.assert_array_equal(slam.state, state)
    np.testing.assert_array_equal(slam.covariance, cov)


def test_a_turn_beyond_the_step_limit_is_refused_and_keeps_the_filter():
    # a wheel jump of 1e9 rad (a corrupt encoder reading) is not a motion
    slam = filter_at(Transform2D(0.2, 0.1, 0.3))
    state, cov = slam.state, slam.covariance
    with pytest.raises(ValueError, match="not a motion"):
        slam.predict((-1e9, 1e9))
    np.testing.assert_array_equal(slam.state, state)
    np.testing.assert_array_equal(slam.covariance, cov)
    # the largest turn it takes: omega = r / d (dphi_right - dphi_left) = MAX_STEP_TURN_RAD
    dphi = MAX_STEP_TURN_RAD * BURGER.track_width / BURGER.wheel_radius / 2.0
    assert np.isfinite(wheel_slip_covariance(BURGER, 0.0, -dphi, dphi, 0.05)).all()
