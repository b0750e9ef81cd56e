"""nuturtle_eval.relative_error: the pairs of a path-distance band, hand-computed errors, invariance to the
estimate's frame."""

import math

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from nuturtle_eval.metrics import PoseSeries
from nuturtle_eval.relative_error import band_pairs, path_length_m, relative_pose_error
from turtlelib import Transform2D


def _pairs(path_m, min_m, max_m, chunk):
    pieces = list(band_pairs(path_m, min_m, max_m, chunk))
    if not pieces:
        return np.zeros(0, int), np.zeros(0, int)
    return np.concatenate([i for i, _ in pieces]), np.concatenate([j for _, j in pieces])


@settings(max_examples=40, deadline=None)
@given(
    steps=st.lists(st.floats(0.0, 0.8), min_size=0, max_size=60),
    min_m=st.floats(0.05, 2.0),
    width_m=st.floats(0.0, 3.0),
    chunk=st.integers(1, 50),
)
def test_band_pairs_are_every_pair_in_the_band_whatever_the_piece_size(steps, min_m, width_m, chunk):
    s = np.concatenate([[0.0], np.cumsum(steps)])
    i, j = _pairs(s, min_m, min_m + width_m, chunk)
    # s_i + min_m <= s_j <= s_i + max_m, row i, column j
    low, high = s[:, None] + min_m, s[:, None] + (min_m + width_m)
    expected_i, expected_j = np.nonzero((s[None, :] >= low) & (s[None, :] <= high))
    np.testing.assert_array_equal(i, expected_i)
    np.testing.assert_array_equal(j, expected_j)


def test_band_pairs_refuse_a_bad_band():
    for low, high in ((0.0, 1.0), (2.0, 1.0), (1.0, math.inf)):
        with pytest.raises(ValueError, match="min_m"):
            next(band_pairs(np.arange(5.0), low, high))


def test_path_length_is_the_sum_of_the_steps():
    np.testing.assert_allclose(path_length_m([[0, 0], [3, 4], [3, 5]]), [0.0, 5.0, 6.0])
    assert path_length_m(np.zeros((0, 2))).shape == (0,)


def test_hand_computed_scale_and_heading_errors():
    # the reference drives 3 m along x, one pose a metre; the estimate sees 1.1 m a metre and its last
    # heading is 0.05 rad off
    t = np.arange(4.0)
    reference = PoseSeries(t, np.column_stack([t, np.zeros(4), np.zeros(4)]))
    estimate = PoseSeries(t, np.column_stack([1.1 * t, np.zeros(4), [0.0, 0.0, 0.0, 0.05]]))
    rpe = relative_pose_error(estimate, reference, 1.0, 3.0)
    # pairs 1 m apart err 0.1 m (three), 2 m 0.2 m (two), 3 m 0.3 m (one); three pairs end at the last pose
    assert rpe.pairs == 6
    assert rpe.translation_m == pytest.approx((3 * 0.1 + 2 * 0.2 + 0.3) / 6)
    assert rpe.rotation_deg == pytest.approx(math.degrees(3 * 0.05 / 6))
    only_long = relative_pose_error(estimate, reference, 2.5, 3.0)
    assert only_long.pairs == 1 and only_long.translation_m == pytest.approx(0.3)


def test_the_estimate_is_read_at_the_reference_stamps_it_covers():
    t = np.arange(6.0)
    reference = PoseSeries(t, np.column_stack([t, np.zeros(6), np.zeros(6)]))
    # twice as dense, covering stamps 1..4 only: exact at those stamps
    t_est = np.arange(1.0, 4.01, 0.5)
    estimate = PoseSeries(t_est, np.column_stack([t_est, np.zeros(t_est.size), np.zeros(t_est.size)]))
    rpe = relative_pose_error(estimate, reference, 1.0, 10.0)
    assert rpe.pairs == 6 and rpe.translation_m == pytest.approx(0.0) and rpe.rotation_deg == 0.0
    outside = PoseSeries(np.array([10.0, 11.0]), np.zeros((2, 3)))
    none = relative_pose_error(outside, reference)
    assert none.pairs == 0 and math.isnan(none.translation_m) and math.isnan(none.rotation_deg)


@settings(max_examples=25, deadline=None)
@given(
    seed=st.integers(0, 2**32 - 1),
    frame=st.tuples(st.floats(-50, 50), st.floats(-50, 50), st.floats(-math.pi, math.pi)),
)
def test_an_estimate_in_another_frame_has_the_same_error(seed, frame):
    rng = np.random.default_rng(seed)
    n = 80
    heading = np.cumsum(rng.normal(0.0, 0.2, n))
    xy = np.cumsum(0.3 * np.column_stack([np.cos(heading), np.sin(heading)]), axis=0)
    t = np.arange(n, dtype=float)
    reference = PoseSeries(t, np.column_stack([xy, heading]))
    noisy = reference.poses + rng.normal(0.0, 0.05, (n, 3))
    T = Transform2D(*frame)
    moved = np.array([(T @ Transform2D(*pose)).as_array() for pose in noisy])
    a = relative_pose_error(PoseSeries(t, noisy), reference)
    b = relative_pose_error(PoseSeries(t, moved), reference)
    assert a.pairs == b.pairs > 0
    assert b.translation_m == pytest.approx(a.translation_m, abs=1e-9)
    assert b.rotation_deg == pytest.approx(a.rotation_deg, abs=1e-7)
    exact = relative_pose_error(
        PoseSeries(t, np.array([(T @ Transform2D(*p)).as_array() for p in reference.poses])), reference
    )
    assert exact.translation_m == pytest.approx(0.0, abs=1e-9) and exact.rotation_deg == pytest.approx(
        0.0, abs=1e-7
    )
