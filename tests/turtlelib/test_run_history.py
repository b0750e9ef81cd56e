"""The run history a timeline keeps for a smoother (turtlelib.estimation.run_history): what it records, where
it starts again, and the smoothing problem it gives."""

from __future__ import annotations

import numpy as np
import pytest

from turtlelib import EkfSlam, SlamConfig, SlamTimeline, TimelineConfig, Transform2D
from turtlelib.estimation.range_bearing import predict_observations
from turtlelib.estimation.run_history import RunHistory
from turtlelib.motion.motion_models import TwistNoise, UnicycleMotion
from turtlelib.motion.motion_signals import HeldInputs
from turtlelib.smoothing.history_problem import problem_from_history
from turtlelib.smoothing.run_smoothing import smooth_history
from turtlelib.smoothing.smoothing_problem import LoopEdge

MOTION = UnicycleMotion(TwistNoise(forward_m2_per_m=1e-3, heading_rad2_per_rad=1e-3, lateral_m2_per_m=1e-4))
CONFIG = SlamConfig(range_std=0.02, bearing_std=0.01, confirm_count=1)
LANDMARKS = np.array([[2.0, 1.0], [1.0, -1.5]])
MS = 1_000_000


def timeline() -> SlamTimeline:
    slam = EkfSlam(CONFIG, MOTION, Transform2D(0.5, 0.0, 0.1))
    return SlamTimeline(slam, HeldInputs(), TimelineConfig(max_observation_delay=0.0), keep_history=True)


def scan_of(slam: EkfSlam) -> np.ndarray:
    return predict_observations(slam.pose.as_array(), LANDMARKS, CONFIG.T_body_sensor)[0]


def drive(line: SlamTimeline, t_ms: range, scan_every: int = 2) -> list[np.ndarray]:
    """Motion samples every 10 ms of ``t_ms`` (0.2 m/s, 0.1 rad/s), an observation of both landmarks at every
    ``scan_every``-th sample's stamp; the filter's pose after each scan."""
    poses = []
    for k, t in enumerate(t_ms):
        line.add_motion(t * MS, (0.2, 0.1))
        if k % scan_every == 0:
            assert line.add_observations(t * MS, scan_of(line.slam), ids=[0, 1])
            poses.append(line.slam.pose.as_array())
    return poses


def test_the_timeline_records_the_run():
    line = timeline()
    start = line.slam.pose.as_array()
    scan_poses = drive(line, range(0, 200, 10))
    history = line.history
    assert history.n_scans == 10
    np.testing.assert_array_equal(history.start_pose, start)
    assert history.motion_t_ns == [t * MS for t in range(0, 200, 10)]
    problem, poses, rescale, unassigned = problem_from_history(
        history, MOTION, HeldInputs(), CONFIG, np.array([0, 1])
    )
    # the first scan shares the start's stamp: it is pose 0, whose prior is the filter's start
    np.testing.assert_array_equal(problem.pose_t_ns, np.arange(0, 200, 20) * MS)
    np.testing.assert_array_equal(problem.prior_mean, start)
    np.testing.assert_allclose(problem.prior_covariance, CONFIG.initial_pose_covariance(), atol=1e-8)
    np.testing.assert_array_equal(problem.observation_pose, np.repeat(np.arange(10), 2))
    np.testing.assert_array_equal(problem.observation_landmark, np.tile([0, 1], 10))
    np.testing.assert_array_equal(poses, scan_poses)
    # 20 ms at 0.2 m/s along a 0.1 rad/s arc between scans
    np.testing.assert_allclose(problem.motion_delta[:, 0], 0.004, rtol=1e-4)
    np.testing.assert_allclose(problem.motion_delta[:, 2], 0.002)
    np.testing.assert_array_equal(rescale(problem), np.ones(20))  # independent errors (the default)
    assert len(unassigned.z) == 0


def test_a_loop_and_a_stamp_asked_for_get_a_pose_each_and_the_loop_its_factor():
    line = timeline()
    scan_poses = drive(line, range(0, 200, 10))
    Z, S = Transform2D(0.03, 0.001, 0.015), np.diag([1e-4, 1e-4, 1e-5])
    loops = [
        LoopEdge(0, 150 * MS, Z, S),  # 150 ms: a motion sample's stamp, between two scans
        LoopEdge(40 * MS, 250 * MS, Z, S),  # past the history's motion: left out
    ]
    # 170 ms: a scan the grid kept whose observations never reached the filter; 900 ms: past the run
    problem, poses, _, _ = problem_from_history(
        line.history, MOTION, HeldInputs(), CONFIG, np.array([0, 1]), loops, extra_t_ns=[170 * MS, 900 * MS]
    )
    np.testing.assert_array_equal(problem.pose_t_ns, np.r_[np.arange(0, 160, 20), 150, 160, 170, 180] * MS)
    np.testing.assert_array_equal(problem.loop_pose, [[0, 8]])
    np.testing.assert_array_equal(problem.loop_delta, [Z.as_array()])
    np.testing.assert_array_equal(problem.loop_covariance, [S])
    # the warm start at 150 ms: the pose at the scan of 140 ms moved on by the 10 ms of motion between them
    expected = Transform2D(*scan_poses[7]) @ Transform2D(*problem.motion_delta[7])
    np.testing.assert_allclose(poses[8], expected.as_array())
    expected = Transform2D(*scan_poses[8]) @ Transform2D(*problem.motion_delta[9])
    np.testing.assert_allclose(poses[10], expected.as_array())
    np.testing.assert_array_equal(poses[[9, 11]], scan_poses[8:])


def test_only_landmarks_of_the_final_map_are_kept():
    line = timeline()
    drive(line, range(0, 100, 10))
    problem, _, _, unassigned = problem_from_history(
        line.history, MOTION, HeldInputs(), CONFIG, np.array([1])
    )
    np.testing.assert_array_equal(problem.observation_landmark, np.ones(5, dtype=int))
    # landmark 0's observations wait as unassigned, from the same poses
    np.testing.assert_array_equal(unassigned.observation_pose, problem.observation_pose)
    assert len(unassigned.z) == 5 and unassigned.z[0, 0] == pytest.approx(np.hypot(2.0 - 0.5, 1.0))


def test_history_starts_again_after_a_restart_and_a_break():
    line = timeline()
    drive(line, range(0, 100, 10))
    line.restart(5_000 * MS, (0.2, 0.1))
    assert line.history.n_scans == 0 and line.history.motion_t_ns == [5_000 * MS]
    np.testing.assert_array_equal(line.history.start_pose, line.slam.pose.as_array())
    drive(line, range(5_010, 5_100, 10))
    # a relocalization from outside: the history starts at the filter's time, from the new pose
    t_f = line.filter_time_ns
    line.relocalize(Transform2D(3.0, 2.0, 1.0), np.eye(3) * 0.01)
    assert line.history.motion_t_ns[0] == t_f and line.history.n_scans == 0
    np.testing.assert_array_equal(line.history.start_pose, [3.0, 2.0, 1.0])
    np.testing.assert_allclose(line.history.start_covariance, np.eye(3) * 0.01)


def test_no_history_unless_asked_and_no_problem_before_the_start():
    slam = EkfSlam(CONFIG, MOTION)
    assert SlamTimeline(slam, HeldInputs()).history is None
    with pytest.raises(ValueError, match="not started"):
        problem_from_history(RunHistory(), MOTION, HeldInputs(), CONFIG, np.array([0]))


def test_a_smoothing_after_a_break_covers_the_landmarks_seen_since():
    line = timeline()
    drive(line, range(0, 100, 10))
    line.relocalize(line.slam.pose, np.eye(3) * 1e-4)
    # from here on only landmark 1 is in view
    for k, t in enumerate(range(100, 200, 10)):
        line.add_motion(t * MS, (0.2, 0.1))
        if k % 2 == 0:
            line.add_observations(t * MS, scan_of(line.slam)[1:], ids=[1])
    slam = line.slam
    outcome = smooth_history(
        line.history, MOTION, HeldInputs(), CONFIG, slam.landmark_ids, slam.landmarks, revise=False
    )
    np.testing.assert_array_equal(slam.landmark_ids, [0, 1])
    np.testing.assert_array_equal(outcome.run.landmark_ids, [1])
    np.testing.assert_allclose(outcome.run.landmarks, LANDMARKS[1:], atol=1e-6)
    assert outcome.pose_at(180 * MS) is not None and outcome.pose_at(185 * MS) is None


def test_a_landmark_removed_as_gone_leaves_the_revisions_pool():
    """Landmark 0, seen at every scan, is not in the final map: as a tentative one that timed out, its
    observations wait unassigned for the revision (to join a landmark compatible with them, or make one);
    as one the filter removed because the LiDAR saw through it (``removed_ids``), they are left out: an
    object that is gone is neither mapped again nor pulls a landmark near where it was."""
    line = timeline()
    drive(line, range(0, 200, 10))
    slam = line.slam
    keep = slam.landmark_ids == 1
    for removed_ids, waiting in (((), 10), ((0,), 0)):
        _, _, _, unassigned = problem_from_history(
            line.history, MOTION, HeldInputs(), CONFIG, np.array([1]), removed_ids=removed_ids
        )
        assert len(unassigned.z) == waiting
        outcome = smooth_history(
            line.history, MOTION, HeldInputs(), CONFIG, slam.landmark_ids[keep], slam.landmarks[keep],
            revise=True, removed_ids=removed_ids,
        )  # fmt: skip
        assert outcome.revision.unassigned == waiting
        np.testing.assert_array_equal(outcome.run.landmark_ids, [1])
