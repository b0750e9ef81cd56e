"""The smoother over a run (turtlelib.smoothing.smoother, turtlelib.smoothing.smoothing_problem,
turtlelib.smoothing.association_revision): Jacobians by finite differences, exact recovery without noise, the
landmark covariance by Monte Carlo, the
motion factors against the filter's own prediction, and the revised association decisions."""

from __future__ import annotations

import dataclasses
from dataclasses import replace

import numpy as np
import pytest
from scipy.special import chdtri

from turtlelib import EkfSlam, SlamConfig, SlamTimeline, TimelineConfig, Transform2D
from turtlelib.estimation.measurement_models import RangeBearing
from turtlelib.estimation.range_bearing import predict_observations
from turtlelib.motion.motion_models import TwistNoise, UnicycleMotion
from turtlelib.motion.motion_signals import HeldInputs
from turtlelib.smoothing.association_revision import RevisionConfig, Unassigned, revise_associations
from turtlelib.smoothing.smoother import Smoother, SmootherConfig, _System
from turtlelib.smoothing.smoothing_problem import SmoothingProblem, relative_motions, viewpoint_scales

SENSOR = Transform2D(0.1, -0.05, 0.02)
MEASUREMENT = RangeBearing(SENSOR, range_std=0.02, bearing_std=0.01)
PLAIN = SmootherConfig(kernel_width=1e6, tolerance=1e-10)  # a kernel so wide that the cost is least squares
# converged far below the noise, so that the tests compare optima, not stopping points
ROBUST = SmootherConfig(kernel_width=1.0, tolerance=1e-10)


def world(n_poses: int = 12, rng: np.random.Generator | None = None):
    """Poses on a circle arc and four landmarks around it, every landmark seen from every pose."""
    t = np.linspace(0.0, 1.5, n_poses)
    poses = np.column_stack([2.0 * np.sin(t), 2.0 * (1.0 - np.cos(t)), t])
    landmarks = np.array([[0.5, 2.5], [2.5, 0.3], [3.0, 2.8], [-1.0, 1.0]])
    return poses, landmarks


def problem_of(poses, landmarks, rng=None, odometry_std=(0.01, 0.01, 0.005)):
    """The factors of the true ``poses`` and ``landmarks``, with noise drawn from ``rng`` (none: exact)."""
    n, m = len(poses), len(landmarks)
    Q = np.diag(np.square(odometry_std))
    delta = np.array(
        [
            (Transform2D(*a).inverse() @ Transform2D(*b)).as_array()
            for a, b in zip(poses[:-1], poses[1:], strict=True)
        ]
    )
    pose_index = np.repeat(np.arange(n), m)
    landmark_id = np.tile(np.arange(m) * 10, n)
    z = np.vstack([predict_observations(q, landmarks, SENSOR)[0] for q in poses])
    R = MEASUREMENT.noise(z)
    if rng is not None:
        delta = delta + rng.multivariate_normal(np.zeros(3), Q, size=len(delta))
        z = z + rng.normal(size=z.shape) * np.sqrt(np.diagonal(R, axis1=1, axis2=2))
    return SmoothingProblem(
        pose_t_ns=np.arange(n, dtype=np.int64) * 100_000_000,
        prior_mean=poses[0].copy(),
        prior_covariance=np.diag([1e-6, 1e-6, 1e-6]),
        motion_delta=delta,
        motion_covariance=np.broadcast_to(Q, (n - 1, 3, 3)).copy(),
        observation_pose=pose_index,
        observation_landmark=landmark_id,
        z=z,
        R=R,
    )


def with_loops(problem, poses, pairs, rng=None, std=(0.01, 0.01, 0.005)):
    """``problem`` with a loop factor between each pair of pose indices ``(a, b)``: the true relative pose,
    with noise from ``rng`` (none: exact)."""
    S = np.diag(np.square(std))
    Z = np.array([(Transform2D(*poses[a]).inverse() @ Transform2D(*poses[b])).as_array() for a, b in pairs])
    if rng is not None:
        Z = Z + rng.multivariate_normal(np.zeros(3), S, size=len(Z))
    return replace(
        problem,
        loop_pose=np.array(pairs, dtype=np.int64),
        loop_delta=Z,
        loop_covariance=np.broadcast_to(S, (len(pairs), 3, 3)).copy(),
    )


def test_a_loop_pulls_a_drifting_run_back():
    """Odometry that turns 0.02 rad too far at every step, no landmarks: a loop from the first pose to the
    last (the true relative pose) spreads the drift along the run, where the odometry alone ends far off."""
    poses, _ = world(n_poses=20)
    drifting = problem_of(poses, np.zeros((0, 2)))
    drifting = replace(drifting, motion_delta=drifting.motion_delta + [0.0, 0.0, 0.02])
    smoother = Smoother(MEASUREMENT, PLAIN)
    none = np.zeros(0, dtype=np.int64)
    alone = smoother.solve(drifting, poses, none, np.zeros((0, 2)))
    closed = smoother.solve(
        with_loops(drifting, poses, [(0, 19)], std=(0.005, 0.005, 0.002)), poses, none, np.zeros((0, 2))
    )
    error_alone = np.hypot(*(alone.poses[:, :2] - poses[:, :2]).T)
    error_closed = np.hypot(*(closed.poses[:, :2] - poses[:, :2]).T)
    assert error_alone[-1] > 0.1
    assert error_closed.max() < 0.25 * error_alone.max()
    # the 0.38 rad of drift goes where the covariances say: the loop (0.002 rad) keeps a share of
    # 0.002^2 / (0.002^2 + 19 0.005^2) of it, 3 mrad, the odometry's factors take the rest
    Z = Transform2D(*closed.poses[0]).inverse() @ Transform2D(*closed.poses[-1])
    true = Transform2D(*poses[0]).inverse() @ Transform2D(*poses[-1])
    assert abs(Z.theta - true.theta) < 0.01


def test_jacobian_matches_finite_differences():
    poses, landmarks = world()
    rng = np.random.default_rng(3)
    problem = with_loops(problem_of(poses, landmarks, rng), poses, [(0, 11), (7, 2)], rng)
    system = _System(problem, MEASUREMENT, np.repeat(np.arange(4)[None], len(poses), 0).ravel(), 4)
    x = np.concatenate([(poses + rng.normal(0, 0.05, poses.shape)).ravel(), (landmarks + 0.1).ravel()])
    J = system.linearise(x, np.inf).J.toarray()
    h = 1e-6
    numeric = np.empty_like(J)
    for i in range(len(x)):
        step = np.zeros(len(x))
        step[i] = h
        # central differences of the whitened residuals (the headings stay far from +-pi here)
        numeric[:, i] = (system.linearise(x + step, np.inf).e - system.linearise(x - step, np.inf).e) / (
            2 * h
        )
    np.testing.assert_allclose(J, numeric, atol=1e-5)


def test_exact_factors_give_the_truth_from_a_distant_start():
    poses, landmarks = world()
    problem = problem_of(poses, landmarks)
    rng = np.random.default_rng(0)
    start = poses + rng.normal(0.0, [0.2, 0.2, 0.1], poses.shape)
    run = Smoother(MEASUREMENT).solve(
        problem, start, np.arange(4) * 10, landmarks + rng.normal(0, 0.3, (4, 2))
    )
    np.testing.assert_allclose(run.poses, poses, atol=1e-7)
    np.testing.assert_allclose(run.landmarks, landmarks, atol=1e-7)
    np.testing.assert_allclose(run.weights, 1.0, atol=1e-9)
    assert run.landmark_covariance.shape == (8, 8)
    np.testing.assert_allclose(run.landmark_covariance, run.landmark_covariance.T)
    assert np.all(np.linalg.eigvalsh(run.landmark_covariance) > 0)


def test_landmark_covariance_matches_monte_carlo():
    """The information matrix's landmark covariance against the spread of 300 noisy solves (seeded)."""
    poses, landmarks = world(n_poses=6)
    rng = np.random.default_rng(42)
    smoother = Smoother(MEASUREMENT, PLAIN)
    estimates, covariances = [], []
    for _ in range(300):
        run = smoother.solve(problem_of(poses, landmarks, rng), poses, np.arange(4) * 10, landmarks)
        estimates.append(run.landmarks.ravel())
        covariances.append(run.landmark_covariance)
    errors = np.array(estimates) - landmarks.ravel()
    predicted = np.mean(covariances, axis=0)
    # NEES of the 8-vector: mean 8 if the covariance is right; 300 samples put the mean within +-0.9 (3 sigma)
    nees = np.einsum("ki,ij,kj->k", errors, np.linalg.inv(predicted), errors)
    assert abs(nees.mean() - 8.0) < 0.9
    np.testing.assert_allclose(np.diag(np.cov(errors.T)), np.diag(predicted), rtol=0.3)


def test_robust_kernel_down_weights_a_gross_outlier():
    poses, landmarks = world()
    clean = problem_of(poses, landmarks, np.random.default_rng(5))
    z = clean.z.copy()
    z[7] += [1.5, 0.3]  # a wrong association: 1.5 m and 0.3 rad off
    ids = np.arange(4) * 10
    robust_smoother = Smoother(MEASUREMENT, ROBUST)
    robust = robust_smoother.solve(dataclasses.replace(clean, z=z), poses, ids, landmarks)
    plain = Smoother(MEASUREMENT, PLAIN).solve(dataclasses.replace(clean, z=z), poses, ids, landmarks)
    reference = robust_smoother.solve(clean, poses, ids, landmarks)
    assert robust.weights[7] < 1e-3
    assert robust.mahalanobis2[7] > 1e3
    # the outlier moves the robust map by millimetres, the least-squares one by centimetres
    assert np.abs(robust.landmarks - reference.landmarks).max() < 0.003
    assert np.abs(plain.landmarks - reference.landmarks).max() > 0.01


def test_relative_motions_are_the_timeline_prediction():
    """The motion factor of an interval is what the filter's timeline predicts over it from the identity."""
    motion = UnicycleMotion(
        TwistNoise(forward_m2_per_m=1e-3, heading_rad2_per_rad=1e-3, lateral_m2_per_m=1e-4)
    )
    times = [0, 30_000_000, 80_000_000, 100_000_000, 170_000_000]
    samples = [(0.2, 0.5), (0.3, -0.2), (0.0, 0.0), (0.1, 1.0), (0.1, 1.0)]
    # between samples, at a sample, between samples (one stamp per sample interval)
    stamps = np.array([0, 55_000_000, 100_000_000, 140_000_000], dtype=np.int64)
    delta, Q = relative_motions(motion, HeldInputs(), times, samples, stamps, min_motion_std=0.0)
    # the filter from the identity, exactly known, restarted there after each stamp's (empty) update
    slam = EkfSlam(SlamConfig(linearization="standard"), motion)
    timeline = SlamTimeline(slam, HeldInputs(), TimelineConfig(max_observation_delay=1.0))
    predicted = []

    def keep(applied):
        for _ in applied:
            predicted.append((slam.pose.as_array(), slam.pose_covariance))
            slam.reset(Transform2D(), np.zeros((3, 3)))

    for k, (t, sample) in enumerate(zip(times, samples, strict=True)):
        keep(timeline.add_motion(t, sample))
        upcoming = times[k + 1] if k + 1 < len(times) else np.inf
        for stamp in stamps[(stamps >= t) & (stamps < upcoming)]:
            keep(timeline.add_observations(int(stamp), np.zeros((0, 2))))
    assert len(predicted) == len(stamps)
    for k in range(len(delta)):
        np.testing.assert_allclose(delta[k], predicted[k + 1][0], atol=1e-12)
        np.testing.assert_allclose(Q[k], predicted[k + 1][1], atol=1e-15)


def test_viewpoint_scales_by_hand():
    sensor_xy = np.array([[0.0, 0.0], [0.3, 0.4], [0.3, 0.4], [1.0, 0.4]])
    pose = np.array([0, 0, 1, 3, 2])
    landmark = np.array([5, 6, 5, 5, 6])
    scales = viewpoint_scales(sensor_xy, pose, landmark, lambda d: 1.0 + 10.0 * d)
    # landmark 5: pose 0 (first), pose 1 (0.5 m on), pose 3 (0.7 m on); landmark 6: pose 0, pose 2 (0.5 m)
    np.testing.assert_allclose(scales, [1.0, 1.0, 6.0, 8.0, 6.0])


def revision_case(labels_of):
    """Noisy factors of the world, with the observations relabelled by ``labels_of(pose, landmark_id)``,
    and the optimum of the true labelling."""
    poses, landmarks = world()
    problem = problem_of(poses, landmarks, np.random.default_rng(9))
    reference = Smoother(MEASUREMENT, ROBUST).solve(problem, poses, np.arange(4) * 10, landmarks)
    labels = labels_of(problem.observation_pose, problem.observation_landmark)
    return poses, landmarks, dataclasses.replace(problem, observation_landmark=labels), reference


def revise(poses, problem, ids, landmark_xy, unassigned=None):
    smoother = Smoother(MEASUREMENT, ROBUST)
    ones = lambda p: np.ones(len(p.z))  # noqa: E731
    return revise_associations(smoother, problem, poses, ids, landmark_xy, ones, unassigned=unassigned)


def test_a_duplicate_is_merged():
    # landmark 20 mapped twice: as 20 from the first half of the run and as 99 from the second
    poses, landmarks, problem, reference = revision_case(
        lambda p, ids: np.where((ids == 20) & (p >= 6), 99, ids)
    )
    ids = np.array([0, 10, 20, 30, 99])
    revised = revise(poses, problem, ids, np.vstack([landmarks, landmarks[2] + [0.05, -0.05]]))
    assert revised.merged == [(20, 99)]
    np.testing.assert_array_equal(revised.run.landmark_ids, [0, 10, 20, 30])
    np.testing.assert_allclose(revised.run.landmarks, reference.landmarks, atol=1e-3)
    assert len(revised.removed) == 0 and revised.created == []


def test_landmarks_seen_together_are_never_merged():
    # two landmarks 2 cm apart, both seen from every pose: compatible positions, but one scan holds both
    poses, landmarks = world()
    landmarks = np.vstack([landmarks[:3], landmarks[2] + [0.02, 0.0]])
    problem = problem_of(poses, landmarks, np.random.default_rng(1))
    revised = revise(poses, problem, np.arange(4) * 10, landmarks)
    assert revised.merged == []
    np.testing.assert_array_equal(revised.run.landmark_ids, [0, 10, 20, 30])


def test_an_unsupported_landmark_is_removed():
    poses, landmarks, problem, reference = revision_case(lambda p, ids: ids)
    # one spurious detection at pose 4, 1 m ahead of the sensor, mapped as landmark 77
    spurious = np.flatnonzero(problem.observation_pose == 4)[-1] + 1
    problem = dataclasses.replace(
        problem,
        observation_pose=np.insert(problem.observation_pose, spurious, 4),
        observation_landmark=np.insert(problem.observation_landmark, spurious, 77),
        z=np.insert(problem.z, spurious, [1.0, 0.0], axis=0),
        R=np.insert(problem.R, spurious, problem.R[0], axis=0),
        noise_scale=np.ones(len(problem.z) + 1),
    )
    T_map_sensor = Transform2D(*poses[4]) @ SENSOR
    xy = np.vstack([landmarks, T_map_sensor @ np.array([1.0, 0.0])])
    revised = revise(poses, problem, np.array([0, 10, 20, 30, 77]), xy)
    np.testing.assert_array_equal(revised.removed, [77])
    np.testing.assert_array_equal(revised.run.landmark_ids, [0, 10, 20, 30])
    assert 77 not in revised.problem.observation_landmark
    np.testing.assert_allclose(revised.run.landmarks, reference.landmarks, atol=1e-3)


def test_unassigned_observations_join_the_landmark_that_explains_them():
    # the filter left landmark 30's views from pose 6 on unassigned (rejected between its gates)
    poses, landmarks, problem, reference = revision_case(lambda p, ids: ids)
    later = (problem.observation_landmark == 30) & (problem.observation_pose >= 6)
    unassigned = Unassigned(problem.observation_pose[later], problem.z[later], problem.R[later])
    labelled = dataclasses.replace(
        problem,
        observation_pose=problem.observation_pose[~later],
        observation_landmark=problem.observation_landmark[~later],
        z=problem.z[~later],
        R=problem.R[~later],
        noise_scale=None,
    )
    revised = revise(poses, labelled, np.arange(4) * 10, landmarks, unassigned)
    assert revised.adopted == later.sum() == 6 and revised.unassigned == 0
    np.testing.assert_allclose(revised.run.landmarks, reference.landmarks, atol=1e-3)


def test_two_landmarks_mapped_as_one_are_split():
    # landmark 30's observations all labelled 20: outliers of 20 that make a landmark of their own
    poses, landmarks, problem, reference = revision_case(lambda p, ids: np.where(ids == 30, 20, ids))
    revised = revise(poses, problem, np.array([0, 10, 20]), landmarks[:3])
    assert len(revised.created) == 1 and revised.created[0] > 20
    np.testing.assert_allclose(revised.run.landmarks, reference.landmarks, atol=1e-3)
    assert revised.outliers == int((reference.mahalanobis2 >= chdtri(2, 0.01)).sum())


@pytest.mark.parametrize(
    "config",
    [
        lambda: SmootherConfig(kernel_width=0.0),
        lambda: SmootherConfig(kernel_width=float("inf")),
        lambda: SmootherConfig(max_iterations=0),
        lambda: SmootherConfig(max_iterations=2.5),
        lambda: RevisionConfig(merge_gate=1.0),
        lambda: RevisionConfig(inlier_gate=0.0),
        lambda: RevisionConfig(min_support=0),
    ],
)
def test_invalid_configs_are_refused(config):
    with pytest.raises(ValueError):
        config()


def test_a_warm_start_that_does_not_fit_is_refused():
    poses, landmarks = world()
    problem = problem_of(poses, landmarks)
    smoother = Smoother(MEASUREMENT)
    with pytest.raises(ValueError, match="warm start"):
        smoother.solve(problem, poses[:-1], np.arange(4) * 10, landmarks)
    with pytest.raises(ValueError, match="observed landmark id"):
        smoother.solve(problem, poses, np.arange(4), landmarks)
