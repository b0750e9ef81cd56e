"""EKF SLAM in a seeded numpy world: filter consistency (NEES) and unknown data association.

The world (slam_world.py): a TurtleBot3 Burger drives one loop of a circle among seven landmarks, its
wheels slipping as the filter's model says, the LDS-01 reporting range and bearing with Gaussian noise.
Known association passes the landmark index; unknown association gets the observations shuffled, and the
spurious-detection test adds random clutter.
"""

import dataclasses
import math
from pathlib import Path

import numpy as np
import pytest
from slam_world import (
    BEARING_STD,
    BURGER,
    CONFIG,
    MOTION,
    N_SCANS,
    PI,
    PREDICTIONS_PER_SCAN,
    RANGE_STD,
    SCAN_PERIOD_NS,
    WHEEL_NOISE,
    World,
)

from turtlelib import Transform2D
from turtlelib.estimation.consistency import chi2_bounds, nees
from turtlelib.estimation.ekf_slam import EkfSlam, ObservationStatus, SlamConfig
from turtlelib.estimation.range_bearing import predict_observations
from turtlelib.motion.motion_models import DiffDriveMotion

# the last two only 0.25 m apart: 6 to 7 sigma in the association metric
LANDMARKS = np.array(
    [[1.2, 0.0], [0.9, 1.3], [-1.0, 0.6], [-0.6, -0.9], [0.6, -1.1], [-0.2, 1.6], [0.05, 1.6]]
)


def pose_nees(slam: EkfSlam, T_world_body: Transform2D) -> float:
    error = T_world_body.as_array() - slam.pose.as_array()
    error[2] = math.remainder(error[2], 2.0 * PI)
    return nees(error, slam.pose_covariance)


def run(seed: int, known: bool, config: SlamConfig = CONFIG, clutter: float = 0.0, on_scan=None):
    """One loop; returns the per-scan pose NEES, the filter and the (source, association) of each scan.

    ``on_scan(slam)`` runs after every update."""
    world = World(seed, LANDMARKS, clutter)
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
        world = World(seed, LANDMARKS)
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
    # the premise: the mapped landmarks are at least 4 sigma apart in the association metric, all along
    # (4.4 at the first confirmations: the sightings of a tentative landmark leave the pose as it is)
    assert min(separations) >= 4.0
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
    # hence gate_known=1, and counted the tentative timeout in scans: 10 scans of 0.2 s = the 2 s default);
    # its unknown-association entries were computed again when the sightings of tentative landmarks stopped
    # moving the pose (test_unconfirmed_detections.py; the map 0.7 mm further from the truth on average)
    _, slam, _ = run(7, known, config=dataclasses.replace(CONFIG, gate_known=1.0), clutter=clutter)
    # Bit for bit on the numpy/BLAS build that wrote it; other builds round the matrix products differently
    # (about 1e-16 relative after 300 scans), so the comparison allows 1e-12 of each value's scale: far
    # below any change of the model, far above rounding.
    golden = np.load(GOLDEN)
    np.testing.assert_array_equal(slam.landmark_ids, golden[f"{name}_ids"])
    state, covariance = golden[f"{name}_state"], golden[f"{name}_covariance"]
    np.testing.assert_allclose(slam.state, state, rtol=0.0, atol=1e-12 * np.abs(state).max())
    np.testing.assert_allclose(slam.covariance, covariance, rtol=0.0, atol=1e-12 * np.abs(covariance).max())
