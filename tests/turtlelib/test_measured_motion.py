"""A relative pose with its own covariance as the filter's motion (MeasuredMotion) and the LiDAR odometry's
samples read as a signal (MeasuredPoses)."""

from __future__ import annotations

import math

import numpy as np
import pytest
from hypothesis import given
from hypothesis import strategies as st

from turtlelib.geometry.se2 import Transform2D
from turtlelib.motion.motion_models import MeasuredMotion, rotation_block
from turtlelib.motion.motion_signals import MeasuredPoses, signal_pieces

SIGMA = np.array([[4e-4, 1e-4, 2e-5], [1e-4, 9e-4, -3e-5], [2e-5, -3e-5, 1e-4]])
UPPER = (SIGMA[0, 0], SIGMA[0, 1], SIGMA[0, 2], SIGMA[1, 1], SIGMA[1, 2], SIGMA[2, 2])


def test_step_moves_by_the_increment_and_turns_its_covariance_into_the_map_frame():
    T = Transform2D(1.0, 2.0, math.pi / 2)
    q, G, Q = MeasuredMotion().step(T, (0.5, 0.1, 0.2, 10, *UPPER))
    # q' = q (+) T_delta: forward 0.5 along +y, 0.1 to the left along -x
    np.testing.assert_allclose(q, [0.9, 2.5, math.pi / 2 + 0.2], atol=1e-12)
    np.testing.assert_allclose(G, [[1, 0, -0.5], [0, 1, -0.1], [0, 0, 1]], atol=1e-12)
    # B(pi/2) swaps x and y: Q_xx = Sigma_yy, Q_xy = -Sigma_xy, Q_x theta = -Sigma_y theta
    np.testing.assert_allclose(Q[0, 0], SIGMA[1, 1]), np.testing.assert_allclose(Q[1, 1], SIGMA[0, 0])
    np.testing.assert_allclose(Q[0, 1], -SIGMA[0, 1]), np.testing.assert_allclose(Q[0, 2], -SIGMA[1, 2])


def test_a_covariance_that_is_not_one_is_refused():
    with pytest.raises(ValueError, match="motion covariance"):
        MeasuredMotion().check((0.1, 0.0, 0.0, 10, -1.0, 0.0, 0.0, 1.0, 0.0, 1.0))
    with pytest.raises(ValueError, match="input must be"):
        MeasuredMotion().check((0.1, 0.0, 0.0, 10))


@given(fraction=st.floats(0.05, 0.95), theta0=st.floats(-math.pi, math.pi))
def test_pieces_of_an_interval_add_up_to_the_interval(fraction, theta0):
    """Split anywhere, the motion composes to the interval's and the covariances (each in its own frame,
    turned into the interval's) add up to Sigma_k."""
    signal = MeasuredPoses()
    s0 = (0.0, 0.0, theta0, 0.0, *(0.0,) * 6)
    T1 = Transform2D(0.0, 0.0, theta0) @ Transform2D(0.4, 0.05, 0.3)
    interval_ns = 200_000_000
    s1 = (T1.x, T1.y, T1.theta, float(interval_ns), *UPPER)
    t_split = int(fraction * interval_ns)
    pieces = signal_pieces(signal, [0, interval_ns], [s0, s1], 0, s0, t_split)
    pieces += signal_pieces(signal, [0, interval_ns], [s0, s1], t_split, pieces[-1][1], interval_ns)
    T, Q = Transform2D(0.0, 0.0, theta0), np.zeros((3, 3))
    model = MeasuredMotion()
    for _, _, u in pieces:
        if u is None:  # the piece that ends where it starts
            continue
        q, G, Q_k = model.step(T, u)
        Q = G @ Q @ G.T + Q_k
        T = Transform2D(*q)
    np.testing.assert_allclose((T1.inverse() @ T).as_array(), [0.0, 0.0, 0.0], atol=1e-12)
    # the whole interval's Q from its start: B(theta0) Sigma_k-in-start-frame B^T = Sigma_k (given in the
    # odometry frame); the pieces' sum differs only by the rotation within the interval (second order)
    np.testing.assert_allclose(Q, SIGMA, atol=2e-5)


def test_the_whole_interval_is_exact():
    signal = MeasuredPoses()
    theta0 = 0.7
    s0 = (1.0, 1.0, theta0, 0.0, *(0.0,) * 6)
    s1 = (1.5, 1.2, theta0 + 0.1, 1e8, *UPPER)
    u = signal.input(s0, s1, 100_000_000)
    B = rotation_block(theta0)
    Sigma_start = np.array([[u[4], u[5], u[6]], [u[5], u[7], u[8]], [u[6], u[8], u[9]]])
    np.testing.assert_allclose(B @ Sigma_start @ B.T, SIGMA, atol=1e-15)
