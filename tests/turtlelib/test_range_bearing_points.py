"""turtlelib.estimation.range_bearing.observations_from_points: Cartesian points with covariance to
range-bearing.

Hand cases, the Jacobian implied by R against central finite differences of z(p), Monte Carlo sampling of
R, vectorisation, and the ValueErrors.
"""

import math

import numpy as np
import pytest
from finite_differences import central_jacobian, wrapping
from hypothesis import given, settings
from hypothesis import strategies as st

from turtlelib import Transform2D
from turtlelib.estimation.range_bearing import observations_from_points, observations_in_sensor_frame

PI = math.pi


def z_of(p):
    return np.array([math.hypot(p[0], p[1]), math.atan2(p[1], p[0])])


def numeric_jacobian(p):
    """Central differences of z(p), the bearing difference wrapped (atan2 jumps by 2 pi across -x)."""
    return central_jacobian(z_of, p, wrapping(1))


# --- hand cases --------------------------------------------------------------------------------------------


def test_three_four_five():
    # p = (3, 4): rho = 5, bearing atan2(4, 3); J = [[3/5, 4/5], [-4/25, 3/25]] = [[0.6, 0.8], [-0.16, 0.12]]
    # Sigma = [[0.04, 0.01], [0.01, 0.09]]:
    #   Sigma J_1 = (0.032, 0.078), Sigma J_2 = (-0.0052, 0.0092)
    #   R_11 = 0.6 * 0.032 + 0.8 * 0.078 = 0.0816
    #   R_12 = 0.6 * -0.0052 + 0.8 * 0.0092 = 0.00424
    #   R_22 = -0.16 * -0.0052 + 0.12 * 0.0092 = 0.001936
    z, R = observations_from_points([[3.0, 4.0]], [[[0.04, 0.01], [0.01, 0.09]]])
    assert z.shape == (1, 2) and R.shape == (1, 2, 2)
    np.testing.assert_allclose(z[0], [5.0, math.atan2(4.0, 3.0)], rtol=0.0, atol=1e-15)
    np.testing.assert_allclose(R[0], [[0.0816, 0.00424], [0.00424, 0.001936]], rtol=1e-12, atol=0.0)


def test_isotropic_noise_gives_range_variance_and_bearing_variance_over_rho_squared():
    # Sigma = s^2 I: R = s^2 J J^T = diag(s^2, s^2 / rho^2) in any direction
    s2 = 1e-4
    points = np.array([[2.0, 0.0], [0.0, 2.0], [-1.0, 0.0], [0.0, -3.0], [-1.0, -1.0]])
    z, R = observations_from_points(points, np.broadcast_to(s2 * np.eye(2), (5, 2, 2)))
    np.testing.assert_allclose(z[:, 0], [2.0, 2.0, 1.0, 3.0, math.sqrt(2.0)], rtol=1e-15)
    np.testing.assert_allclose(z[:, 1], [0.0, 0.5 * PI, PI, -0.5 * PI, -0.75 * PI], rtol=0.0, atol=1e-15)
    rho2 = np.array([4.0, 4.0, 1.0, 9.0, 2.0])
    expected = np.zeros((5, 2, 2))
    expected[:, 0, 0] = s2
    expected[:, 1, 1] = s2 / rho2
    np.testing.assert_allclose(R, expected, rtol=1e-12, atol=1e-20)


def test_noise_along_the_ray_is_range_noise_across_it_is_bearing_noise():
    # the point (0, 2) (straight left) with 1 cm along y and 3 cm along x: range std 1 cm, bearing 3 cm / 2 m
    _, R = observations_from_points([[0.0, 2.0]], [np.diag([0.03**2, 0.01**2])])
    np.testing.assert_allclose(R[0], np.diag([0.01**2, (0.03 / 2.0) ** 2]), rtol=1e-12, atol=1e-20)


def test_no_points():
    z, R = observations_from_points(np.zeros((0, 2)), np.zeros((0, 2, 2)))
    assert z.shape == (0, 2) and R.shape == (0, 2, 2)


# --- the Jacobian behind R ---------------------------------------------------------------------------------

points = st.builds(
    lambda r, a: np.array([r * math.cos(a), r * math.sin(a)]), st.floats(0.1, 5.0), st.floats(-PI, PI)
)
# Sigma = L L^T from a lower-triangular L (stds 1 mm .. 10 cm, any correlation)
covariances = st.builds(
    lambda a, b, c: np.array([[a, 0.0], [b, c]]) @ np.array([[a, 0.0], [b, c]]).T,
    st.floats(1e-3, 0.1),
    st.floats(-0.1, 0.1),
    st.floats(1e-3, 0.1),
)


@settings(max_examples=200)
@given(points, covariances)
def test_R_is_J_Sigma_J_with_the_finite_difference_jacobian(p, sigma):
    z, R = observations_from_points(p[None], sigma[None])
    J = numeric_jacobian(p)
    expected = J @ sigma @ J.T
    scale = math.sqrt(expected[0, 0] * expected[1, 1])
    np.testing.assert_allclose(R[0], expected, rtol=1e-7, atol=1e-7 * scale)
    np.testing.assert_allclose(z[0], z_of(p), rtol=1e-14, atol=1e-15)
    np.testing.assert_array_equal(R[0], R[0].T)


@given(points)
def test_unit_covariances_recover_the_jacobian(p):
    # Sigma = e_i e_i^T gives R = J_i J_i^T (column i of J): its diagonal is the squared column
    J = numeric_jacobian(p)
    for i in range(2):
        sigma = np.zeros((2, 2))
        sigma[i, i] = 1.0
        _, R = observations_from_points(p[None], sigma[None])
        np.testing.assert_allclose(np.diag(R[0]), J[:, i] ** 2, rtol=1e-6, atol=1e-9 * np.abs(J).max() ** 2)
        np.testing.assert_allclose(R[0, 0, 1], J[0, i] * J[1, i], rtol=1e-6, atol=1e-9 * np.abs(J).max() ** 2)


def test_vectorised_equals_one_at_a_time():
    rng = np.random.default_rng(3)
    p = rng.uniform(-4.0, 4.0, (7, 2))
    L = rng.normal(0.0, 0.05, (7, 2, 2))
    sigma = L @ L.transpose(0, 2, 1)
    z, R = observations_from_points(p, sigma)
    for k in range(7):
        z_k, R_k = observations_from_points(p[k : k + 1], sigma[k : k + 1])
        np.testing.assert_allclose(z[k], z_k[0], rtol=1e-15, atol=0.0)
        np.testing.assert_allclose(R[k], R_k[0], rtol=1e-14, atol=0.0)


# --- Monte Carlo -------------------------------------------------------------------------------------------


@pytest.mark.parametrize("p", [(2.0, 1.0), (-0.5, -1.5), (-3.0, 0.01)])
def test_monte_carlo_covariance_of_range_and_bearing(p):
    # with 1 .. 2 cm noise at >= 1.5 m the linearisation error is ~(sigma / rho)^2 ~ 1e-4 relative; the
    # sampling error of a covariance entry with 200000 samples is ~ sqrt(2 / N) ~ 0.3 %: 2 % tolerance.
    # (-3.0, 0.01) straddles the -x axis: the bearing samples are wrapped about the mean bearing.
    rng = np.random.default_rng(20240611)
    p = np.array(p)
    sigma = np.array([[2.0e-4, -0.6e-4], [-0.6e-4, 1.0e-4]])
    z, R = observations_from_points(p[None], sigma[None])
    samples = rng.multivariate_normal(p, sigma, size=200_000)
    ranges = np.hypot(samples[:, 0], samples[:, 1])
    bearings = np.arctan2(samples[:, 1], samples[:, 0])
    bearings = z[0, 1] + np.remainder(bearings - z[0, 1] + PI, 2.0 * PI) - PI
    empirical = np.cov(np.stack([ranges, bearings]))
    scale = np.sqrt(np.outer(np.diag(R[0]), np.diag(R[0])))
    np.testing.assert_array_less(np.abs(empirical - R[0]), 0.02 * scale)
    # the means are z(p) up to 5 standard errors and the second-order bias (<= tr(Sigma) / rho, / rho^2)
    standard_errors = np.sqrt(np.diag(R[0]) / len(samples))
    rho, trace = z[0, 0], np.trace(sigma)
    assert abs(ranges.mean() - z[0, 0]) < 5.0 * standard_errors[0] + trace / rho
    assert abs(bearings.mean() - z[0, 1]) < 5.0 * standard_errors[1] + trace / rho**2


# --- errors ------------------------------------------------------------------------------------------------

GOOD_P = [[1.0, 2.0], [3.0, -1.0]]
GOOD_SIGMA = [np.eye(2) * 1e-4] * 2


@pytest.mark.parametrize(
    "p, sigma",
    [
        pytest.param(GOOD_P, GOOD_SIGMA[:1], id="too-few-covariances"),
        pytest.param(GOOD_P, [np.eye(2) * 1e-4] * 3, id="too-many-covariances"),
        pytest.param(GOOD_P, np.eye(2) * 1e-4, id="one-2x2-for-two-points"),
        pytest.param(GOOD_P, [np.eye(3) * 1e-4] * 2, id="3x3-covariances"),
        pytest.param([[1.0, 2.0, 0.0], [3.0, -1.0, 0.0]], [np.eye(2) * 1e-4] * 3, id="three-columns"),
        pytest.param([1.0, 2.0, 3.0, -1.0], GOOD_SIGMA, id="flat-points"),
        pytest.param([[1.0, 2.0, 3.0, -1.0]], GOOD_SIGMA, id="one-row-of-four"),
        pytest.param([1.0, 2.0], GOOD_SIGMA[:1], id="one-point-not-2d"),
        pytest.param([[math.nan, 2.0], [3.0, -1.0]], GOOD_SIGMA, id="nan-point"),
        pytest.param([[1.0, 2.0], [math.inf, -1.0]], GOOD_SIGMA, id="inf-point"),
        pytest.param(GOOD_P, [np.eye(2) * 1e-4, np.diag([math.nan, 1e-4])], id="nan-covariance"),
        pytest.param(GOOD_P, [np.eye(2) * 1e-4, np.diag([1e-4, math.inf])], id="inf-covariance"),
        pytest.param([[1.0, 2.0], [0.0, 0.0]], GOOD_SIGMA, id="point-at-the-origin"),
        pytest.param([[0.0, -0.0]], GOOD_SIGMA[:1], id="negative-zero-at-the-origin"),
    ],
)
def test_bad_input_raises(p, sigma):
    with pytest.raises(ValueError):
        observations_from_points(p, sigma)


# --- observations about another frame's origin --------------------------------------------------------


def test_in_the_sensor_frame_itself_the_observations_are_unchanged():
    p = np.array([[1.0, 2.0], [-3.0, 0.5]])
    R = np.array([np.diag([0.02**2, 0.01**2]), [[4e-4, 1e-5], [1e-5, 2e-4]]])
    z, R_sensor = observations_in_sensor_frame(p, R, Transform2D())
    np.testing.assert_allclose(z, np.column_stack([np.hypot(*p.T), np.arctan2(p[:, 1], p[:, 0])]), atol=1e-15)
    np.testing.assert_allclose(R_sensor, R, atol=1e-15)


def test_the_noise_about_another_origin_matches_monte_carlo():
    """Range-bearing noise about the body's origin, seen from a LiDAR 0.2 m behind it and turned 0.3 rad:
    the sampled observations' covariance is R (to first order: small noise)."""
    rng = np.random.default_rng(4)
    p_body = np.array([[1.5, 0.4]])
    R_body = np.array([np.diag([0.01**2, 0.005**2])])
    T_sensor_body = Transform2D(0.2, 0.0, 0.3).inverse()
    _, R = observations_in_sensor_frame(p_body, R_body, T_sensor_body)
    r, b = np.hypot(*p_body[0]), np.arctan2(p_body[0, 1], p_body[0, 0])
    samples = rng.multivariate_normal([r, b], R_body[0], size=40_000)
    points = np.column_stack([samples[:, 0] * np.cos(samples[:, 1]), samples[:, 0] * np.sin(samples[:, 1])])
    p_sensor = T_sensor_body @ points
    z = np.column_stack([np.hypot(*p_sensor.T), np.arctan2(p_sensor[:, 1], p_sensor[:, 0])])
    np.testing.assert_allclose(np.cov(z.T), R[0], rtol=0.03, atol=1e-9)


def test_a_point_at_the_frames_origin_is_refused():
    with pytest.raises(ValueError, match="origin"):
        observations_in_sensor_frame(np.zeros((1, 2)), np.eye(2)[None] * 1e-4, Transform2D())
