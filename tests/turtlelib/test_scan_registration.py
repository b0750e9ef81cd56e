"""Scan registration (turtlelib.sensing.scan_registration) and LiDAR odometry
(turtlelib.estimation.lidar_odometry) against simulated scans of a room with exact truth."""

from __future__ import annotations

import math
from dataclasses import replace
from itertools import pairwise

import numpy as np
import pytest

from turtlelib.estimation.lidar_odometry import Basis, LidarOdometry, LidarOdometryConfig, scan_points
from turtlelib.geometry.se2 import Transform2D, normalize_angle
from turtlelib.motion.motion_models import TwistNoise
from turtlelib.sensing.range_scan import RangeScan
from turtlelib.sensing.scan_model import LidarConfig, polygon_walls, simulate_scan
from turtlelib.sensing.scan_registration import (
    LocalMap,
    RegistrationConfig,
    register,
    voxel_centroids,
)

# an L-shaped room (m) with a pillar: every direction constrained
ROOM = polygon_walls([[-3, -2], [4, -2], [4, 1], [1, 1], [1, 3], [-3, 3]])
PILLAR = np.array([[2.0, -0.5, 0.15]])
# a corridor 1.6 m wide and 40 m long: its length is constrained by nothing in a 3.5 m scan
CORRIDOR = polygon_walls([[-20, -0.8], [20, -0.8], [20, 0.8], [-20, 0.8]])
LIDAR = LidarConfig(range_max=3.5, noise=0.01)
CONFIG = RegistrationConfig()


def points_at(T_world_body: Transform2D, walls, circles=PILLAR, rng=None, lidar=LIDAR) -> np.ndarray:
    """A simulated scan from ``T_world_body`` (LiDAR at the body origin) as thinned body-frame points."""
    rng = np.random.default_rng(0) if rng is None else rng
    scan = lidar.range_scan(simulate_scan(T_world_body, circles, walls, lidar, rng))
    return voxel_centroids(scan_points(scan, Transform2D()), CONFIG.voxel_m)


def map_from(poses, walls, circles=PILLAR) -> LocalMap:
    """A local map of scans taken at the true ``poses`` (world frame = map frame)."""
    rng = np.random.default_rng(1)
    q = np.concatenate([T @ points_at(T, walls, circles, rng) for T in poses])
    return LocalMap(voxel_centroids(q, CONFIG.voxel_m), CONFIG)


def test_voxel_centroids_hand_computed():
    p = np.array([[0.01, 0.01], [0.03, 0.01], [0.12, 0.0], [-0.01, 0.0]])
    got = voxel_centroids(p, 0.05)
    expected = {(0.02, 0.01), (0.12, 0.0), (-0.01, 0.0)}
    assert {tuple(np.round(row, 12)) for row in got} == expected


def test_registration_recovers_the_true_pose_from_a_prior_that_is_off():
    local_map = map_from([Transform2D(0.0, 0.0, 0.0), Transform2D(0.3, 0.1, 0.2)], ROOM)
    T_true = Transform2D(0.25, 0.15, 0.1)
    T_prior = Transform2D(0.40, 0.02, 0.16)  # 0.2 m and 3.4 deg off
    P_prior = np.diag([0.1**2, 0.1**2, 0.05**2])
    result = register(points_at(T_true, ROOM), local_map, T_prior, P_prior, CONFIG)
    assert result is not None and not result.degenerate
    error = T_true.inverse() @ result.T_map_body
    assert math.hypot(error.x, error.y) < 0.01
    assert abs(error.theta) < math.radians(0.3)
    # the prior's distance is what it was off by, in its own units
    r = np.array([T_prior.x - result.T_map_body.x, T_prior.y - result.T_map_body.y, T_prior.theta - 0.1])
    assert result.prior_nis == pytest.approx(r @ np.linalg.solve(P_prior, r), rel=0.1)


def test_people_walking_by_do_not_move_the_registration():
    local_map = map_from([Transform2D(0.0, 0.0, 0.0)], ROOM)
    T_true = Transform2D(0.1, -0.05, -0.05)
    # six legs of three people between the robot and the walls, not in the map
    people = np.array([[1.0, 0.3, 0.06], [1.2, 0.3, 0.06], [-1.0, 1.0, 0.06], [-1.2, 1.1, 0.06],
                       [0.5, -1.0, 0.06], [0.7, -1.1, 0.06]])  # fmt: skip
    p = points_at(T_true, ROOM, np.concatenate([PILLAR, people]))
    result = register(p, local_map, Transform2D(0.0, 0.0, 0.0), np.diag([0.1**2, 0.1**2, 0.05**2]), CONFIG)
    error = T_true.inverse() @ result.T_map_body
    assert math.hypot(error.x, error.y) < 0.01 and abs(error.theta) < math.radians(0.3)


def test_a_corridor_is_degenerate_along_its_length_and_the_prior_holds_it():
    local_map = map_from([Transform2D(0.0, 0.0, 0.0)], CORRIDOR, np.zeros((0, 3)))
    T_true = Transform2D(0.3, 0.05, 0.02)
    T_prior = Transform2D(0.5, 0.0, 0.0)  # 0.2 m off along the corridor, 5 cm across
    P_prior = np.diag([0.1**2, 0.1**2, 0.02**2])
    result = register(points_at(T_true, CORRIDOR, np.zeros((0, 3))), local_map, T_prior, P_prior, CONFIG)
    assert result.degenerate and result.weakest_std_m > CONFIG.degenerate_std_m
    # across the corridor and in heading the scan decides; along it the prior does
    assert result.T_map_body.y == pytest.approx(0.05, abs=0.01)
    assert result.T_map_body.theta == pytest.approx(0.02, abs=math.radians(0.3))
    assert result.T_map_body.x == pytest.approx(0.5, abs=0.02)
    # along the corridor the uncertainty is (nearly) the prior's 0.1 m, across it the scan's
    assert 0.085 < math.sqrt(result.Sigma[0, 0]) <= 0.1
    assert math.sqrt(result.Sigma[1, 1]) < 0.01


def test_the_covariance_is_what_repeated_scans_give():
    """Monte Carlo: the registered pose's scatter over scans with independent range noise (seeded) agrees
    with Sigma: mean NEES within the 99 % band of its chi-square(3 n) / n."""
    local_map = map_from([Transform2D(0.0, 0.0, 0.0), Transform2D(0.5, 0.3, 0.4)], ROOM)
    T_true = Transform2D(0.2, 0.1, 0.2)
    P_prior = np.diag([0.05**2, 0.05**2, 0.03**2])
    rng = np.random.default_rng(7)
    lidar = LidarConfig(range_max=3.5, noise=CONFIG.point_std_m)
    nees = []
    for _ in range(60):
        T_prior = Transform2D(*(T_true.as_array() + rng.multivariate_normal(np.zeros(3), P_prior)))
        result = register(points_at(T_true, ROOM, rng=rng, lidar=lidar), local_map, T_prior, P_prior, CONFIG)
        e = result.T_map_body.as_array() - T_true.as_array()
        e[2] = normalize_angle(e[2])
        nees.append(e @ np.linalg.solve(result.Sigma, e))
    # chi2(180) / 60: 99 % band [2.38, 3.72]; the map's own noise adds a little
    assert 2.2 < np.mean(nees) < 3.9


def test_nothing_to_match_gives_no_registration():
    local_map = map_from([Transform2D(0.0, 0.0, 0.0)], ROOM)
    far = np.array([[50.0, 50.0], [51.0, 50.0], [52.0, 50.0]])
    assert register(far, local_map, Transform2D(), np.eye(3) * 0.01, CONFIG) is None


@pytest.mark.parametrize(
    ("field", "value", "message"),
    [
        ("voxel_m", 0.0, "voxel_m must be finite and > 0"),
        ("max_iterations", 0, "max_iterations must be"),
        ("min_points", 2, "min_points must be"),
        ("kernel", math.nan, "kernel must be a finite number"),
    ],
)
def test_invalid_registration_config_is_refused(field, value, message):
    with pytest.raises(ValueError, match=message):
        RegistrationConfig(**{field: value})


def test_invalid_odometry_config_is_refused():
    with pytest.raises(ValueError, match="keyframes must be"):
        LidarOdometryConfig(keyframes=0)
    with pytest.raises(ValueError, match="registration must be a RegistrationConfig"):
        LidarOdometryConfig(registration={"voxel_m": 0.05})


NOISE = TwistNoise(forward_m2_per_m=0.02**2, lateral_m2_per_m=0.01**2, heading_rad2_per_m=0.02**2,
                   heading_rad2_per_rad=0.02**2)  # fmt: skip


def drive(walls, circles, wheel_bias: float, steps: int = 40):
    """LiDAR odometry along an arc in ``walls`` fed wheel odometry whose heading drifts by ``wheel_bias``
    rad per step; the true, the input's and the registered poses at each scan."""
    odometry = LidarOdometry(LidarOdometryConfig(), NOISE)
    rng = np.random.default_rng(3)
    truth, inputs, registered, bases = [], [], [], []
    T_true, T_input = Transform2D(-1.5, 0.0, 0.0), Transform2D(-1.5, 0.0, 0.0)
    U = Transform2D(0.05, 0.0, 0.02)
    for k in range(steps):
        scan = LIDAR.range_scan(simulate_scan(T_true, circles, walls, LIDAR, rng))
        result = odometry.step(k * 200_000_000, T_input, scan, Transform2D())
        truth.append(T_true), inputs.append(T_input), registered.append(result.T_odom_body)
        bases.append(result.basis)
        T_true = T_true @ U
        T_input = T_input @ U @ Transform2D(0.0, 0.0, wheel_bias)
    return truth, inputs, registered, bases


def test_lidar_odometry_corrects_drifting_wheels():
    truth, inputs, registered, bases = drive(ROOM, PILLAR, wheel_bias=0.01)
    assert bases[0] is Basis.MOTION and set(bases[1:]) == {Basis.REGISTERED}
    input_error = abs(normalize_angle(inputs[-1].theta - truth[-1].theta))
    registered_error = truth[-1].inverse() @ registered[-1]
    assert input_error == pytest.approx(0.39, abs=1e-9)
    assert abs(registered_error.theta) < math.radians(1.0)
    assert math.hypot(registered_error.x, registered_error.y) < 0.03


def test_with_nothing_in_sight_the_lidar_odometry_is_the_motion_input():
    """Never worse than its input: no returns, so every scan rests on the motion input, exactly."""
    truth, inputs, registered, bases = drive(np.zeros((0, 4)), np.zeros((0, 3)), wheel_bias=0.01, steps=10)
    assert set(bases) == {Basis.MOTION}
    for T_input, T_registered in zip(inputs, registered, strict=True):
        np.testing.assert_allclose(T_registered.as_array(), T_input.as_array(), atol=1e-12)


def test_scans_must_come_in_time_order():
    odometry = LidarOdometry(LidarOdometryConfig(), NOISE)
    scan = LIDAR.range_scan(simulate_scan(Transform2D(), PILLAR, ROOM, LIDAR, np.random.default_rng(0)))
    odometry.step(10, Transform2D(), scan, Transform2D())
    with pytest.raises(ValueError, match="not after the previous scan's"):
        odometry.step(10, Transform2D(), scan, Transform2D())


def test_a_first_scan_older_than_the_input_driven_steps_seeds_the_map_where_the_input_was():
    """The input alone drove on to 1 s; the first scan, stamped 0.5 s, starts the map at the pose then
    (T_last T_input_last^-1 T_input(t)): the next scan registers to it, at its true pose."""
    odometry = LidarOdometry(LidarOdometryConfig(), NOISE)
    rng = np.random.default_rng(2)
    T_at = {
        0: Transform2D(-1.5, 0.0, 0.0),
        5: Transform2D(-1.4, 0.02, 0.05),
        10: Transform2D(-1.3, 0.04, 0.1),
    }
    odometry.step(0, T_at[0], None)
    odometry.step(1_000_000_000, T_at[10], None)
    scan = LIDAR.range_scan(simulate_scan(T_at[5], PILLAR, ROOM, LIDAR, rng))
    assert odometry.seed_map(500_000_000, T_at[5], scan, Transform2D())
    # a map exists: the next older scan is not a seed
    assert not odometry.seed_map(600_000_000, T_at[5], scan, Transform2D())
    T_true = Transform2D(-1.25, 0.05, 0.12)
    scan = LIDAR.range_scan(simulate_scan(T_true, PILLAR, ROOM, LIDAR, rng))
    step = odometry.step(1_200_000_000, Transform2D(-1.2, 0.05, 0.12), scan, Transform2D())
    assert step.basis is Basis.REGISTERED
    error = T_true.inverse() @ step.T_odom_body
    assert math.hypot(error.x, error.y) < 0.01 and abs(error.theta) < math.radians(0.5)


def test_the_steps_add_up_to_the_envelope_of_the_map_and_scan_errors():
    """C_k = Sigma_k + M C_k-1 M^T (M = Sigma_k P_prior^-1 = I - Sigma_k H_s); at a keyframe added to a map of
    n, N = s (I - M) + M (s = 1 / (n + 1) while it grows), B <- B + N C N^T, C <- (I - N) C (I - N)^T;
    Q_k = [B + C_k - A]_+, A the sum so far; A, B, C carried by G to each new pose: replayed by hand; the
    sum always covers B + C_k, and it adds far less than the Sigmas' sum in a room that pins every
    direction (without the maps' drift per metre: the next test)."""
    odometry = LidarOdometry(LidarOdometryConfig(drift_m2_per_m=0.0, drift_rad2_per_m=0.0), NOISE)
    rng = np.random.default_rng(4)
    U = Transform2D(0.044, 0.0, 0.0)
    T = Transform2D(-1.5, 0.0, 0.0)
    steps = []
    for k in range(12):  # 4.4 cm a scan: keyframes at scans 0, 5 and 10 (0.22 m)
        scan = LIDAR.range_scan(simulate_scan(T, PILLAR, ROOM, LIDAR, rng))
        steps.append(odometry.step(k * 200_000_000, T, scan, Transform2D()))
        T = T @ U
    np.testing.assert_allclose(steps[1].Sigma, steps[1].registration.Sigma, rtol=1e-9, atol=1e-15)
    A, B, C = np.zeros((3, 3)), np.zeros((3, 3)), np.zeros((3, 3))
    keyframes = 1
    for k, (previous, step) in enumerate(pairwise(steps), start=1):
        T_prev, T_prior = previous.T_odom_body, previous.T_odom_body @ U
        G = np.array([[1.0, 0.0, -(T_prior.y - T_prev.y)], [0.0, 1.0, T_prior.x - T_prev.x], [0.0, 0.0, 1.0]])
        A, B, C = (G @ X @ G.T for X in (A, B, C))
        Sigma, H = step.registration.Sigma, step.registration.H_scan
        M = np.eye(3) - Sigma @ H
        C = Sigma + M @ C @ M.T
        eigenvalues, V = np.linalg.eigh(0.5 * (B + C - A + (B + C - A).T))
        np.testing.assert_allclose(step.Sigma, V @ np.diag(np.maximum(eigenvalues, 0.0)) @ V.T, atol=1e-14)
        A = A + step.Sigma
        assert np.linalg.eigvalsh(A - B - C).min() > -1e-14
        if k in (5, 10):
            N = (np.eye(3) - M) / (keyframes + 1) + M
            B, C = B + N @ C @ N.T, (np.eye(3) - N) @ C @ (np.eye(3) - N).T
            keyframes += 1
    assert np.trace(A) < 0.3 * sum(np.trace(step.registration.Sigma) for step in steps[1:])


def test_the_lidar_odometrys_covariance_stays_honest_over_many_keyframes():
    """Monte Carlo (seeded): 24 runs of 40 scans along a curve in the room, 14 keyframes each, the wheels'
    increments perturbed by their own noise model (the LiDAR's by point_std_m); the filter's prediction
    ``P' = G P G^T + Sigma_k`` against the error of the registered pose after 10, 25 and 39 scans: a mean
    NEES (3 dof, over the runs) near 3 that neither shrinks nor grows with the keyframes (chi2(72) / 24's
    99.9 % band is [1.8, 4.6]; the model's approximations widen it to [1.5, 6])."""
    lidar = LidarConfig(range_max=3.5, noise=CONFIG.point_std_m)
    config = LidarOdometryConfig(drift_m2_per_m=0.0, drift_rad2_per_m=0.0)
    U, dt_s = Transform2D(0.05, 0.0, 0.08), 0.2
    checked = (10, 25, 39)
    nees = {k: [] for k in checked}
    for run in range(24):
        rng = np.random.default_rng(100 + run)
        odometry = LidarOdometry(config, NOISE)
        T = T_input = Transform2D(-1.0, 0.5, 0.0)
        P, T_prev = np.zeros((3, 3)), None
        for k in range(40):
            scan = lidar.range_scan(simulate_scan(T, PILLAR, ROOM, lidar, rng))
            step = odometry.step(k * 200_000_000, T_input, scan, Transform2D())
            if T_prev is not None:
                T_new = step.T_odom_body
                G = np.array(
                    [[1.0, 0.0, -(T_new.y - T_prev.y)], [0.0, 1.0, T_new.x - T_prev.x], [0.0, 0.0, 1.0]]
                )
                P = G @ P @ G.T + step.Sigma
            T_prev = step.T_odom_body
            if k in nees:
                e = step.T_odom_body.as_array() - T.as_array()
                e[2] = normalize_angle(e[2])
                nees[k].append(e @ np.linalg.solve(P, e))
            # the wheels: U, then their noise (additive in the map frame, as the model's)
            noise = rng.multivariate_normal(np.zeros(3), NOISE.covariance(T_input, U.log(), dt_s))
            T_input = Transform2D(*((T_input @ U).as_array() + noise))
            T = T @ U
    means = [np.mean(nees[k]) for k in checked]
    assert all(1.5 < mean < 6.0 for mean in means), means


def test_a_registered_step_adds_the_maps_drift_over_its_length():
    """Q_k + d_k diag(q_xy, q_xy, q_theta): the same scans with and without the drift differ by exactly that;
    a step on the motion input alone (the first) carries none."""
    config = LidarOdometryConfig(drift_m2_per_m=0.03**2, drift_rad2_per_m=0.02**2)
    steps = {}
    for name, odometry in (
        ("drift", LidarOdometry(config, NOISE)),
        ("none", LidarOdometry(replace(config, drift_m2_per_m=0.0, drift_rad2_per_m=0.0), NOISE)),
    ):
        rng = np.random.default_rng(6)
        T, steps[name] = Transform2D(-1.5, 0.0, 0.0), []
        for k in range(4):
            scan = LIDAR.range_scan(simulate_scan(T, PILLAR, ROOM, LIDAR, rng))
            steps[name].append(odometry.step(k * 200_000_000, T, scan, Transform2D()))
            T = T @ Transform2D(0.05, 0.0, 0.02)
    np.testing.assert_array_equal(steps["drift"][0].Sigma, steps["none"][0].Sigma)
    for previous, drifting, plain in zip(steps["drift"], steps["drift"][1:], steps["none"][1:], strict=False):
        d_m = math.hypot(
            drifting.T_odom_body.x - previous.T_odom_body.x, drifting.T_odom_body.y - previous.T_odom_body.y
        )
        assert d_m == pytest.approx(0.05, abs=0.005)
        expected = plain.Sigma + d_m * np.diag([0.03**2, 0.03**2, 0.02**2])
        np.testing.assert_allclose(drifting.Sigma, expected, rtol=1e-9, atol=1e-15)


def compose(steps) -> np.ndarray:
    """The steps' anchored increments composed from the first step's pose on, as a keyframe graph's edge
    composes them: ``S <- A S A^T + Sigma_anchored``, ``A`` the step's displacement Jacobian."""
    S, T_last = np.zeros((3, 3)), steps[0].T_odom_body
    for step in steps[1:]:
        T = step.T_odom_body
        A = np.array([[1.0, 0.0, -(T.y - T_last.y)], [0.0, 1.0, T.x - T_last.x], [0.0, 0.0, 1.0]])
        S, T_last = A @ S @ A.T + step.Sigma_anchored, T
    return S


def test_steps_without_a_scan_defer_their_motion_to_the_next_registered_scan():
    """A LiDAR slower than the input: between scans the input alone moves the pose on (steps with no scan),
    which the filter's increments carry (the pose is that uncertain then); the anchored increments leave it
    to the next scan, whose registration re-anchors the pose to the map. The same scans with and without
    three such steps between each pair: the anchored increments compose to what the scans alone give, the
    filter's grow by the input's motion."""
    rng = np.random.default_rng(8)
    U = Transform2D(0.05, 0.0, 0.04)
    truth = [Transform2D(-1.5, 0.0, 0.0)]
    for _ in range(15):
        truth.append(truth[-1] @ U)
    scans = [LIDAR.range_scan(simulate_scan(T, PILLAR, ROOM, LIDAR, rng)) for T in truth]
    runs = {}
    for quiet in (False, True):
        odometry, steps = LidarOdometry(LidarOdometryConfig(), NOISE), []
        for k, (T, scan) in enumerate(zip(truth, scans, strict=True)):
            if quiet and k:
                for fraction in (0.25, 0.5, 0.75):
                    T_between = truth[k - 1] @ Transform2D.exp(U.log() * fraction)
                    step = odometry.step((4 * k - 4 + int(4 * fraction)) * 50_000_000, T_between, None)
                    assert step.basis is Basis.MOTION and not step.Sigma_anchored.any() and step.Sigma.any()
                    steps.append(step)
            steps.append(odometry.step(k * 200_000_000, T, scan, Transform2D()))
        runs[quiet] = steps
    registered = {quiet: [s for s in steps if s.registration is not None] for quiet, steps in runs.items()}
    for plain, quiet in zip(registered[False], registered[True], strict=True):
        error = plain.T_odom_body.inverse() @ quiet.T_odom_body
        assert math.hypot(error.x, error.y) < 1e-3 and abs(error.theta) < 1e-3
    plain, quiet = compose(runs[False]), compose(runs[True])
    np.testing.assert_allclose(np.diag(quiet), np.diag(plain), rtol=0.2)
    # the filter's: the input's heading noise over the steps without a scan (measured: 5.4 x)
    filter_quiet = compose([replace(s, Sigma_anchored=s.Sigma) for s in runs[True]])
    assert filter_quiet[2, 2] > 3.0 * plain[2, 2]


def test_a_scan_that_does_not_register_carries_the_deferred_motion():
    """Standing still (every displacement Jacobian the identity), the input's noise growing with time:
    three steps without a scan defer their motion; the next scan, too sparse to register, carries it all
    (Q + D, by hand from the model's own Q at heading 0: the registered heading is 1e-4 rad off it); the
    filter's increments are each step's own Q."""
    noise = TwistNoise(forward_m2_per_s=0.01**2, heading_rad2_per_s=0.01**2)
    odometry = LidarOdometry(LidarOdometryConfig(), noise)
    T = Transform2D(-1.5, 0.0, 0.0)
    rng = np.random.default_rng(9)
    for k in range(2):
        odometry.step(k * 100_000_000, T, LIDAR.range_scan(simulate_scan(T, PILLAR, ROOM, LIDAR, rng)))
    Q = noise.covariance(T, Transform2D().log(), 0.1)
    for k in range(2, 5):
        step = odometry.step(k * 100_000_000, T, None)
        np.testing.assert_allclose(step.Sigma, Q, rtol=1e-3, atol=1e-8)
        assert not step.Sigma_anchored.any()
    ranges = np.full(360, np.inf)
    ranges[:5] = 1.0  # five returns: fewer than min_points, no registration
    sparse = RangeScan(ranges, 0.0, 2 * math.pi / 360, 0.12, 3.5)
    step = odometry.step(5 * 100_000_000, T, sparse, Transform2D())
    assert step.basis is Basis.MOTION
    np.testing.assert_allclose(step.Sigma, Q, rtol=1e-3, atol=1e-8)
    np.testing.assert_allclose(step.Sigma_anchored, 4 * Q, rtol=1e-3, atol=1e-8)
