"""First-estimates Jacobians (SlamConfig.linearization = 'fej'): the filter gains no information about the
global heading, which relative observations cannot give (Huang, Mourikis & Roumeliotis 2008).

The world: a unicycle drives two loops of a circle among six landmarks, with twist noise as its model says
and noisy range-bearing observations. The standard EKF's heading variance falls below its value when the
first landmark was seen (spurious information); with FEJ it never does.
"""

import math

import numpy as np
import pytest

from turtlelib import Transform2D, TwistNoise, UnicycleMotion
from turtlelib.ekf_slam import EkfSlam, SlamConfig
from turtlelib.range_bearing import predict_observations

LANDMARKS = np.array([[2.0, 0.0], [1.0, 2.2], [-1.5, 1.5], [-2.0, -0.5], [0.0, -2.0], [1.6, -1.4]])
NOISE = TwistNoise(forward_m2_per_m=1e-3, heading_rad2_per_m=2e-3, heading_rad2_per_rad=1e-3)
DT_NS = 100_000_000
STEPS = 2 * 126  # two loops at 0.5 rad/s, 10 Hz
STEPS_BEFORE_FIRST_LANDMARK = 20
RANGE_STD, BEARING_STD = 0.05, 0.02


def run(linearization: str, seed: int) -> tuple[float, float, float, float]:
    """``(P_tt when the first landmark is seen, min P_tt afterwards, final heading error, final P_tt)``."""
    rng = np.random.default_rng(seed)
    config = SlamConfig(
        range_std=RANGE_STD,
        bearing_std=BEARING_STD,
        max_range=3.0,
        initial_xy_std=0.05,
        initial_theta_std=0.1,
        linearization=linearization,
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


@pytest.mark.parametrize("seed", range(3))
def test_fej_never_gains_global_heading_information(seed):
    before, smallest, _, _ = run("fej", seed)
    assert smallest >= before * (1.0 - 1e-9)


@pytest.mark.parametrize("seed", range(3))
def test_the_standard_ekf_does(seed):
    # the spurious information the remedy removes: without it the heading variance shrinks below the
    # value no relative observation can improve on
    before, smallest, _, _ = run("standard", seed)
    assert smallest < 0.9 * before


@pytest.mark.parametrize(("linearization", "consistent"), [("fej", True), ("standard", False)])
def test_final_heading_error_against_the_filter_sigma(linearization, consistent):
    # 30 seeds: the final heading error squared over the filter's variance is chi2(1) when the filter is
    # honest; the mean of 30 lies below 1.65 with 97.5 % probability (chi2(30) / 30)
    ratios = [
        error**2 / variance for _, _, error, variance in (run(linearization, 100 + s) for s in range(30))
    ]
    assert (np.mean(ratios) < 1.65) == consistent
