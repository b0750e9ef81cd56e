"""PoseTwist: the body twist between consecutive odometry poses (hand cases, the arc property, errors)."""

import math

import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from turtlelib import Transform2D, Twist2D, integrate_twist
from turtlelib.motion.pose_twist import PoseTwist


def test_a_straight_step_gives_its_speed():
    odometry = PoseTwist()
    odometry.set_reference(1.0, 0.0, 0.0, 0.5)
    T = Transform2D(0.0, 0.0, 0.5) @ Transform2D(0.2, 0.0, 0.0)
    V = odometry.step(1.5, T.x, T.y, T.theta)
    assert (V.omega, V.vx, V.vy) == pytest.approx((0.0, 0.4, 0.0), abs=1e-12)
    assert odometry.reference_time_s == 1.5


@given(
    st.floats(-2.0, 2.0),
    st.floats(-0.5, 0.5),
    st.floats(-0.3, 0.3),
    st.floats(0.01, 1.5),
    st.floats(-3.0, 3.0),
)
@settings(max_examples=100, deadline=None)
def test_the_twist_moves_the_first_pose_to_the_second_in_the_time_between(omega, vx, vy, dt_s, theta):
    # turns below pi per step (|omega dt| <= 3 rad): a larger one is the shorter turn the other way
    T0 = Transform2D(0.3, -0.7, theta)
    T1 = T0 @ integrate_twist(Twist2D(omega, vx, vy) * dt_s)
    odometry = PoseTwist()
    odometry.set_reference(10.0, T0.x, T0.y, T0.theta)
    V = odometry.step(10.0 + dt_s, T1.x, T1.y, T1.theta)
    assert (V.omega, V.vx, V.vy) == pytest.approx((omega, vx, vy), rel=1e-6, abs=1e-6)


def test_no_time_gives_zero_twist():
    odometry = PoseTwist()
    odometry.set_reference(1.0, 0.0, 0.0, 0.0)
    assert odometry.step(1.0, 0.1, 0.0, 0.0) == Twist2D()


def test_errors_leave_the_reference_unchanged():
    odometry = PoseTwist()
    with pytest.raises(ValueError, match="reference"):
        odometry.step(1.0, 0.0, 0.0, 0.0)
    with pytest.raises(ValueError, match="finite"):
        odometry.set_reference(math.nan, 0.0, 0.0, 0.0)
    odometry.set_reference(2.0, 0.0, 0.0, 0.0)
    with pytest.raises(ValueError, match="backwards"):
        odometry.step(1.0, 0.0, 0.0, 0.0)
    with pytest.raises(ValueError, match="finite"):
        odometry.step(3.0, math.inf, 0.0, 0.0)
    assert odometry.reference_time_s == 2.0
