"""turtlelib.motion.kinematics.DiffDrive: forward/inverse kinematics, exact arc steps, step Jacobians.

Jacobians are checked against central finite differences of `step`, including straight-line motion and
rotations on both sides of the series threshold.
"""

import math

import numpy as np
import pytest
from finite_differences import central_jacobian, wrapping
from hypothesis import given
from hypothesis import strategies as st

from turtlelib import DiffDrive, Transform2D, Twist2D
from turtlelib.geometry.se2 import SMALL_ANGLE_RAD

PI = math.pi
BURGER = DiffDrive(wheel_radius=0.033, track_width=0.16)
NON_FINITE = [math.nan, math.inf, -math.inf]

coords_m = st.floats(-10.0, 10.0, allow_nan=False)
heading_rad = st.floats(-4.0 * PI, 4.0 * PI, allow_nan=False)
poses = st.builds(Transform2D, coords_m, coords_m, heading_rad)
wheel_rad = st.floats(-30.0, 30.0, allow_nan=False)
drives = st.builds(DiffDrive, st.floats(0.01, 0.5), st.floats(0.05, 1.0))


def assert_transform_close(actual: Transform2D, expected: Transform2D, atol: float) -> None:
    np.testing.assert_allclose(actual.as_matrix(), expected.as_matrix(), rtol=0.0, atol=atol)


# --- construction ----------------------------------------------------------------------------------------


@pytest.mark.parametrize("field", ["wheel_radius", "track_width"])
@pytest.mark.parametrize("bad", [0.0, -0.1, *NON_FINITE])
def test_rejects_invalid_geometry(field, bad):
    values = {"wheel_radius": 0.033, "track_width": 0.16, field: bad}
    with pytest.raises(ValueError):
        DiffDrive(**values)


# --- forward / inverse kinematics --------------------------------------------------------------------------


def test_body_twist_hand_cases():
    r, d = 0.033, 0.16
    # both wheels 1 rad forward: straight, r m
    np.testing.assert_allclose(BURGER.body_twist(1.0, 1.0).as_array(), [0.0, r, 0.0], atol=0.0)
    # spin in place counter-clockwise: right forward, left back
    np.testing.assert_allclose(BURGER.body_twist(-1.0, 1.0).as_array(), [2.0 * r / d, 0.0, 0.0], atol=1e-15)
    # only the right wheel: the body turns about the left wheel, omega = r / d, vx = r / 2
    np.testing.assert_allclose(BURGER.body_twist(0.0, 1.0).as_array(), [r / d, r / 2.0, 0.0], atol=1e-15)
    assert BURGER.wheel_speeds(Twist2D(0.0, r, 0.0)) == pytest.approx((1.0, 1.0), abs=1e-15)
    assert BURGER.wheel_speeds(Twist2D(2.0 * r / d, 0.0, 0.0)) == pytest.approx((-1.0, 1.0), abs=1e-15)
    # 0.22 m/s forward while turning at 1 rad/s: wheels at (0.22 -+ 0.08) / 0.033
    assert BURGER.wheel_speeds(Twist2D(1.0, 0.22, 0.0)) == pytest.approx((0.14 / r, 0.30 / r), rel=1e-14)


@given(drives, wheel_rad, wheel_rad)
def test_inverse_kinematics_inverts_forward(drive, dphi_left, dphi_right):
    twist = drive.body_twist(dphi_left, dphi_right)
    assert twist.vy == 0.0
    left, right = drive.wheel_speeds(twist)
    assert left == pytest.approx(dphi_left, abs=1e-12)
    assert right == pytest.approx(dphi_right, abs=1e-12)


@given(drives, st.floats(-5.0, 5.0), st.floats(-1.0, 1.0))
def test_forward_kinematics_inverts_inverse(drive, omega, vx):
    twist = Twist2D(omega, vx, 0.0)
    np.testing.assert_allclose(
        drive.body_twist(*drive.wheel_speeds(twist)).as_array(), twist.as_array(), rtol=0.0, atol=1e-12
    )


def test_wheel_speeds_rejects_sideways_twist():
    with pytest.raises(ValueError):
        BURGER.wheel_speeds(Twist2D(0.0, 0.1, 1e-12))


@pytest.mark.parametrize("bad", NON_FINITE)
def test_non_finite_wheel_values_raise(bad):
    for method in (
        BURGER.body_twist,
        lambda left, right: BURGER.step(Transform2D(), left, right),
        lambda left, right: BURGER.step_jacobians(0.0, left, right),
    ):
        with pytest.raises(ValueError):
            method(bad, 0.0)
        with pytest.raises(ValueError):
            method(0.0, bad)
    with pytest.raises(ValueError):
        BURGER.step_jacobians(bad, 0.1, 0.2)


# --- step --------------------------------------------------------------------------------------------------


def test_step_hand_cases():
    r, d = 0.033, 0.16
    start = Transform2D(1.0, 2.0, 0.5 * PI)
    # straight: 10 rad on both wheels = 0.33 m along the heading (+y)
    assert_transform_close(BURGER.step(start, 10.0, 10.0), Transform2D(1.0, 2.33, 0.5 * PI), atol=1e-15)
    # spin in place by a quarter turn: each wheel travels d/2 * pi/2 m
    quarter = 0.5 * d * 0.5 * PI / r
    assert_transform_close(BURGER.step(start, -quarter, quarter), Transform2D(1.0, 2.0, PI), atol=1e-15)
    # quarter circle about the stopped left wheel (radius d/2) from the origin facing +x:
    # the right wheel travels d * pi/2 m, the body ends at (d/2, d/2) facing +y
    right = d * 0.5 * PI / r
    arc_end = Transform2D(0.5 * d, 0.5 * d, 0.5 * PI)
    assert_transform_close(BURGER.step(Transform2D(), 0.0, right), arc_end, atol=1e-15)
    # the same arc from `start` is the same relative motion: (1, 2) + R(pi/2) (d/2, d/2)
    assert_transform_close(
        BURGER.step(start, 0.0, right), Transform2D(1.0 - 0.5 * d, 2.0 + 0.5 * d, PI), atol=1e-15
    )


@given(drives, poses, wheel_rad, wheel_rad, st.integers(2, 5))
def test_step_is_exact_arc(drive, pose, dphi_left, dphi_right, n):
    # an exact arc equals n arcs of 1/n the wheel increments
    one = drive.step(pose, dphi_left, dphi_right)
    many = pose
    for _ in range(n):
        many = drive.step(many, dphi_left / n, dphi_right / n)
    assert_transform_close(many, one, atol=1e-10)
    # and it is T @ exp(F dphi)
    expected = pose @ Transform2D.exp(drive.body_twist(dphi_left, dphi_right))
    assert one == expected


def test_step_converges_to_euler_integration():
    # many tiny first-order steps (x += v cos(theta) dt, ...) converge to the exact arc
    dphi_left, dphi_right, n = 3.0, 7.0, 100_000
    twist = BURGER.body_twist(dphi_left / n, dphi_right / n)
    x = y = theta = 0.0
    for _ in range(n):
        x += twist.vx * math.cos(theta)
        y += twist.vx * math.sin(theta)
        theta += twist.omega
    exact = BURGER.step(Transform2D(), dphi_left, dphi_right)
    np.testing.assert_allclose([x, y, theta], exact.as_array(), atol=1e-5)


# --- Jacobians ---------------------------------------------------------------------------------------------


def numeric_jacobians(drive, pose, dphi_left, dphi_right):
    """Central differences of q' = step(q, dphi) in q = [x, y, theta] and dphi = [left, right], the heading
    difference unwrapped."""

    def q_new(q, wheels):
        return drive.step(Transform2D(*q), *wheels).as_array()

    q = pose.as_array()
    wheels = np.array([dphi_left, dphi_right])
    G_pose = central_jacobian(lambda v: q_new(v, wheels), q, wrapping(2))
    G_wheels = central_jacobian(lambda v: q_new(q, v), wheels, wrapping(2))
    return G_pose, G_wheels


def assert_jacobians_match_finite_differences(drive, pose, dphi_left, dphi_right):
    G_pose, G_wheels = drive.step_jacobians(pose, dphi_left, dphi_right)
    assert G_pose.shape == (3, 3) and G_wheels.shape == (3, 2)
    numeric_pose, numeric_wheels = numeric_jacobians(drive, pose, dphi_left, dphi_right)
    np.testing.assert_allclose(G_pose, numeric_pose, rtol=0.0, atol=1e-7)
    np.testing.assert_allclose(G_wheels, numeric_wheels, rtol=0.0, atol=1e-7)
    # the heading alone gives the same Jacobians
    by_theta = drive.step_jacobians(pose.theta, dphi_left, dphi_right)
    np.testing.assert_array_equal(by_theta[0], G_pose)
    np.testing.assert_array_equal(by_theta[1], G_wheels)


@given(drives, poses, wheel_rad, wheel_rad)
def test_jacobians_match_finite_differences(drive, pose, dphi_left, dphi_right):
    assert_jacobians_match_finite_differences(drive, pose, dphi_left, dphi_right)


@given(drives, poses, wheel_rad, st.one_of(st.just(0.0), st.floats(-1e-3, 1e-3)))
def test_jacobians_match_finite_differences_near_straight_motion(drive, pose, dphi_left, skew):
    assert_jacobians_match_finite_differences(drive, pose, dphi_left, dphi_left + skew)


@pytest.mark.parametrize("omega_over_threshold", [0.0, 1e-9, 0.5, 1.0 - 1e-9, 1.0, 1.0 + 1e-9, 2.0])
@pytest.mark.parametrize(
    "pose", [Transform2D(), Transform2D(1.0, -2.0, 2.0), Transform2D(0.0, 0.0, -PI + 1e-9)]
)
def test_jacobians_across_the_series_threshold(omega_over_threshold, pose):
    # omega = r (dphi_r - dphi_l) / d = omega_over_threshold * SMALL_ANGLE_RAD, with 5 rad of forward travel
    skew = omega_over_threshold * SMALL_ANGLE_RAD * BURGER.track_width / BURGER.wheel_radius
    assert_jacobians_match_finite_differences(BURGER, pose, 5.0 - 0.5 * skew, 5.0 + 0.5 * skew)


def test_jacobians_hand_case_straight_line():
    r, d = 0.033, 0.16
    # heading pi/2, both wheels 10 rad: moved 0.33 m along +y
    G_pose, G_wheels = BURGER.step_jacobians(0.5 * PI, 10.0, 10.0)
    np.testing.assert_allclose(G_pose, [[1.0, 0.0, -0.33], [0.0, 1.0, 0.0], [0.0, 0.0, 1.0]], atol=1e-15)
    # d(forward)/d(wheel) = r/2 along +y; d(heading)/d(wheel) = -+ r/d; a heading change of the straight
    # path deflects its end sideways by half the distance: dx = -u/2 * domega
    u = 10.0 * r
    expected_wheels = [
        [-u / 2.0 * (-r / d), -u / 2.0 * (r / d)],
        [r / 2.0, r / 2.0],
        [-r / d, r / d],
    ]
    np.testing.assert_allclose(G_wheels, expected_wheels, atol=1e-15)


def test_jacobian_series_and_closed_forms_agree_at_the_threshold():
    # Finite differences cannot resolve the series' high-order terms; continuity at the switch can.
    # With r = d (powers of two) omega = dphi_right - dphi_left exactly, so the two neighbouring floats
    # for dphi_right straddle omega = SMALL_ANGLE_RAD; u = 50 m magnifies any mismatch, and the closed
    # forms' cancellation error there is ~ u eps / SMALL_ANGLE_RAD ~ 1e-12.
    drive = DiffDrive(wheel_radius=0.5, track_width=0.5)
    dphi_left = 100.0
    dphi_right = dphi_left + SMALL_ANGLE_RAD
    while dphi_right - dphi_left < SMALL_ANGLE_RAD:
        dphi_right = math.nextafter(dphi_right, math.inf)
    while math.nextafter(dphi_right, 0.0) - dphi_left >= SMALL_ANGLE_RAD:
        dphi_right = math.nextafter(dphi_right, 0.0)
    below_right = math.nextafter(dphi_right, 0.0)
    assert (
        drive.body_twist(dphi_left, below_right).omega
        < SMALL_ANGLE_RAD
        <= drive.body_twist(dphi_left, dphi_right).omega
    )

    below = drive.step_jacobians(0.7, dphi_left, below_right)
    above = drive.step_jacobians(0.7, dphi_left, dphi_right)
    np.testing.assert_allclose(below[0], above[0], rtol=0.0, atol=1e-11)
    np.testing.assert_allclose(below[1], above[1], rtol=0.0, atol=1e-11)
