"""EKF SLAM update and map growth against a naive dense textbook EKF, plus Monte Carlo checks.

`DenseEkf` below is the textbook filter: full N x N Jacobians, `S^-1` by `np.linalg.inv`, the Joseph form
`(I - K H) P (I - K H)^T + K R K^T`, and state augmentation with full Jacobians. The fast filter
(turtlelib.estimation.slam_state via EkfSlam) must agree with it to 1e-9 through predictions, batched updates,
new landmarks (beyond the initial storage capacity) and marginalisation.
"""

import copy
import dataclasses
import math

import numpy as np
import pytest
from dense_batches import augmented, fuse_known_batch, random_noise, stacked_observations

from turtlelib import DiffDrive, Transform2D
from turtlelib.estimation.ekf_slam import EkfSlam, ObservationStatus, SlamConfig
from turtlelib.estimation.range_bearing import landmarks_from_observations, predict_observations, residual
from turtlelib.estimation.slam_state import SlamState
from turtlelib.motion.motion_models import DiffDriveMotion
from turtlelib.motion.wheel_noise import wheel_slip_covariance

PI = math.pi
BURGER = DiffDrive(wheel_radius=0.033, track_width=0.16)
WHEEL_NOISE = 0.05
MOTION = DiffDriveMotion(BURGER, WHEEL_NOISE)
# no innovation gate: these tests compare the fusion of every observation with the textbook filter's
CONFIG = SlamConfig(
    sensor_x=-0.032, max_range=50.0, initial_xy_std=0.02, initial_theta_std=0.01, gate_known=1.0
)
SENSOR = CONFIG.T_body_sensor


class DenseEkf:
    """Textbook EKF SLAM over [x, y, theta, m_0x, m_0y, ...] with landmarks in creation order."""

    def __init__(self, pose: np.ndarray, pose_covariance: np.ndarray) -> None:
        self.x = pose.astype(float).copy()
        self.P = pose_covariance.astype(float).copy()
        self.ids: list[int] = []

    def predict(self, left: float, right: float) -> None:
        N = len(self.x)
        theta = self.x[2]
        new_pose = BURGER.step(Transform2D(*self.x[:3]), left, right).as_array()
        G_pose, _ = BURGER.step_jacobians(theta, left, right)
        F = np.eye(N)
        F[:3, :3] = G_pose
        Q = np.zeros((N, N))
        Q[:3, :3] = wheel_slip_covariance(BURGER, theta, left, right, WHEEL_NOISE)
        self.x[:3] = new_pose
        self.P = F @ self.P @ F.T + Q

    def landmark(self, landmark_id: int) -> np.ndarray:
        i = 3 + 2 * self.ids.index(landmark_id)
        return self.x[i : i + 2]

    def update(self, ids, z, R) -> None:
        H, nu, R_full = stacked_observations(self.x, self.ids, ids, z, R, SENSOR)
        S = H @ self.P @ H.T + R_full
        gain = self.P @ H.T @ np.linalg.inv(S)
        self.x = self.x + gain @ nu
        self.x[2] = math.remainder(self.x[2], 2.0 * PI)
        A = np.eye(len(self.x)) - gain @ H
        self.P = A @ self.P @ A.T + gain @ R_full @ gain.T

    def augment(self, landmark_id: int, z: np.ndarray, R: np.ndarray) -> None:
        self.x, self.P = augmented(self.x, self.P, z, R, SENSOR)
        self.ids.append(landmark_id)

    def sorted_by_id(self) -> tuple[np.ndarray, np.ndarray]:
        order = np.argsort(self.ids)
        indices = np.concatenate([np.arange(3), (3 + 2 * order[:, None] + np.arange(2)).ravel()])
        return self.x[indices], self.P[np.ix_(indices, indices)]


def assert_agrees(slam: EkfSlam, dense: DenseEkf, atol=1e-9) -> None:
    x, P = dense.sorted_by_id()
    state = slam.state
    np.testing.assert_allclose(state[3:], x[3:], rtol=0.0, atol=atol)
    np.testing.assert_allclose(state[:2], x[:2], rtol=0.0, atol=atol)
    assert math.remainder(state[2] - x[2], 2.0 * PI) == pytest.approx(0.0, abs=atol)
    np.testing.assert_allclose(slam.covariance, P, rtol=0.0, atol=atol)


def test_fast_filter_equals_the_dense_textbook_filter():
    rng = np.random.default_rng(3)
    world = rng.uniform(-4.0, 4.0, (40, 2))
    start = Transform2D(0.1, -0.2, 0.3)
    slam = EkfSlam(CONFIG, MOTION, start)
    dense = DenseEkf(start.as_array(), CONFIG.initial_pose_covariance())
    truth = start
    seen: set[int] = set()
    for _ in range(30):
        left, right = rng.uniform(-5.0, 25.0, 2)
        slam.predict((left, right))
        dense.predict(left, right)
        truth = BURGER.step(truth, left, right)
        assert_agrees(slam, dense)

        # a batch of distinct ids mixing seen and unseen landmarks (40 ids outgrow the initial capacity)
        ids = rng.choice(len(world), size=int(rng.integers(1, 9)), replace=False)
        z, _, _ = predict_observations(truth.as_array(), world[ids], SENSOR)
        z = z + rng.normal(0.0, 0.02, z.shape)
        R = random_noise(rng, len(ids))
        result = fuse_known_batch(slam, dense, seen, ids, z, R)
        np.testing.assert_array_equal(result.landmark_ids, ids)
        assert_agrees(slam, dense)
    assert len(seen) > 16


def test_joint_nis_of_a_batch_matches_the_dense_innovation():
    rng = np.random.default_rng(11)
    slam = EkfSlam(CONFIG, MOTION)
    dense = DenseEkf(np.zeros(3), CONFIG.initial_pose_covariance())
    z0 = np.array([[1.0, 0.2], [2.0, -0.5], [1.5, 2.0]])
    R0 = random_noise(rng, 3)
    slam.update_known([0, 1, 2], z0, R0)
    for k in range(3):
        dense.augment(k, z0[k], R0[k])
    slam.predict((3.0, 4.0))
    dense.predict(3.0, 4.0)

    z = z0 + rng.normal(0.0, 0.02, z0.shape)
    R = random_noise(rng, 3)
    # the dense joint NIS: nu^T S^-1 nu with the stacked innovation
    H = np.zeros((6, 9))
    nu = np.zeros(6)
    for k in range(3):
        z_hat, H_robot, H_landmark = predict_observations(dense.x[:3], dense.landmark(k)[None], SENSOR)
        H[2 * k : 2 * k + 2, :3] = H_robot[0]
        H[2 * k : 2 * k + 2, 3 + 2 * k : 5 + 2 * k] = H_landmark[0]
        nu[2 * k : 2 * k + 2] = residual(z[k], z_hat[0])
    S = H @ dense.P @ H.T
    for k in range(3):
        S[2 * k : 2 * k + 2, 2 * k : 2 * k + 2] += R[k]
    result = slam.update_known([0, 1, 2], z, R)
    assert result.nis == pytest.approx(nu @ np.linalg.solve(S, nu), rel=1e-10)
    assert result.nis_dof == 6


# --- the innovation gate of known association --------------------------------------------------------------


def test_an_observation_outside_the_known_gate_is_rejected_and_changes_nothing():
    config = SlamConfig(sensor_x=-0.032, initial_xy_std=0.02, initial_theta_std=0.01)  # gate_known 0.9999
    slam = EkfSlam(config, MOTION)
    world = np.array([[1.0, 0.5], [-0.5, 1.5]])
    slam.update_known([0, 1], predict_observations(np.zeros(3), world, SENSOR)[0])
    slam.predict((3.0, 4.0))
    z, _, _ = predict_observations(slam.state[:3], world, SENSOR)
    state, P = slam.state, slam.covariance

    # a range 1 m off with range_std 0.02: D2 in the thousands, far beyond chi2_2^-1(0.9999) = 18.4
    wrong = z[:1] + [[1.0, 0.0]]
    result = slam.update_known([0], wrong)
    np.testing.assert_array_equal(result.status, [ObservationStatus.REJECTED])
    np.testing.assert_array_equal(result.landmark_ids, [-1])
    assert result.nis_dof == 0
    np.testing.assert_array_equal(slam.state, state)
    np.testing.assert_array_equal(slam.covariance, P)

    # in one batch with a good one: the good one is fused, the wrong one is not
    reference = copy.deepcopy(slam)
    result = slam.update_known([0, 1], np.vstack([wrong, z[1:]]))
    np.testing.assert_array_equal(result.status, [ObservationStatus.REJECTED, ObservationStatus.MATCHED])
    np.testing.assert_array_equal(result.landmark_ids, [-1, 1])
    assert result.nis_dof == 2
    alone = reference.update_known([1], z[1:])
    assert result.nis == alone.nis
    np.testing.assert_array_equal(slam.state, reference.state)
    np.testing.assert_array_equal(slam.covariance, reference.covariance)
    assert not np.array_equal(slam.covariance, P)

    # without the gate (gate_known = 1) the same wrong observation is fused
    ungated = EkfSlam(dataclasses.replace(config, gate_known=1.0), MOTION)
    ungated.update_known([0, 1], predict_observations(np.zeros(3), world, SENSOR)[0])
    ungated.predict((3.0, 4.0))
    np.testing.assert_array_equal(ungated.update_known([0], wrong).status, [ObservationStatus.MATCHED])
    assert not np.array_equal(ungated.state, state)


def test_a_normal_observation_is_fused_under_the_default_gate():
    rng = np.random.default_rng(13)
    config = SlamConfig(sensor_x=-0.032, initial_xy_std=0.02, initial_theta_std=0.01)
    gated, ungated = EkfSlam(config, MOTION), EkfSlam(CONFIG, MOTION)
    world = np.array([[1.0, 0.5], [-0.5, 1.5], [0.3, -1.2]])
    z0, _, _ = predict_observations(np.zeros(3), world, SENSOR)
    for slam in (gated, ungated):
        slam.update_known([0, 1, 2], z0)
        slam.predict((3.0, 4.0))
    z, _, _ = predict_observations(gated.state[:3], world, SENSOR)
    z = z + rng.normal(0.0, 0.02, z.shape)  # one sigma of the default noise
    result = gated.update_known([0, 1, 2], z)
    np.testing.assert_array_equal(result.status, [ObservationStatus.MATCHED] * 3)
    np.testing.assert_array_equal(result.landmark_ids, [0, 1, 2])
    # the gate only decides; a fused observation is fused exactly as without it
    expected = ungated.update_known([0, 1, 2], z)
    assert result.nis == expected.nis
    np.testing.assert_array_equal(gated.state, ungated.state)
    np.testing.assert_array_equal(gated.covariance, ungated.covariance)


@pytest.mark.parametrize("gate_known", [0.0, 1.5, -0.5, math.nan])
def test_invalid_known_gate_is_refused(gate_known):
    with pytest.raises(ValueError):
        SlamConfig(gate_known=gate_known)


# --- SlamState: marginalisation and numerical health -------------------------------------------------------


def grown_state(rng, n_landmarks):
    state = SlamState(np.array([0.1, 0.2, 0.3]), np.diag([1e-3, 2e-3, 1e-4]), capacity_landmarks=2)
    for _ in range(n_landmarks):
        z = np.array([[rng.uniform(0.5, 3.0), rng.uniform(-PI, PI)]])
        p_map, G_robot, G_z = landmarks_from_observations(state.mean[:3], z, SENSOR)
        state.append(p_map[0], G_robot[0], G_z[0], np.diag([4e-4, 1e-3]))
    return state


@pytest.mark.parametrize("slot", [0, 3, 6])
def test_remove_is_the_marginal(slot):
    rng = np.random.default_rng(5)
    state = grown_state(rng, 7)
    x, P = state.mean.copy(), state.covariance.copy()
    moved = state.remove(slot)
    keep = [i for i in range(7) if i != slot]
    # the last slot moves into the freed one
    if slot != 6:
        assert moved == 6
        keep = [6 if i == slot else i for i in range(6)]
    else:
        assert moved is None
    indices = np.concatenate([np.arange(3), (3 + 2 * np.array(keep)[:, None] + np.arange(2)).ravel()])
    np.testing.assert_array_equal(state.mean, x[indices])
    np.testing.assert_array_equal(state.covariance, P[np.ix_(indices, indices)])


def test_the_storage_shrinks_back_when_landmarks_are_removed_and_keeps_the_marginal():
    """A flood of landmarks that are then dropped (expired tentative ones) must not leave the storage, whose
    size every update's cost follows, at its peak: it shrinks to within twice the size a state of the
    remaining landmarks would grow to, and what remains is exactly the marginal."""
    rng = np.random.default_rng(11)
    state = grown_state(rng, 300)
    assert state.capacity_landmarks >= 300
    x, P = state.mean.copy(), state.covariance.copy()
    while state.n_landmarks > 5:
        assert state.remove(state.n_landmarks - 1) is None  # the last slot: nothing moves
    n = state.n_landmarks
    assert n <= state.capacity_landmarks <= 2 * (n + 8)
    keep = np.arange(3 + 2 * n)
    np.testing.assert_array_equal(state.mean, x[keep])
    np.testing.assert_array_equal(state.covariance, P[np.ix_(keep, keep)])
    # and it grows again as before
    z = np.array([[1.0, 0.2]])
    p_map, G_robot, G_z = landmarks_from_observations(state.mean[:3], z, SENSOR)
    for _ in range(30):
        state.append(p_map[0], G_robot[0], G_z[0], np.diag([4e-4, 1e-3]))
    assert state.n_landmarks == n + 30 <= state.capacity_landmarks
    np.testing.assert_array_equal(state.covariance[: 3 + 2 * n, : 3 + 2 * n], P[np.ix_(keep, keep)])


def random_state_step(rng, state):
    """One random filter step on ``state``: predict (1-3 times), correct some landmarks (or consider them),
    append or remove one."""
    n = state.n_landmarks
    action = rng.integers(5) if n else 2
    if action == 0:
        for _ in range(rng.integers(1, 4)):
            G = np.eye(3)
            G[:2, 2] = rng.normal(0.0, 0.1, 2)
            A = rng.normal(0.0, 0.01, (3, 3))
            state.predict(state.mean[:3] + rng.normal(0.0, 0.01, 3), G, A @ A.T + 1e-6 * np.eye(3))
    elif action in (1, 4):
        slots = rng.choice(n, min(n, int(rng.integers(1, 4))), replace=False)
        z_hat, H_robot, H_landmark = predict_observations(
            state.mean[:3], state.landmark_positions()[slots], SENSOR
        )
        nu = rng.normal(0.0, 0.01, (len(slots), 2))
        R = np.tile(np.diag([4e-4, 1e-3]), (len(slots), 1, 1))
        state.correct(slots, H_robot, H_landmark, nu, R, consider_landmarks=action == 4)
    elif action == 2:
        z = np.array([[rng.uniform(0.5, 3.0), rng.uniform(-PI, PI)]])
        p_map, G_robot, G_z = landmarks_from_observations(state.mean[:3], z, SENSOR)
        state.append(p_map[0], G_robot[0], G_z[0], np.diag([4e-4, 1e-3]))
    else:
        state.remove(int(rng.integers(n)))


@pytest.mark.parametrize("seed", range(5))
def test_reads_between_steps_see_the_whole_covariance(seed):
    # P is kept by its upper triangle: a state whose whole P is never read (the lower triangle stale) must
    # give, block by block and in the end, bitwise what a state read in full after every step gives
    rng = np.random.default_rng(seed)
    lazy, full = grown_state(rng, 5), grown_state(np.random.default_rng(seed), 5)
    for _ in range(60):
        state_seed = int(rng.integers(2**31))
        random_state_step(np.random.default_rng(state_seed), lazy)
        random_state_step(np.random.default_rng(state_seed), full)
        P = full.covariance
        np.testing.assert_array_equal(P, P.T)
        np.testing.assert_array_equal(lazy.mean, full.mean)
        np.testing.assert_array_equal(lazy.pose_covariance, P[:3, :3])
        n = full.n_landmarks
        rows = 3 + 2 * np.arange(n)[:, None] + np.arange(2)
        np.testing.assert_array_equal(lazy.landmark_blocks(), P[rows[:, :, None], rows[:, None, :]])
        joint = np.concatenate([np.tile(np.arange(3), (n, 1)), rows], axis=1)
        np.testing.assert_array_equal(lazy.pose_landmark_blocks(), P[joint[:, :, None], joint[:, None, :]])
    np.testing.assert_array_equal(lazy.covariance, full.covariance)


def test_deferred_predictions_are_the_sequential_ones():
    # predict defers P_qm <- G P_qm into a product of the G's: after k predictions P is, to rounding, what
    # applying each step in turn gives
    rng = np.random.default_rng(11)
    state = grown_state(rng, 6)
    P = state.covariance.copy()
    for _ in range(8):
        G = np.eye(3)
        G[:2, 2] = rng.normal(0.0, 0.2, 2)
        A = rng.normal(0.0, 0.01, (3, 3))
        Q = A @ A.T
        state.predict(state.mean[:3], G, Q)
        # P_qq <- G P_qq G^T + Q, P_qm <- G P_qm, P_mq = P_qm^T
        P[:3, :3] = G @ P[:3, :3] @ G.T + Q
        P[:3, 3:] = G @ P[:3, 3:]
        P[3:, :3] = P[:3, 3:].T
        np.testing.assert_allclose(state.pose_covariance, P[:3, :3], rtol=0.0, atol=1e-15)
    np.testing.assert_allclose(state.covariance, P, rtol=0.0, atol=1e-14 * np.abs(P).max())


def test_covariance_stays_symmetric_positive_definite_under_precise_observations():
    # very precise observations, many times, of landmarks whose prior is wide: the regime where the
    # standard form P - K H P loses symmetry and definiteness
    rng = np.random.default_rng(9)
    slam = EkfSlam(CONFIG, MOTION)
    world = rng.uniform(-3.0, 3.0, (12, 2))
    truth = Transform2D()
    z, _, _ = predict_observations(truth.as_array(), world, SENSOR)
    slam.update_known(np.arange(12), z, np.tile(np.diag([1.0, 0.3]), (12, 1, 1)))
    for _ in range(200):
        left, right = rng.uniform(0.0, 3.0, 2)
        slam.predict((left, right))
        truth = BURGER.step(truth, left, right)
        ids = rng.choice(12, 6, replace=False)
        z, _, _ = predict_observations(truth.as_array(), world[ids], SENSOR)
        slam.update_known(ids, z, np.tile(np.diag([1e-12, 1e-12]), (6, 1, 1)))
        P = slam.covariance
        np.testing.assert_array_equal(P, P.T)
        assert np.linalg.eigvalsh(P).min() > 0.0


# --- Monte Carlo -------------------------------------------------------------------------------------------


def test_new_landmark_covariance_matches_monte_carlo():
    rng = np.random.default_rng(21)
    pose_cov = np.array([[4e-4, 1e-4, 2e-5], [1e-4, 3e-4, -1e-5], [2e-5, -1e-5, 1e-4]])
    start = Transform2D(0.5, 0.2, 1.1)
    slam = EkfSlam(CONFIG, MOTION, start)
    slam.reset(start, pose_cov)
    z = np.array([[1.0, 0.4], [2.5, -2.0]])
    R = random_noise(rng, 1)[0]
    slam.update_known([0], z[:1], R[None])
    slam.update_known([1], z[1:], R[None])

    n_samples = 40_000
    poses = rng.multivariate_normal(start.as_array(), pose_cov, n_samples)
    noise = rng.multivariate_normal(np.zeros(2), R, (n_samples, 2))
    samples = np.empty((n_samples, 7))
    samples[:, :3] = poses
    for i in range(n_samples):
        # the landmark position that the true pose and true landmark would have produced z
        p_map, _, _ = landmarks_from_observations(poses[i], z - noise[i], SENSOR)
        samples[i, 3:] = p_map.ravel()
    error = samples - slam.state
    C = np.cov(error.T)
    P = slam.covariance
    std = np.sqrt(np.diag(P))
    np.testing.assert_array_less(np.abs(C - P) / np.outer(std, std), 0.04)


def test_update_covariance_matches_monte_carlo():
    # x ~ N(x_hat, P), z = h(x) + v: the filter's posterior mean x_hat+ = x_hat + K (z - h(x_hat)) has
    # error covariance E[(x - x_hat+)(x - x_hat+)^T] = P+ (up to linearisation)
    rng = np.random.default_rng(31)
    slam = EkfSlam(CONFIG, MOTION, Transform2D(0.0, 0.0, 0.2))
    slam.reset(Transform2D(0.0, 0.0, 0.2), np.diag([1e-3, 1e-3, 5e-4]))
    z0 = np.array([[1.5, 0.3], [2.0, -1.2]])
    slam.update_known([0, 1], z0, np.tile(np.diag([4e-4, 4e-4]), (2, 1, 1)))
    slam.predict((10.0, 12.0))
    prior_mean, prior_cov = slam.state, slam.covariance
    R = random_noise(rng, 2)

    n_samples = 3000
    truth = rng.multivariate_normal(prior_mean, prior_cov, n_samples)
    errors = np.empty((n_samples, 7))
    posterior_cov = None
    for i in range(n_samples):
        trial = copy.deepcopy(slam)
        z, _, _ = predict_observations(truth[i, :3], truth[i, 3:].reshape(2, 2), SENSOR)
        z = z + np.array([rng.multivariate_normal(np.zeros(2), R[k]) for k in range(2)])
        trial.update_known([0, 1], z, R)
        errors[i] = truth[i] - trial.state
        posterior_cov = trial.covariance
    errors[:, 2] = np.remainder(errors[:, 2] + PI, 2.0 * PI) - PI
    C = np.cov(errors.T)
    std = np.sqrt(np.diag(posterior_cov))
    # the update shrinks the covariance, and the sampled error agrees (3000 samples: ~3 % noise)
    assert np.trace(posterior_cov) < 0.9 * np.trace(prior_cov)
    np.testing.assert_array_less(np.abs(C - posterior_cov) / np.outer(std, std), 0.1)
