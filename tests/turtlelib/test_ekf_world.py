"""EKF SLAM in a seeded numpy world: filter consistency (NEES) and unknown data association.

The world: a TurtleBot3 Burger drives one loop of a circle among seven landmarks. Its wheels slip as the
filter's model says (a random walk, simulated with independent slip on sub-steps of every prediction
step); the LDS-01 (x = -0.032 m on the body) reports range and bearing of every landmark within range
with Gaussian noise. Known association passes the landmark index; unknown association shuffles the
observations, and the spurious-detection test adds random clutter.
"""

import dataclasses
import math
from pathlib import Path

import numpy as np
import pytest

from turtlelib import DiffDrive, Transform2D, Twist2D
from turtlelib.consistency import chi2_bounds, nees
from turtlelib.ekf_slam import EkfSlam, ObservationStatus, SlamConfig
from turtlelib.motion_models import DiffDriveMotion
from turtlelib.range_bearing import predict_observations

PI = math.pi
BURGER = DiffDrive(wheel_radius=0.033, track_width=0.16)
# the last two only 0.25 m apart: 6 to 7 sigma in the association metric
LANDMARKS = np.array(
    [[1.2, 0.0], [0.9, 1.3], [-1.0, 0.6], [-0.6, -0.9], [0.6, -1.1], [-0.2, 1.6], [0.05, 1.6]]
)
# one loop of a circle of radius 0.5 m centred at (0, 0.5): 0.2 m/s, 0.4 rad/s, 5 Hz scans
TWIST = Twist2D(0.4, 0.2, 0.0)
SCAN_PERIOD_S = 0.2
SCAN_PERIOD_NS = 200_000_000
PREDICTIONS_PER_SCAN = 4
SLIP_SUBSTEPS = 4
N_SCANS = int(round(2.0 * PI / TWIST.omega / SCAN_PERIOD_S))
RANGE_STD, BEARING_STD = 0.02, 0.02
WHEEL_NOISE = 0.05
MOTION = DiffDriveMotion(BURGER, WHEEL_NOISE)
CONFIG = SlamConfig(sensor_x=-0.032, range_std=RANGE_STD, bearing_std=BEARING_STD, max_range=2.5)


class World:
    """The ground truth and the sensors, drawing noise from one seeded generator."""

    def __init__(self, seed: int, clutter_per_observation: float = 0.0) -> None:
        self.rng = np.random.default_rng(seed)
        self.T_world_body = Transform2D()
        self.clutter = clutter_per_observation
        speeds = BURGER.wheel_speeds(TWIST)
        dt = SCAN_PERIOD_S / PREDICTIONS_PER_SCAN
        self.increments = (speeds[0] * dt, speeds[1] * dt)

    def drive(self) -> tuple[float, float]:
        """Move the truth by one prediction step; returns the encoder increments (what the filter gets)."""
        k = WHEEL_NOISE
        for _ in range(SLIP_SUBSTEPS):
            left, right = (dphi / SLIP_SUBSTEPS for dphi in self.increments)
            slip = self.rng.normal(0.0, k * np.sqrt(np.abs([left, right])))
            self.T_world_body = BURGER.step(self.T_world_body, left + slip[0], right + slip[1])
        return self.increments

    def observe(self) -> tuple[np.ndarray, np.ndarray]:
        """``(source, z)``: the landmark index (-1 for clutter) and [range, bearing] of each detection, in
        random order. Clutter is uniform over the disc within max_range."""
        z, _, _ = predict_observations(self.T_world_body.as_array(), LANDMARKS, CONFIG.T_body_sensor)
        source = np.flatnonzero(z[:, 0] <= CONFIG.max_range)
        z = z[source] + self.rng.normal(0.0, 1.0, (len(source), 2)) * [RANGE_STD, BEARING_STD]
        n_clutter = self.rng.binomial(len(source), self.clutter) if self.clutter else 0
        clutter = np.column_stack(
            [
                CONFIG.max_range * np.sqrt(self.rng.uniform(0.01, 1.0, n_clutter)),
                self.rng.uniform(-PI, PI, n_clutter),
            ]
        )
        source = np.concatenate([source, np.full(n_clutter, -1)])
        z = np.concatenate([z, clutter])
        z[:, 1] = np.remainder(z[:, 1] + PI, 2.0 * PI) - PI
        order = self.rng.permutation(len(z))
        return source[order], z[order]


def pose_nees(slam: EkfSlam, T_world_body: Transform2D) -> float:
    error = T_world_body.as_array() - slam.pose.as_array()
    error[2] = math.remainder(error[2], 2.0 * PI)
    return nees(error, slam.pose_covariance)


def run(seed: int, known: bool, config: SlamConfig = CONFIG, clutter: float = 0.0, on_scan=None):
    """One loop; returns the per-scan pose NEES, the filter and the (source, association) of each scan.

    ``on_scan(slam)`` runs after every update."""
    world = World(seed, clutter)
    slam = EkfSlam(config, MOTION)
    history = []
    nees_per_scan = np.empty(N_SCANS)
    for scan in range(N_SCANS):
        for _ in range(PREDICTIONS_PER_SCAN):
            slam.predict(world.drive())
        source, z = world.observe()
        if known:
            slam.update_known(source, z)
        else:
            history.append((source, slam.update_unknown(z, stamp_ns=scan * SCAN_PERIOD_NS)))
        nees_per_scan[scan] = pose_nees(slam, world.T_world_body)
        if on_scan is not None:
            on_scan(slam)
    return nees_per_scan, slam, history


# --- consistency -------------------------------------------------------------------------------------------

N_RUNS = 50


@pytest.mark.parametrize("known", [True, False], ids=["known", "unknown"])
def test_average_pose_nees_stays_in_the_chi2_band(known):
    runs = np.array([run(seed, known)[0] for seed in range(N_RUNS)])
    average = runs.mean(axis=0)
    low, high = chi2_bounds(3, N_RUNS, 0.95)
    inside = (average > low) & (average < high)
    # a consistent filter leaves the 95 % band at ~5 % of the scans; the loop's scans are correlated,
    # so allow some more, and the average over the whole loop must sit well inside
    assert inside.mean() >= 0.85, f"ANEES inside [{low:.2f}, {high:.2f}] at only {inside.mean():.0%} of scans"
    assert low < average.mean() < high


def test_an_overconfident_filter_fails_the_nees_band():
    # the same check must catch a filter that believes its odometry 5x more than it should
    overconfident = DiffDriveMotion(BURGER, WHEEL_NOISE / 5.0)
    runs = []
    for seed in range(10):
        world = World(seed)
        slam = EkfSlam(CONFIG, overconfident)
        nees_per_scan = []
        for _ in range(N_SCANS // 2):
            for _ in range(PREDICTIONS_PER_SCAN):
                slam.predict(world.drive())
            source, z = world.observe()
            slam.update_known(source, z)
            nees_per_scan.append(pose_nees(slam, world.T_world_body))
        runs.append(nees_per_scan)
    _, high = chi2_bounds(3, 10, 0.95)
    assert np.mean(runs) > high


# --- unknown association -----------------------------------------------------------------------------------


def origins(history) -> dict[int, int]:
    """The source (true landmark index, or -1 for clutter) of the detection that started each landmark."""
    origin_of = {}
    for source, result in history:
        for k in np.flatnonzero(result.status == ObservationStatus.NEW):
            origin_of[int(result.landmark_ids[k])] = int(source[k])
    return origin_of


def min_separation_sigmas(slam: EkfSlam) -> float:
    """min over landmark pairs (i, j) of sqrt((z_i - z_j)^T S_j^-1 (z_i - z_j)) at the current estimate."""
    state, P = slam.state, slam.covariance
    if len(state) < 7:
        return math.inf
    landmarks = state[3:].reshape(-1, 2)
    z_hat, H_robot, H_landmark = predict_observations(state[:3], landmarks, CONFIG.T_body_sensor)
    R = np.diag([RANGE_STD**2, BEARING_STD**2])
    smallest = math.inf
    for j in range(len(landmarks)):
        H = np.zeros((2, len(state)))
        H[:, :3] = H_robot[j]
        H[:, 3 + 2 * j : 5 + 2 * j] = H_landmark[j]
        S = H @ P @ H.T + R
        for i in range(len(landmarks)):
            if i != j:
                d = z_hat[i] - z_hat[j]
                d[1] = math.remainder(d[1], 2.0 * PI)
                smallest = min(smallest, math.sqrt(d @ np.linalg.solve(S, d)))
    return smallest


@pytest.mark.parametrize("association", ["nn", "jcbb"])
@pytest.mark.parametrize("seed", [100, 101, 102])
def test_unknown_association_maps_each_landmark_once(association, seed):
    config = dataclasses.replace(CONFIG, matcher=association)
    separations = []
    _, slam, history = run(
        seed, known=False, config=config, on_scan=lambda slam: separations.append(min_separation_sigmas(slam))
    )
    # the premise: the mapped landmarks are at least 5 sigma apart in the association metric, all along
    assert min(separations) >= 5.0
    origin_of = origins(history)
    truth_of = {int(i): origin_of[int(i)] for i in slam.landmark_ids}
    assert sorted(truth_of.values()) == list(range(len(LANDMARKS)))
    # no false association: every observation joined the landmark its true source started
    for source, result in history:
        for k in np.flatnonzero(result.status == ObservationStatus.MATCHED):
            assert origin_of[int(result.landmark_ids[k])] == source[k]
    # and the map sits where the landmarks are, relative to the true start
    np.testing.assert_allclose(slam.landmarks, LANDMARKS[[truth_of[i] for i in slam.landmark_ids]], atol=0.1)


@pytest.mark.parametrize("association", ["nn", "jcbb"])
@pytest.mark.parametrize("seed", [200, 201, 202])
def test_spurious_detections_never_survive_confirmation(association, seed):
    # clutter: one random detection for every four real ones, i.e. 20 % of all detections
    config = dataclasses.replace(CONFIG, matcher=association)
    _, slam, history = run(seed, known=False, config=config, clutter=0.25)
    n_clutter = sum(int(np.sum(source < 0)) for source, _ in history)
    n_total = sum(len(source) for source, _ in history)
    assert 0.15 < n_clutter / n_total < 0.25
    started = sum(int(np.sum(result.status == ObservationStatus.NEW)) for _, result in history)
    assert started > len(LANDMARKS) + 20  # plenty of clutter became tentative landmarks ...
    # ... but every confirmed landmark is a true one: most of its sightings come from one true landmark
    # (its first may be clutter that fell on it), each true landmark is mapped once, and nothing else is
    sightings: dict[int, list[int]] = {}
    for source, result in history:
        for k in np.flatnonzero(result.status != ObservationStatus.REJECTED):
            sightings.setdefault(int(result.landmark_ids[k]), []).append(int(source[k]))
    truth_of = {}
    for landmark_id in slam.landmark_ids:
        sources, counts = np.unique(sightings[int(landmark_id)], return_counts=True)
        assert sources[np.argmax(counts)] >= 0 and counts.max() >= 0.9 * counts.sum()
        truth_of[int(landmark_id)] = int(sources[np.argmax(counts)])
    assert sorted(truth_of.values()) == list(range(len(LANDMARKS)))
    np.testing.assert_allclose(slam.landmarks, LANDMARKS[[truth_of[i] for i in slam.landmark_ids]], atol=0.1)


# --- regression: the diff-drive filter is today's, to rounding -------------------------------------------

GOLDEN = Path(__file__).parent / "data" / "diff_drive_golden.npz"


@pytest.mark.parametrize(("name", "known", "clutter"), [("known", True, 0.0), ("unknown", False, 0.3)])
def test_diff_drive_filter_is_unchanged_to_rounding(name, known, clutter):
    # diff_drive_golden.npz holds the final state, covariance and landmark ids of run(7, ...) computed by the
    # filter of commit 59b6b40 (before motion models were passed in; it had no known-association gate,
    # hence gate_known=1, and counted the tentative timeout in scans: 10 scans of 0.2 s = the 2 s default)
    _, slam, _ = run(7, known, config=dataclasses.replace(CONFIG, gate_known=1.0), clutter=clutter)
    # Bit for bit on the numpy/BLAS build that wrote it; other builds round the matrix products differently
    # (about 1e-16 relative after 300 scans), so the comparison allows 1e-12 of each value's scale: far
    # below any change of the model, far above rounding.
    golden = np.load(GOLDEN)
    np.testing.assert_array_equal(slam.landmark_ids, golden[f"{name}_ids"])
    state, covariance = golden[f"{name}_state"], golden[f"{name}_covariance"]
    np.testing.assert_allclose(slam.state, state, rtol=0.0, atol=1e-12 * np.abs(state).max())
    np.testing.assert_allclose(slam.covariance, covariance, rtol=0.0, atol=1e-12 * np.abs(covariance).max())
