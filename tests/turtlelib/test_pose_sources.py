"""A second pose source: EkfSlam.update_pose (a measurement of the pose itself) against the dense textbook
update, and a toy pose source that plugs into SlamTimeline beside the landmark update without touching the
filter: its measurements wait for the motion, are applied at their stamps, and it hears every
relocalization; reset and relocalize reach the filter, every step, the history and the listeners."""

from __future__ import annotations

import math
from dataclasses import replace

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from turtlelib import (
    EkfSlam,
    HeldInputs,
    Outcome,
    SlamConfig,
    SlamTimeline,
    StepResult,
    TimelineConfig,
    Transform2D,
)
from turtlelib.estimation.range_bearing import predict_observations
from turtlelib.motion.motion_models import TwistNoise, UnicycleMotion

MOTION = UnicycleMotion(TwistNoise(forward_m2_per_m=1e-3, heading_rad2_per_rad=1e-3, lateral_m2_per_m=1e-4))
CONFIG = SlamConfig(range_std=0.02, bearing_std=0.01, initial_xy_std=0.05, initial_theta_std=0.05)
LANDMARKS = np.array([[2.0, 1.0], [1.0, -1.5], [-1.0, 0.5]])
MS = 1_000_000
POSE_COV = np.diag([0.01**2, 0.02**2, 0.01**2])


def mapped(config: SlamConfig = CONFIG) -> EkfSlam:
    """Three landmarks mapped from an uncertain pose, then the pose moved on: correlated pose and map."""
    slam = EkfSlam(config, MOTION, Transform2D(0.3, -0.1, 0.2))
    z = predict_observations(slam.pose.as_array(), LANDMARKS, config.T_body_sensor)[0]
    slam.update_known([0, 1, 2], z)
    slam.predict((0.5, 0.2, 1_000_000_000))
    return slam


def dense_update(x: np.ndarray, P: np.ndarray, z: np.ndarray, R: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """The textbook update with H = [I_3 0]: K = P H^T S^-1, x + K nu, (I - K H) P (I - K H)^T + K R K^T."""
    H = np.zeros((3, len(x)))
    H[:, :3] = np.eye(3)
    nu = z - x[:3]
    nu[2] = math.remainder(nu[2], math.tau)
    S = H @ P @ H.T + R
    K = P @ H.T @ np.linalg.inv(S)
    A = np.eye(len(x)) - K @ H
    return x + K @ nu, A @ P @ A.T + K @ R @ K.T


def pose_update_error(linearization: str, scale: float) -> tuple[float, float, float]:
    """The largest difference of mean and covariance between ``update_pose`` and the dense update for a
    pose measurement ``scale`` times (3 cm, -2 cm, 0.015 rad) off the estimate, and that update's NIS
    against the one computed densely (relative difference)."""
    slam = mapped(replace(CONFIG, linearization=linearization))
    x, P = slam.state, slam.covariance
    z = x[:3] + scale * np.array([0.03, -0.02, 0.015])
    nis, fused = slam.update_pose(Transform2D(*z), POSE_COV)
    assert fused
    x_dense, P_dense = dense_update(x, P, z, POSE_COV)
    nu = z - x[:3]
    dense_nis = nu @ np.linalg.solve(P[:3, :3] + POSE_COV, nu)
    return (
        float(np.abs(slam.state - x_dense).max()),
        float(np.abs(slam.covariance - P_dense).max()),
        abs(nis - dense_nis) / dense_nis,
    )


def test_a_pose_measurement_is_the_dense_textbook_update():
    mean_error, covariance_error, nis_error = pose_update_error("standard", 1.0)
    assert mean_error < 1e-12 and covariance_error < 1e-12 and nis_error < 1e-9


def test_the_invariant_pose_update_agrees_with_the_textbook_one_to_first_order():
    """The invariant EKF moves the mean along the group and gives P at the new mean: its differences from
    the standard update vanish with the correction, the mean's quadratically, the covariance's linearly."""
    big, small = pose_update_error("invariant", 1.0), pose_update_error("invariant", 0.1)
    assert big[2] < 1e-9 and small[2] < 1e-9
    assert small[0] < big[0] / 50.0 and small[1] < big[1] / 5.0


@settings(max_examples=30, deadline=None)
@given(st.floats(-math.pi, math.pi), st.floats(0.001, 0.5), st.sampled_from([-1.0, 1.0]))
def test_the_heading_residual_is_wrapped(theta, size, sign):
    """A measured heading given a turn away (across +-pi or not) moves the estimate the short way round."""
    error = sign * size
    slam = EkfSlam(CONFIG, MOTION, Transform2D(0.0, 0.0, theta))
    _, fused = slam.update_pose(Transform2D(0.0, 0.0, theta + error + 2.0 * math.pi), POSE_COV)
    assert fused
    moved = math.remainder(slam.pose.theta - theta, math.tau)
    assert 0.0 < moved * sign <= size


def test_in_localization_the_map_is_considered_not_moved():
    slam = mapped(replace(CONFIG, mode="localization"))
    landmarks, landmark_covariances = slam.landmarks.copy(), slam.landmark_covariances.copy()
    pose_std_before = np.sqrt(np.diag(slam.pose_covariance))
    slam.update_pose(Transform2D(slam.pose.x + 0.05, slam.pose.y, slam.pose.theta), POSE_COV)
    np.testing.assert_array_equal(slam.landmarks, landmarks)
    np.testing.assert_array_equal(slam.landmark_covariances, landmark_covariances)
    assert (np.sqrt(np.diag(slam.pose_covariance)) < pose_std_before).all()


def test_a_measurement_beyond_the_gate_changes_nothing():
    slam = mapped()
    state, covariance = slam.state.copy(), slam.covariance.copy()
    nis, fused = slam.update_pose(
        Transform2D(slam.pose.x + 5.0, slam.pose.y, slam.pose.theta), POSE_COV, 11.3
    )
    assert not fused and nis > 11.3
    np.testing.assert_array_equal(slam.state, state)
    np.testing.assert_array_equal(slam.covariance, covariance)


@pytest.mark.parametrize(
    ("pose", "covariance", "match"),
    [
        (Transform2D(0.0, 0.0, 0.0), np.eye(2), "3x3"),
        (Transform2D(0.0, 0.0, 0.0), np.diag([1.0, 1.0, -1.0]), "positive definite"),
        (Transform2D(0.0, 0.0, 0.0), np.array([[1.0, 0.5, 0], [0, 1.0, 0], [0, 0, 1.0]]), "symmetric"),
        (Transform2D(0.0, 0.0, 0.0), np.diag([1.0, np.nan, 1.0]), "finite"),
    ],
)
def test_a_bad_pose_measurement_is_refused_and_changes_nothing(pose, covariance, match):
    slam = mapped()
    state = slam.state.copy()
    with pytest.raises(ValueError, match=match):
        slam.update_pose(pose, covariance)
    np.testing.assert_array_equal(slam.state, state)


class ToyPoseSource:
    """A second pose source as the next ones will plug in (a scan registration, a GNSS fix): its payload is
    a measured pose, fused with :meth:`EkfSlam.update_pose`; it records what it was told."""

    def __init__(self) -> None:
        self.applied_at: list[tuple[int, Transform2D]] = []
        self.relocalized_at: list[Transform2D] = []

    def apply(self, slam: EkfSlam, payload: Transform2D, stamp_ns: int) -> StepResult:
        self.applied_at.append((stamp_ns, slam.pose))
        _, fused = slam.update_pose(payload, POSE_COV)
        return StepResult(Outcome.APPLIED if fused else Outcome.HELD)

    def relocalized(self, T_map_body: Transform2D) -> None:
        self.relocalized_at.append(T_map_body)


class Keyframes:
    """A listener: the posterior poses it was given by stamp, and how often it was cleared."""

    def __init__(self) -> None:
        self.poses: dict[int, Transform2D] = {}
        self.clears = 0

    def corrected(self, t_ns: int, T_map_body: Transform2D) -> None:
        self.poses[t_ns] = T_map_body

    def cleared(self) -> None:
        self.clears += 1


def driving_timeline() -> tuple[SlamTimeline, ToyPoseSource, Keyframes]:
    slam = EkfSlam(CONFIG, MOTION, Transform2D())
    timeline = SlamTimeline(slam, HeldInputs(), TimelineConfig(max_observation_delay=0.05), keep_history=True)
    source = timeline.attach(ToyPoseSource())
    keyframes = Keyframes()
    timeline.listen(keyframes)
    return timeline, source, keyframes


def test_a_toy_pose_source_plugs_in_and_is_applied_at_its_stamp():
    timeline, source, keyframes = driving_timeline()
    timeline.add_motion(0, (0.2, 0.0))
    # stamped ahead of the motion: it waits
    assert timeline.add(35 * MS, source, Transform2D(0.007, 0.0, 0.0)) == []
    assert timeline.pending_count == 1
    timeline.add_motion(20 * MS, (0.2, 0.0))
    [result] = timeline.add_motion(40 * MS, (0.2, 0.0))
    assert result.t_ns == 35 * MS and result.outcome is Outcome.APPLIED and result.association is None
    # the filter was predicted exactly to the stamp: 0.2 m/s for 35 ms
    [(stamp, T_before)] = source.applied_at
    assert stamp == 35 * MS and T_before.x == pytest.approx(0.007, abs=1e-12)
    # the listener has the posterior at the stamp, where the filter still is (50 ms behind the motion)
    assert timeline.filter_time_ns == 35 * MS and keyframes.poses == {35 * MS: timeline.slam.pose}
    assert timeline.slam.pose.x == pytest.approx(0.007, abs=1e-12)
    # a pose measurement is no scan of landmarks: the history records none
    assert timeline.history.n_scans == 0


def test_an_unattached_step_is_refused():
    timeline, _, _ = driving_timeline()
    timeline.add_motion(0, (0.2, 0.0))
    with pytest.raises(ValueError, match="not attached"):
        timeline.add(0, ToyPoseSource(), Transform2D())


def test_reset_and_relocalize_reach_every_step_the_history_and_the_listeners():
    timeline, source, keyframes = driving_timeline()
    for k in range(5):
        timeline.add_motion(k * 20 * MS, (0.2, 0.1))
    z = predict_observations(timeline.slam.pose.as_array(), LANDMARKS, CONFIG.T_body_sensor)[0]
    [scan] = timeline.add_observations(timeline.filter_time_ns, z, ids=[0, 1, 2])
    assert scan.outcome is Outcome.APPLIED and timeline.history.n_scans == 1
    assert keyframes.poses == {scan.t_ns: timeline.slam.pose}
    T_new = Transform2D(1.0, 2.0, 0.5)
    timeline.relocalize(T_new, np.eye(3) * 1e-4)
    assert source.relocalized_at == [T_new] and timeline.slam.pose == T_new
    assert len(timeline.slam.landmark_ids) == 3 and timeline.history.n_scans == 0
    assert keyframes.clears == 0  # the map is kept: so are the keyframes
    timeline.reset(Transform2D(0.5, 0.0, 0.0))
    assert source.relocalized_at[-1] == Transform2D(0.5, 0.0, 0.0) and len(timeline.slam.landmark_ids) == 0
    assert keyframes.clears == 1
    np.testing.assert_array_equal(timeline.history.start_pose, [0.5, 0.0, 0.0])


def test_the_pose_at_a_stamp_is_the_filter_moved_on_without_changing_it():
    timeline, _, _ = driving_timeline()
    for k in range(6):
        timeline.add_motion(k * 20 * MS, (0.2, 0.0))
    t_f, t_w = timeline.filter_time_ns, timeline.latest_time_ns
    state = timeline.slam.state.copy()
    assert timeline.pose_at(t_f) == timeline.slam.pose
    assert timeline.pose_at(t_w).x == pytest.approx(timeline.latest_pose()[0].x, abs=1e-12)
    assert timeline.pose_at(t_f + 10 * MS).x == pytest.approx(timeline.slam.pose.x + 0.002, abs=1e-12)
    assert timeline.pose_at(t_f - 1) is None and timeline.pose_at(t_w + 1) is None
    np.testing.assert_array_equal(timeline.slam.state, state)
