"""turtlelib.estimation.range_bearing: the observation model, its inverse, their Jacobians, and the residual
wrap.

Every Jacobian is checked against central finite differences.
"""

import math

import numpy as np
import pytest
from finite_differences import central_jacobian, wrapping
from hypothesis import example, given
from hypothesis import strategies as st

from turtlelib import Transform2D, normalize_angle
from turtlelib.estimation.range_bearing import landmarks_from_observations, predict_observations, residual

PI = math.pi
LDS01 = Transform2D(-0.032, 0.0, 0.0)

coords_m = st.floats(-5.0, 5.0, allow_nan=False)
headings = st.floats(-PI, PI, allow_nan=False)
poses = st.builds(lambda x, y, t: np.array([x, y, t]), coords_m, coords_m, headings)
sensors = st.builds(Transform2D, st.floats(-0.3, 0.3), st.floats(-0.3, 0.3), headings)
# a landmark at 0.2 .. 4 m from the sensor in any direction
offsets = st.builds(
    lambda r, a: np.array([r * math.cos(a), r * math.sin(a)]), st.floats(0.2, 4.0), st.floats(-PI, PI)
)
observations = st.builds(lambda r, b: np.array([r, b]), st.floats(0.1, 4.0), st.floats(-PI, PI))


def sensor_position(pose, sensor):
    return (Transform2D(*pose) @ sensor).translation


# --- observation model -------------------------------------------------------------------------------------


def test_observation_hand_cases():
    # robot at (1, 2) facing +y, sensor 0.032 m behind the centre: at (1, 1.968) facing +y
    pose = np.array([1.0, 2.0, 0.5 * PI])
    landmarks = np.array([[1.0, 3.968], [0.0, 1.968], [2.0, 1.968]])
    z_hat, _, _ = predict_observations(pose, landmarks, LDS01)
    np.testing.assert_allclose(z_hat[:, 0], [2.0, 1.0, 1.0], atol=1e-12)
    # straight ahead, to the left (+90 deg), to the right (-90 deg)
    expected = np.array([[2.0, 0.0], [1.0, 0.5 * PI], [1.0, -0.5 * PI]])
    np.testing.assert_allclose(residual(z_hat, expected), 0.0, atol=1e-12)


def test_observation_with_a_rotated_sensor():
    # a sensor turned by +90 deg at the body origin sees the body's +x axis at bearing -90 deg
    z_hat, _, _ = predict_observations(np.zeros(3), np.array([[2.0, 0.0]]), Transform2D(0.0, 0.0, 0.5 * PI))
    np.testing.assert_allclose(z_hat, [[2.0, -0.5 * PI]], atol=1e-15)


@given(poses, sensors, offsets)
def test_observation_jacobians_match_finite_differences(pose, sensor, offset):
    landmark = sensor_position(pose, sensor) + offset
    _, H_robot, H_landmark = predict_observations(pose, landmark[None], sensor)

    def h_of_pose(q):
        return predict_observations(q, landmark[None], sensor)[0][0]

    def h_of_landmark(m):
        return predict_observations(pose, m[None], sensor)[0][0]

    numeric_robot = central_jacobian(h_of_pose, pose, wrapping(1))
    numeric_landmark = central_jacobian(h_of_landmark, landmark, wrapping(1))
    np.testing.assert_allclose(H_robot[0], numeric_robot, rtol=0.0, atol=1e-6)
    np.testing.assert_allclose(H_landmark[0], numeric_landmark, rtol=0.0, atol=1e-6)


def test_observation_is_vectorised():
    rng = np.random.default_rng(1)
    pose = np.array([0.3, -0.2, 1.0])
    landmarks = rng.uniform(-3.0, 3.0, (7, 2))
    z_hat, H_robot, H_landmark = predict_observations(pose, landmarks, LDS01)
    for i, landmark in enumerate(landmarks):
        one = predict_observations(pose, landmark[None], LDS01)
        np.testing.assert_array_equal(z_hat[i], one[0][0])
        np.testing.assert_array_equal(H_robot[i], one[1][0])
        np.testing.assert_array_equal(H_landmark[i], one[2][0])


# --- inverse model -----------------------------------------------------------------------------------------


@given(poses, sensors, observations)
def test_inverse_model_inverts_the_observation(pose, sensor, z):
    p_map, _, _ = landmarks_from_observations(pose, z[None], sensor)
    z_hat, _, _ = predict_observations(pose, p_map, sensor)
    assert z_hat[0, 0] == pytest.approx(z[0], abs=1e-12)
    assert residual(z, z_hat[0])[1] == pytest.approx(0.0, abs=1e-12)


def test_inverse_model_hand_case():
    # robot at the origin facing +x, LDS-01 at x = -0.032: 1 m at +90 deg is (-0.032, 1)
    p_map, _, _ = landmarks_from_observations(np.zeros(3), np.array([[1.0, 0.5 * PI]]), LDS01)
    np.testing.assert_allclose(p_map, [[-0.032, 1.0]], atol=1e-15)


@given(poses, sensors, observations)
def test_inverse_model_jacobians_match_finite_differences(pose, sensor, z):
    _, G_robot, G_z = landmarks_from_observations(pose, z[None], sensor)

    def g_of_pose(q):
        return landmarks_from_observations(q, z[None], sensor)[0][0]

    def g_of_z(obs):
        return landmarks_from_observations(pose, obs[None], sensor)[0][0]

    np.testing.assert_allclose(G_robot[0], central_jacobian(g_of_pose, pose), rtol=0.0, atol=1e-6)
    np.testing.assert_allclose(G_z[0], central_jacobian(g_of_z, z), rtol=0.0, atol=1e-6)


# --- residual ----------------------------------------------------------------------------------------------


def test_residual_wraps_only_the_bearing():
    nu = residual(np.array([1.0, PI - 0.1]), np.array([0.5, -PI + 0.1]))
    np.testing.assert_allclose(nu, [0.5, -0.2], atol=1e-12)
    # ranges are never wrapped
    np.testing.assert_allclose(residual(np.array([10.0, 0.0]), np.array([0.0, 0.0])), [10.0, 0.0])


@given(st.floats(-100.0, 100.0), st.floats(-100.0, 100.0))
@example(PI, 0.0)
@example(-PI, 0.0)
@example(2.0 * PI, 0.0)
@example(-2.0 * PI, 0.0)
@example(3.0 * PI, 0.0)
@example(-3.0 * PI, 0.0)
@example(0.0, 3.0 * PI)
def test_residual_bearing_lies_in_half_open_interval(b, b_hat):
    nu = residual(np.array([1.0, b]), np.array([1.0, b_hat]))
    assert -PI < nu[1] <= PI
    # exactly the wrap of normalize_angle (its shortcuts for |b - b_hat| < 3 pi change no bit)
    assert nu[1] == normalize_angle(b - b_hat)


def test_residual_broadcasts_observations_against_landmarks():
    z = np.array([[1.0, 0.0], [2.0, 3.0]])
    z_hat = np.array([[1.0, 0.1], [1.5, -3.0], [0.5, 0.0]])
    nu = residual(z[:, None, :], z_hat[None, :, :])
    assert nu.shape == (2, 3, 2)
    np.testing.assert_allclose(nu[1, 1], [0.5, 6.0 - 2.0 * PI], atol=1e-12)


def test_residual_wraps_inputs_of_any_memory_layout():
    # column-major stacks (Fortran-ordered, as a transposed array is) are wrapped as row-major ones
    rng = np.random.default_rng(3)
    z, z_hat = rng.uniform(-3.0 * PI, 3.0 * PI, (2, 3, 4, 2))
    expected = residual(z.copy(), z_hat.copy())
    nu = residual(np.asfortranarray(z), np.asfortranarray(z_hat))
    np.testing.assert_array_equal(nu, expected)
    assert [normalize_angle(b) for b in (z - z_hat)[..., 1].ravel()] == nu[..., 1].ravel().tolist()


@pytest.mark.parametrize("bearing", [math.nan, math.inf])
def test_residual_rejects_non_finite_bearings(bearing):
    with pytest.raises(ValueError):
        residual(np.array([1.0, bearing]), np.array([1.0, 0.0]))
