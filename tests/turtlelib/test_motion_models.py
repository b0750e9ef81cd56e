"""Motion models (turtlelib.motion.motion_models) and motion signals (turtlelib.motion.motion_signals).

Every model: G by finite differences, Q by Monte Carlo (the twist noise simulated as a random walk on many
sub-steps), and splitting a motion into shorter steps leaves mean and covariance unchanged; hand-computed
cases; invalid inputs refused.
"""

import math

import numpy as np
import pytest
from finite_differences import central_jacobian, wrapping
from hypothesis import example, given, settings
from hypothesis import strategies as st

from turtlelib import (
    AckermannMotion,
    DiffDrive,
    DiffDriveMotion,
    HeldInputs,
    OdometryMotion,
    OdometryPoses,
    Transform2D,
    TwistNoise,
    UnicycleMotion,
    WheelAngles,
    integrate_twist,
    normalize_angles,
)
from turtlelib.geometry.se2 import Twist2D

BURGER = DiffDrive(wheel_radius=0.033, track_width=0.16)
NOISE = TwistNoise(
    forward_m2_per_m=0.004,
    forward_m2_per_s=0.0005,
    lateral_m2_per_m=0.001,
    heading_rad2_per_m=0.003,
    heading_rad2_per_rad=0.002,
    heading_rad2_per_s=0.0004,
)
# Victoria Park's truck: wheelbase 2.83 m, encoder on the rear-left wheel 0.76 m left of the centreline
TRUCK = AckermannMotion(wheelbase_m=2.83, encoder_y_m=0.76, noise=NOISE)
S = 1_000_000_000


def split(model, u, n):
    """``u`` as n consecutive inputs of the same motion, each 1/n of it."""
    if isinstance(model, DiffDriveMotion):
        return [(u[0] / n, u[1] / n)] * n
    if isinstance(model, OdometryMotion):
        T_part = integrate_twist(Transform2D(*u[:3]).log() * (1.0 / n))
        assert u[3] % n == 0
        return [(T_part.x, T_part.y, T_part.theta, u[3] // n)] * n
    assert u[-1] % n == 0
    return [(*u[:-1], u[-1] // n)] * n


# one input per model: a curved motion with every noise term active
CASES = [
    (DiffDriveMotion(BURGER, 0.05), (3.0, 4.5)),
    (OdometryMotion(NOISE), (0.4, 0.1, 0.6, 2 * S)),
    (UnicycleMotion(NOISE), (0.3, -0.4, 2 * S)),
    (TRUCK, (2.0, 0.2, 2 * S)),
]
IDS = ["diff_drive", "odometry", "unicycle", "ackermann"]


def propagate(model, T, P, inputs):
    for u in inputs:
        q, G, Q = model.step(T, u)
        P = G @ P @ G.T + Q
        T = Transform2D(*q)
    return T, P


@pytest.mark.parametrize(("model", "u"), CASES, ids=IDS)
def test_G_matches_finite_differences(model, u):
    T = Transform2D(0.3, -0.7, 2.5)
    _, G, _ = model.step(T, u)
    numeric = central_jacobian(lambda q: model.step(Transform2D(*q), u)[0], T.as_array(), wrapping(2))
    np.testing.assert_allclose(G, numeric, atol=1e-8)


@pytest.mark.parametrize(("model", "u"), CASES, ids=IDS)
@pytest.mark.parametrize("n", [2, 5])
def test_splitting_a_motion_leaves_mean_and_covariance_unchanged(model, u, n):
    T0 = Transform2D(1.0, 2.0, -0.4)
    P0 = np.diag([0.01, 0.02, 0.03])
    T_one, P_one = propagate(model, T0, P0, [u])
    T_many, P_many = propagate(model, T0, P0, split(model, u, n))
    np.testing.assert_allclose(T_many.as_array(), T_one.as_array(), atol=1e-12)
    np.testing.assert_allclose(P_many, P_one, rtol=1e-9, atol=1e-15)


@settings(max_examples=40, deadline=None)
@given(
    v=st.floats(-1.0, 1.0),
    omega=st.floats(-2.0, 2.0),
    dt_s=st.integers(1, 5),
    theta=st.floats(-math.pi, math.pi),
    n=st.integers(2, 6),
)
def test_unicycle_splitting_property(v, omega, dt_s, theta, n):
    model = UnicycleMotion(NOISE)
    u = (v, omega, dt_s * n * 100_000_000)
    T0 = Transform2D(0.0, 0.0, theta)
    T_one, P_one = propagate(model, T0, np.zeros((3, 3)), [u])
    T_many, P_many = propagate(model, T0, np.zeros((3, 3)), split(model, u, n))
    np.testing.assert_allclose(T_many.as_array(), T_one.as_array(), atol=1e-10)
    np.testing.assert_allclose(P_many, P_one, rtol=1e-8, atol=1e-14)


def _twist_random_walk(rng, T0, xi, Sigma, substeps, samples):
    """Monte Carlo of the twist-noise model: the step's twist xi (3,) [omega, vx, vy] cut into ``substeps``
    pieces, each perturbed by N(0, Sigma / substeps) (Sigma over [vx, vy, omega]) and composed."""
    poses = np.tile(T0.as_array(), (samples, 1))
    for _ in range(substeps):
        noise = rng.multivariate_normal(np.zeros(3), Sigma / substeps, samples)
        omega = xi[0] / substeps + noise[:, 2]
        vx = xi[1] / substeps + noise[:, 0]
        vy = xi[2] / substeps + noise[:, 1]
        # exp of each piece (arc), composed onto each sample
        small = np.abs(omega) < 1e-9
        w = np.where(small, 1.0, omega)
        a = np.where(small, 1.0, np.sin(w) / w)
        b = np.where(small, 0.0, (1.0 - np.cos(w)) / w)
        dx, dy = a * vx - b * vy, b * vx + a * vy
        c, s = np.cos(poses[:, 2]), np.sin(poses[:, 2])
        poses[:, 0] += c * dx - s * dy
        poses[:, 1] += s * dx + c * dy
        poses[:, 2] += omega
    return poses


@pytest.mark.parametrize(("model", "u"), CASES[1:], ids=IDS[1:])
def test_Q_matches_monte_carlo(model, u):
    rng = np.random.default_rng(11)
    T0 = Transform2D(0.5, -0.2, 0.8)
    q_next, _, Q = model.step(T0, u)
    # the twist and the noise the model puts on it
    if isinstance(model, OdometryMotion):
        xi = Transform2D(*u[:3]).log()
    elif isinstance(model, UnicycleMotion):
        xi = Twist2D(u[1] * u[2] / S, u[0] * u[2] / S, 0.0)
    else:
        scale = 1.0 - math.tan(u[1]) / TRUCK.wheelbase_m * TRUCK.encoder_y_m
        travel = u[0] / scale * u[2] / S
        xi = Twist2D(travel * math.tan(u[1]) / TRUCK.wheelbase_m, travel, 0.0)
    d, turn, dt = math.hypot(xi.vx, xi.vy), abs(xi.omega), u[-1] / S
    Sigma = np.diag(
        [
            NOISE.forward_m2_per_m * d + NOISE.forward_m2_per_s * dt,
            NOISE.lateral_m2_per_m * d,
            NOISE.heading_rad2_per_m * d + NOISE.heading_rad2_per_rad * turn + NOISE.heading_rad2_per_s * dt,
        ]
    )
    poses = _twist_random_walk(rng, T0, xi.as_array(), Sigma, substeps=200, samples=20_000)
    error = poses - q_next
    error[:, 2] = normalize_angles(error[:, 2])
    sample_cov = np.cov(error.T)
    # the sample covariance of 20 000 draws: ~1/sqrt(10 000) relative on the variances, plus linearisation
    scale = np.sqrt(np.outer(np.diag(Q), np.diag(Q)))
    np.testing.assert_allclose(sample_cov, Q, atol=0.05 * scale.max(), rtol=0.05)
    np.testing.assert_allclose(error.mean(axis=0), 0.0, atol=0.05 * math.sqrt(Q.diagonal().max()))


def test_odometry_sideways_step_hand_case():
    # a pure sideways step of 1 m from heading 0: vx = 0, vy = 1, omega = 0, travel 1 m, over 1 s
    noise = TwistNoise(forward_m2_per_m=0.01, lateral_m2_per_m=0.02, heading_rad2_per_m=0.03)
    q, G, Q = OdometryMotion(noise).step(Transform2D(), (0.0, 1.0, 0.0, S))
    np.testing.assert_allclose(q, [0.0, 1.0, 0.0], atol=1e-15)
    np.testing.assert_allclose(G, [[1.0, 0.0, -1.0], [0.0, 1.0, 0.0], [0.0, 0.0, 1.0]], atol=1e-15)
    # Q_xx = f + h/3 (heading noise at s swings the rest (1 - s) of the path), Q_yy = l, Q_tt = h,
    # Q_xt = -h/2, Q_yt = 0
    expected = np.array([[0.01 + 0.01, 0.0, -0.015], [0.0, 0.02, 0.0], [-0.015, 0.0, 0.03]])
    np.testing.assert_allclose(Q, expected, atol=1e-15)


def test_unicycle_straight_line_hand_case():
    noise = TwistNoise(forward_m2_per_m=0.01, forward_m2_per_s=0.002, heading_rad2_per_s=0.003)
    # 0.5 m/s for 2 s along +y (heading pi/2)
    q, _, Q = UnicycleMotion(noise).step(Transform2D(0.0, 0.0, math.pi / 2), (0.5, 0.0, 2 * S))
    np.testing.assert_allclose(q, [0.0, 1.0, math.pi / 2], atol=1e-15)
    # along the path (y): 0.01 * 1 m + 0.002 * 2 s; across (x): heading noise 0.006 rad^2 over the 1 m
    # path, integral (1 - s)^2 = 1/3; heading: 0.006
    assert Q[1, 1] == pytest.approx(0.014, rel=1e-12)
    assert Q[0, 0] == pytest.approx(0.006 / 3, rel=1e-12)
    assert Q[2, 2] == pytest.approx(0.006, rel=1e-12)
    assert Q[0, 2] == pytest.approx(-0.003, rel=1e-12)


def test_a_standing_unicycle_gets_only_the_time_terms():
    noise = TwistNoise(forward_m2_per_m=0.5, forward_m2_per_s=0.001, heading_rad2_per_s=0.002)
    q, _, Q = UnicycleMotion(noise).step(Transform2D(1.0, 2.0, 0.0), (0.0, 0.0, 3 * S))
    np.testing.assert_array_equal(q, [1.0, 2.0, 0.0])
    np.testing.assert_allclose(np.diag(Q), [0.003, 0.0, 0.006], atol=1e-18)


def test_ackermann_rear_axle_speed_and_turn_rate_hand_case():
    # v_c = v_e / (1 - tan(a) H / L); omega = v_c tan(a) / L; 1 s
    speed, steering = 3.0, 0.1
    v_c = speed / (1.0 - math.tan(steering) * 0.76 / 2.83)
    omega = v_c * math.tan(steering) / 2.83
    q, _, _ = TRUCK.step(Transform2D(), (speed, steering, S))
    expected = integrate_twist(Twist2D(omega, v_c, 0.0)).as_array()
    np.testing.assert_allclose(q, expected, atol=1e-14)
    # straight ahead the encoder speed is the axle's
    q, _, _ = TRUCK.step(Transform2D(), (speed, 0.0, S))
    np.testing.assert_allclose(q, [3.0, 0.0, 0.0], atol=1e-15)


def test_diff_drive_motion_is_the_wheel_slip_model():
    from turtlelib.motion.wheel_noise import wheel_slip_covariance

    T = Transform2D(0.1, 0.2, 0.3)
    q, G, Q = DiffDriveMotion(BURGER, 0.05).step(T, (2.0, 3.0))
    np.testing.assert_array_equal(q, BURGER.step(T, 2.0, 3.0).as_array())
    np.testing.assert_array_equal(Q, wheel_slip_covariance(BURGER, 0.3, 2.0, 3.0, 0.05))
    G_pose, _ = BURGER.step_jacobians(T, 2.0, 3.0)
    np.testing.assert_allclose(G, G_pose, atol=1e-15)


def _odometry_input(T_delta: Transform2D) -> tuple:
    return (T_delta.x, T_delta.y, T_delta.theta, S)


def _both_steps(dphi_left: float, dphi_right: float) -> tuple[np.ndarray, np.ndarray]:
    """Q of the wheel model and of the odometry model with the matched twist noise, for one wheel step."""
    T = Transform2D(0.4, -0.2, 0.7)
    q, _, Q_wheels = DiffDriveMotion(BURGER, 0.05).step(T, (dphi_left, dphi_right))
    odometry = OdometryMotion(TwistNoise.from_wheel_slip(BURGER, 0.05))
    _, _, Q_odometry = odometry.step(T, _odometry_input(T.inverse() @ Transform2D(*q)))
    return Q_wheels, Q_odometry


@pytest.mark.parametrize(("dphi_left", "dphi_right"), [(3.0, 3.0), (-4.0, -4.0)])
def test_twist_noise_from_wheel_slip_matches_the_wheels_on_straight_lines(dphi_left, dphi_right):
    Q_wheels, Q_odometry = _both_steps(dphi_left, dphi_right)
    np.testing.assert_allclose(Q_odometry, Q_wheels, rtol=1e-9, atol=1e-18)


@pytest.mark.parametrize(("dphi_left", "dphi_right"), [(-2.0, 2.0), (1.5, -1.5)])
def test_twist_noise_from_wheel_slip_matches_the_wheels_heading_on_turns_on_the_spot(dphi_left, dphi_right):
    Q_wheels, Q_odometry = _both_steps(dphi_left, dphi_right)
    assert Q_odometry[2, 2] == pytest.approx(Q_wheels[2, 2], rel=1e-9)


@given(
    st.floats(0.5, 5.0),
    st.floats(0.0, 0.95),
)
@settings(max_examples=50, deadline=None)
def test_twist_noise_from_wheel_slip_is_cautious_on_arcs(dphi_outer, ratio):
    # both wheels forward: the heading variance is over-stated by at most 1 + b kappa / 2
    T = Transform2D()
    wheels = DiffDriveMotion(BURGER, 0.05)
    odometry = OdometryMotion(TwistNoise.from_wheel_slip(BURGER, 0.05))
    q, _, Q_wheels = wheels.step(T, (ratio * dphi_outer, dphi_outer))
    _, _, Q_odometry = odometry.step(T, _odometry_input(Transform2D(*q)))
    xi = BURGER.body_twist(ratio * dphi_outer, dphi_outer)
    kappa = abs(xi.omega) / xi.vx
    # var(theta) is the heading noise alone, so it compares exactly
    assert (
        Q_wheels[2, 2]
        <= Q_odometry[2, 2]
        <= (1 + 0.5 * BURGER.track_width * kappa) * Q_wheels[2, 2] * (1 + 1e-9)
    )


def test_twist_noise_from_wheel_slip_refuses_a_negative_noise():
    with pytest.raises(ValueError, match="wheel_noise"):
        TwistNoise.from_wheel_slip(BURGER, -0.01)


@pytest.mark.parametrize(
    ("model", "u"),
    [
        (OdometryMotion(NOISE), (0.1, 0.0, math.nan, S)),
        (OdometryMotion(NOISE), (0.1, 0.0, 0.0, -1)),
        (OdometryMotion(NOISE), (0.1, 0.0, 0.0, 0.5)),
        (OdometryMotion(NOISE), (0.1, 0.0, 0.0)),
        (UnicycleMotion(NOISE), (math.inf, 0.0, S)),
        (UnicycleMotion(NOISE), (1.0, 0.0, True)),
        (TRUCK, (1.0, 1.6, S)),
        (TRUCK, (1.0, math.atan(2.83 / 0.76) + 0.01, S)),
        (DiffDriveMotion(BURGER, 0.05), (math.nan, 1.0)),
    ],
)
def test_invalid_inputs_raise(model, u):
    with pytest.raises(ValueError):
        model.step(Transform2D(), u)


@pytest.mark.parametrize("field", list(TwistNoise.__dataclass_fields__))
@pytest.mark.parametrize("value", [-1e-3, math.nan, math.inf])
def test_invalid_noise_raises(field, value):
    with pytest.raises(ValueError, match=field):
        TwistNoise(**{field: value})


@pytest.mark.parametrize("kwargs", [{"wheelbase_m": 0.0}, {"wheelbase_m": -1.0}, {"encoder_y_m": math.nan}])
def test_invalid_ackermann_geometry_raises(kwargs):
    with pytest.raises(ValueError):
        AckermannMotion(**{"wheelbase_m": 2.83, "encoder_y_m": 0.76, "noise": NOISE, **kwargs})


def test_invalid_wheel_noise_raises():
    with pytest.raises(ValueError, match="wheel_noise"):
        DiffDriveMotion(BURGER, -0.1)


# --- signals ---------------------------------------------------------------------------------------------


def test_wheel_angles_interpolate_linearly_and_difference():
    signal = WheelAngles()
    assert signal.at((1.0, 2.0), (3.0, 6.0), 0.25) == (1.5, 3.0)
    assert signal.input((1.0, 2.0), (1.5, 3.0), 123) == (0.5, 1.0)
    assert signal.input((1.0, 2.0), (1.0, 2.0), 123) is None


def test_held_inputs_hold_the_earlier_sample():
    signal = HeldInputs()
    assert signal.at((0.3, 0.1), (0.5, 0.2), 0.9) == (0.3, 0.1)
    assert signal.input((0.3, 0.1), (0.5, 0.2), 250) == (0.3, 0.1, 250)
    assert signal.input((0.3, 0.1), (0.3, 0.1), 0) is None


def test_odometry_poses_split_along_one_arc():
    signal = OdometryPoses()
    s0, s1 = (1.0, 2.0, 3.0), (1.5, 2.2, -2.9)  # crosses +-pi
    middle = signal.at(s0, s1, 0.5)
    first = signal.input(s0, middle, 50)
    second = signal.input(middle, s1, 50)
    # the two halves are the same relative motion, and together the whole
    np.testing.assert_allclose(first[:3], second[:3], atol=1e-12)
    whole = Transform2D(*s0) @ Transform2D(*first[:3]) @ Transform2D(*second[:3])
    np.testing.assert_allclose(whole.as_array(), Transform2D(*s1).as_array(), atol=1e-12)
    assert signal.input(s0, s0, 0) is None
    assert signal.input(s0, s0, 10) == (0.0, 0.0, 0.0, 10)


# input values from ordinary to absurd: zero, small, large, a turn far beyond any step, non-finite
WILD = st.sampled_from([0.0, 0.3, -1.2, 1.5, 1e3, -4e4, 1e9, 1e300, math.inf, -math.inf, math.nan])
WILD_DT = st.sampled_from([0, 1, S, 10**6 * S, 10**15 * S, -1, 2.5])


@pytest.mark.parametrize(("model", "u"), CASES, ids=IDS)
@settings(max_examples=300, deadline=None, derandomize=True)
@given(values=st.lists(WILD, min_size=4, max_size=4), dt_ns=WILD_DT, theta=st.sampled_from([0.0, 2.0, -3.0]))
@example(values=[1e300, 0.0, 0.0, 0.0], dt_ns=10**24, theta=0.0)  # a finite speed, a non-finite travel
def test_check_refuses_exactly_what_step_refuses(model, u, values, dt_ns, theta):
    # check(u) is step's refusal without the step, from any pose: the timeline checks a sample with it
    # before it changes anything
    wild = (*values[: len(u) - 1], dt_ns) if isinstance(u[-1], int) else tuple(values[: len(u)])
    # absurd inputs overflow on the way to their ValueError
    with np.errstate(over="ignore", invalid="ignore"):
        try:
            model.step(Transform2D(1.0, -2.0, theta), wild)
        except ValueError:
            with pytest.raises(ValueError):
                model.check(wild)
        else:
            model.check(wild)
