"""turtlelib.motion.arc_noise: the closed form of the arc's process noise against its defining integral.

The reference integrates ``A(s) Sigma A(s)^T`` over ``s`` in [0, 1] numerically (scipy's adaptive
quadrature), with ``A(s)`` built in the map frame from the arc ``p(s)`` itself, so it shares nothing with the
closed form's end-frame derivation or its series.
"""

import math

import numpy as np
import pytest
from hypothesis import given
from hypothesis import strategies as st
from scipy.integrate import quad

from turtlelib import Transform2D, Twist2D
from turtlelib.geometry.se2 import integrate_twist
from turtlelib.motion.arc_noise import MAX_STEP_TURN_RAD, SERIES_BELOW, arc_covariance, arc_covariances


def reference_covariance(theta, omega, vx, vy, var_vx, cov_vx_omega, var_omega, var_vy):
    """``integral_0^1 A(s) Sigma A(s)^T ds`` entry by entry (module docstring of
    turtlelib.motion.arc_noise)."""
    start = Transform2D(0.0, 0.0, theta)

    def position(s):
        return (start @ integrate_twist(Twist2D(omega * s, vx * s, vy * s))).as_array()[:2]

    end = position(1.0)
    Sigma = np.array([[var_vx, 0.0, cov_vx_omega], [0.0, var_vy, 0.0], [cov_vx_omega, 0.0, var_omega]])

    def integrand(s, i, j):
        heading = theta + omega * s
        rest = end - position(s)
        A = np.array(
            [
                [math.cos(heading), -math.sin(heading), -rest[1]],
                [math.sin(heading), math.cos(heading), rest[0]],
                [0.0, 0.0, 1.0],
            ]
        )
        return (A @ Sigma @ A.T)[i, j]

    limit = max(50, int(4 * abs(omega)))
    Q = np.empty((3, 3))
    for i in range(3):
        for j in range(i, 3):
            Q[i, j] = Q[j, i] = quad(
                integrand, 0.0, 1.0, args=(i, j), epsabs=1e-16, epsrel=1e-13, limit=limit
            )[0]
    return Q


TURNS = [0.0, 1e-300, 1e-9, 1e-4, 0.01, 0.3, 0.5 - 1e-9, 0.5, 0.5 + 1e-9, 0.9, 1.0 - 1e-9, 1.0, 1.0 + 1e-9]
TURNS += [1.7, math.pi, 6.0, 40.0]


@pytest.mark.parametrize("omega", TURNS + [-w for w in TURNS if w])
@pytest.mark.parametrize("vy", [0.0, -0.4])
def test_closed_form_is_the_integral(omega, vy):
    # both sides of the series' switch (|omega| or |2 omega| = SERIES_BELOW), straight, tiny and large turns
    args = (0.7, omega, 1.3, vy, 2e-3, -4e-4, 5e-3, 3e-4)
    Q = arc_covariance(*args)
    expected = reference_covariance(*args)
    np.testing.assert_allclose(Q, expected, rtol=0.0, atol=1e-12 * np.abs(expected).max())
    np.testing.assert_array_equal(Q, Q.T)


def test_the_series_and_the_direct_form_meet():
    # at the switch the two forms of every integral agree to rounding: Q is continuous there
    for w in (0.5 * SERIES_BELOW, SERIES_BELOW):
        below = arc_covariance(0.2, np.nextafter(w, 0.0), 1.0, 0.3, 1e-3, 1e-4, 1e-3, 1e-3)
        above = arc_covariance(0.2, w, 1.0, 0.3, 1e-3, 1e-4, 1e-3, 1e-3)
        np.testing.assert_allclose(below, above, rtol=0.0, atol=1e-14 * np.abs(above).max())


finite = st.floats(-3.0, 3.0, allow_nan=False)
variance = st.floats(0.0, 1.0, allow_nan=False)


@given(finite, st.floats(-8.0, 8.0, allow_nan=False), finite, finite, variance, variance, variance)
def test_noise_is_symmetric_positive_semidefinite(theta, omega, vx, vy, var_vx, var_omega, var_vy):
    # a valid Sigma (|cov| <= sqrt(var_vx var_omega)) gives a valid Q
    cov = 0.5 * math.sqrt(var_vx * var_omega)
    Q = arc_covariance(theta, omega, vx, vy, var_vx, cov, var_omega, var_vy)
    np.testing.assert_array_equal(Q, Q.T)
    assert np.linalg.eigvalsh(Q).min() >= -1e-13 * max(np.abs(Q).max(), 1e-300)


def test_a_turn_beyond_the_limit_is_refused():
    with pytest.raises(ValueError, match="not a motion"):
        arc_covariance(0.0, 1.01 * MAX_STEP_TURN_RAD, 1.0, 0.0, 1.0, 0.0, 1.0)
    with pytest.raises(ValueError, match="not a motion"):
        arc_covariance(0.0, math.nan, 1.0, 0.0, 1.0, 0.0, 1.0)


def test_a_batch_is_each_step_alone():
    # turns on both sides of the series' switch, exactly straight, tiny and large, both signs
    rng = np.random.default_rng(5)
    omega = np.r_[
        0.0, 1e-12, -1e-6, np.nextafter(SERIES_BELOW, 0.0), SERIES_BELOW, -2.5, 40.0, rng.normal(0, 2, 40)
    ]
    n = len(omega)
    theta, vx, vy = rng.uniform(-4, 4, n), rng.normal(0, 2, n), rng.normal(0, 0.5, n)
    var_vx, var_omega, var_vy = rng.uniform(0, 1e-2, (3, n))
    cov = 0.5 * np.sqrt(var_vx * var_omega) * rng.uniform(-1, 1, n)
    batch = arc_covariances(theta, omega, vx, vy, var_vx, cov, var_omega, var_vy)
    assert batch.shape == (n, 3, 3)
    for k in range(n):
        one = arc_covariance(theta[k], omega[k], vx[k], vy[k], var_vx[k], cov[k], var_omega[k], var_vy[k])
        np.testing.assert_allclose(batch[k], one, rtol=0.0, atol=1e-15 * np.abs(one).max())
    # scalars broadcast against arrays; a batch of one is (1, 3, 3)
    np.testing.assert_allclose(
        arc_covariances(theta, omega, vx, 0.0, 1e-3, 0.0, 1e-4),
        arc_covariances(theta, omega, vx, np.zeros(n), np.full(n, 1e-3), np.zeros(n), np.full(n, 1e-4)),
    )
    assert arc_covariances(0.0, 0.1, 1.0, 0.0, 1e-3, 0.0, 1e-4).shape == (1, 3, 3)


def test_a_batch_with_a_turn_beyond_the_limit_is_refused():
    for bad in (1.01 * MAX_STEP_TURN_RAD, math.nan):
        with pytest.raises(ValueError, match="not a motion"):
            arc_covariances(np.zeros(3), np.array([0.1, bad, 0.2]), 1.0, 0.0, 1.0, 0.0, 1.0)
