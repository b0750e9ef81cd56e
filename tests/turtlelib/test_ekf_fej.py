"""The consistency remedies (SlamConfig.linearization = 'fej', 'oc' or 'invariant'): the filter gains no
information about the global heading, which relative observations cannot give.

* 'fej' / 'oc': observability-constrained Jacobians (Huang, Mourikis & Roumeliotis 2008, 2010), whose
  null space holds the unobservable directions at the first estimates;
* 'invariant': the right-invariant EKF (Barrau & Bonnabel 2015), whose covariance is that of the error
  ``xi`` with ``truth = exp(xi) estimate`` on SE_(n+1)(2): the unobservable directions are the constant
  ``xi`` of a global rotation and translation, and its observation Jacobian ``H T`` annihilates them at
  every estimate (its heading column is zero), so no linearisation point can bring the information in.

The world: a unicycle drives two loops of a circle among six landmarks, with twist noise as its model says
and noisy range-bearing observations. The standard EKF's heading variance falls below its value when the
first landmark was seen (spurious information); with FEJ, OC or the invariant EKF it never does.
"""

import math

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from turtlelib import Transform2D, TwistNoise, UnicycleMotion
from turtlelib.estimation.ekf_slam import EkfSlam, SlamConfig
from turtlelib.estimation.range_bearing import predict_observations

LANDMARKS = np.array([[2.0, 0.0], [1.0, 2.2], [-1.5, 1.5], [-2.0, -0.5], [0.0, -2.0], [1.6, -1.4]])
NOISE = TwistNoise(forward_m2_per_m=1e-3, heading_rad2_per_m=2e-3, heading_rad2_per_rad=1e-3)
DT_NS = 100_000_000
STEPS = 2 * 126  # two loops at 0.5 rad/s, 10 Hz
STEPS_BEFORE_FIRST_LANDMARK = 20
RANGE_STD, BEARING_STD = 0.05, 0.02


def run(linearization: str, seed: int, relinearize_gate: float = 1.0) -> tuple[float, float, float, float]:
    """``(P_tt when the first landmark is seen, min P_tt afterwards, final heading error, final P_tt)``."""
    rng = np.random.default_rng(seed)
    config = SlamConfig(
        range_std=RANGE_STD,
        bearing_std=BEARING_STD,
        max_range=3.0,
        initial_xy_std=0.05,
        initial_theta_std=0.1,
        linearization=linearization,
        relinearize_gate=relinearize_gate,
        gate_known=1.0,
    )
    motion = UnicycleMotion(NOISE)
    truth = Transform2D(0.0, -1.0, 0.0)
    slam = EkfSlam(config, motion, Transform2D(0.0, -1.0, rng.normal(0.0, 0.1)))
    u = (0.5, 0.5, DT_NS)
    P_tt_before, P_tt_after = None, math.inf
    for step in range(STEPS):
        # the truth moves with the model's noise (one draw of Q's square root per step is enough here)
        q, _, Q = motion.step(truth, u)
        truth = Transform2D(*(q + np.linalg.cholesky(Q + 1e-15 * np.eye(3)) @ rng.normal(size=3)))
        slam.predict(u)
        if step < STEPS_BEFORE_FIRST_LANDMARK:
            continue
        if P_tt_before is None:
            P_tt_before = slam.pose_covariance[2, 2]
        z, _, _ = predict_observations(truth.as_array(), LANDMARKS, config.T_body_sensor)
        seen = np.flatnonzero(z[:, 0] <= config.max_range)
        z = z[seen] + rng.normal(size=(len(seen), 2)) * [RANGE_STD, BEARING_STD]
        slam.update_known(seen, z)
        P_tt_after = min(P_tt_after, slam.pose_covariance[2, 2])
    error = math.remainder(truth.theta - slam.pose.theta, math.tau)
    return P_tt_before, P_tt_after, error, slam.pose_covariance[2, 2]


@pytest.mark.parametrize("linearization", ["fej", "oc", "invariant"])
@pytest.mark.parametrize("seed", range(3))
def test_the_remedies_never_gain_global_heading_information(linearization, seed):
    # invariant: the heading variance is P_xi[theta, theta], which the updates (heading column of H T
    # zero) leave unchanged up to rounding
    before, smallest, _, _ = run(linearization, seed)
    assert smallest >= before * (1.0 - 1e-9)


@pytest.mark.parametrize("linearization", ["fej", "oc"])
def test_first_estimates_are_reset_beyond_the_relinearize_gate(linearization):
    # a gate every estimate passes (the first estimates of this world are sound) changes nothing; a gate
    # of probability ~0 resets every first estimate after every update: the Jacobians of the newest
    # estimates, so the spurious heading information is back
    assert run(linearization, 0, relinearize_gate=1.0 - 1e-12) == run(linearization, 0)
    before, smallest, _, _ = run(linearization, 0, relinearize_gate=1e-9)
    assert smallest < 0.9 * before


@pytest.mark.parametrize("seed", range(3))
def test_the_standard_ekf_does(seed):
    # the spurious information the remedy removes: without it the heading variance shrinks below the
    # value no relative observation can improve on
    before, smallest, _, _ = run("standard", seed)
    assert smallest < 0.9 * before


@pytest.mark.parametrize(
    ("linearization", "consistent"), [("fej", True), ("oc", True), ("invariant", True), ("standard", False)]
)
def test_final_heading_error_against_the_filter_sigma(linearization, consistent):
    # 30 seeds: the final heading error squared over the filter's variance is chi2(1) when the filter is
    # honest; the mean of 30 lies below 1.65 with 97.5 % probability (chi2(30) / 30)
    ratios = [
        error**2 / variance for _, _, error, variance in (run(linearization, 100 + s) for s in range(30))
    ]
    assert (np.mean(ratios) < 1.65) == consistent


@settings(max_examples=50, deadline=None)
@given(
    pose=st.tuples(st.floats(-5, 5), st.floats(-5, 5), st.floats(-3, 3)),
    offset=st.tuples(st.floats(-0.5, 0.5), st.floats(-0.5, 0.5)),
    shift=st.tuples(st.floats(-1, 1), st.floats(-1, 1)),
    seed=st.integers(0, 1000),
)
def test_oc_jacobians_have_the_unobservable_directions_in_their_null_space(pose, offset, shift, seed):
    from turtlelib.estimation.linearization import observability_constrained

    landmarks = np.random.default_rng(seed).uniform(-6.0, 6.0, (4, 2)) + pose[:2] + 0.5
    T_body_sensor = Transform2D(*offset, 0.0)
    _, H_robot, H_landmark = predict_observations(np.array(pose), landmarks, T_body_sensor)
    # N built at other (first) estimates than the Jacobians' own point
    first = landmarks + shift
    H_robot_oc, H_landmark_oc = observability_constrained(H_robot, H_landmark, np.array(pose), first)
    for k in range(len(landmarks)):
        N = np.zeros((5, 3))
        N[[0, 1, 3, 4], [0, 1, 0, 1]] = 1.0
        N[:, 2] = [-pose[1], pose[0], 1.0, -first[k, 1], first[k, 0]]
        H_oc = np.hstack([H_robot_oc[k], H_landmark_oc[k]])
        np.testing.assert_allclose(H_oc @ N, 0.0, atol=1e-9)
        # the smallest change that does it: what was removed lies in the span of N^T
        change = np.hstack([H_robot[k], H_landmark[k]]) - H_oc
        np.testing.assert_allclose(change @ (np.eye(5) - N @ np.linalg.pinv(N)), 0.0, atol=1e-9)


def test_oc_changes_nothing_when_the_jacobian_already_respects_the_null_space():
    from turtlelib.estimation.linearization import observability_constrained

    pose, landmarks = np.array([0.3, -0.2, 0.7]), np.array([[2.0, 1.0], [-1.0, 3.0]])
    # sensor at the body origin, N at the Jacobians' own point: H N = 0 already
    _, H_robot, H_landmark = predict_observations(pose, landmarks, Transform2D())
    H_robot_oc, H_landmark_oc = observability_constrained(H_robot, H_landmark, pose, landmarks)
    np.testing.assert_allclose(H_robot_oc, H_robot, atol=1e-12)
    np.testing.assert_allclose(H_landmark_oc, H_landmark, atol=1e-12)


@pytest.mark.parametrize("linearization", ["standard", "fej", "oc", "invariant"])
def test_propagated_pose_is_what_predict_gives_after_an_update(linearization):
    # after an update the pose has left its prior: the first propagated step must use the same G as predict
    config = SlamConfig(
        linearization=linearization, initial_xy_std=0.1, initial_theta_std=0.1, gate_known=1.0
    )
    slam = EkfSlam(config, UnicycleMotion(NOISE))
    slam.predict((0.5, 0.3, DT_NS))
    slam.update_known([0, 1], [[2.0, 0.3], [1.5, -0.8]])
    slam.update_known([0, 1], [[1.9, 0.35], [1.6, -0.75]])
    inputs = [(0.5, 0.3, DT_NS), (0.4, -0.2, DT_NS)]
    T, P = slam.propagated_pose_along(inputs)
    for u in inputs:
        slam.predict(u)
    np.testing.assert_allclose(T.as_array(), slam.pose.as_array(), atol=1e-12)
    np.testing.assert_allclose(P, slam.pose_covariance, atol=1e-12)
