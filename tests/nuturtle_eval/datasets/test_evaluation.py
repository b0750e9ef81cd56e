"""The published protocol's pairing of estimates with GPS fixes (``evaluation.pair_with_fixes``): a hand
case, its property against every fix, and its refusals."""

from __future__ import annotations

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from nuturtle_eval.datasets.evaluation import pair_with_fixes

MS = 1_000_000


def test_each_estimate_takes_its_nearest_fix_within_the_tolerance():
    fix_ms = np.array([0, 100, 200, 230])
    estimate_ms = np.array([-30, 25, 50, 90, 205, 215, 226, 300])
    estimates, fixes = pair_with_fixes(estimate_ms * MS, fix_ms * MS, 25 * MS)
    # -30: 30 ms before fix 0, out; 25: 25 ms after fix 0, in (the bound counts); 50: 50 ms from fixes 0
    # and 1, out; 90: fix 1 (10 ms); 205: fix 2 (5 ms); 215: 15 ms from fixes 2 and 3, the earlier one,
    # so fix 2 serves two estimates; 226: fix 3 (4 ms, fix 2 is 26 ms away); 300: 70 ms after fix 3, out
    np.testing.assert_array_equal(estimates, [1, 3, 4, 5, 6])
    np.testing.assert_array_equal(fixes, [0, 1, 2, 2, 3])
    # a tighter tolerance drops the estimates 25 ms (fix 0) and 15 ms (fix 2) away
    estimates, fixes = pair_with_fixes(estimate_ms * MS, fix_ms * MS, 10 * MS)
    np.testing.assert_array_equal(estimates, [3, 4, 6])
    np.testing.assert_array_equal(fixes, [1, 2, 3])


def test_one_fix_or_none():
    estimates, fixes = pair_with_fixes(np.array([-40, -20, 20, 40]) * MS, np.array([0]), 25 * MS)
    np.testing.assert_array_equal(estimates, [1, 2])
    np.testing.assert_array_equal(fixes, [0, 0])
    estimates, fixes = pair_with_fixes(np.array([0, 10]), np.zeros(0, dtype=np.int64), 25 * MS)
    assert estimates.size == 0 and fixes.size == 0


@settings(max_examples=60, deadline=None)
@given(
    fix_ms=st.lists(st.integers(0, 2000), min_size=1, max_size=20, unique=True),
    estimate_ms=st.lists(st.integers(-100, 2100), max_size=30),
    tolerance_ms=st.integers(0, 60),
)
def test_paired_fixes_are_the_nearest_and_the_unpaired_estimates_have_none_near(
    fix_ms, estimate_ms, tolerance_ms
):
    fix_t = np.sort(np.array(fix_ms, dtype=np.int64)) * MS
    t = np.array(estimate_ms, dtype=np.int64) * MS
    estimates, fixes = pair_with_fixes(t, fix_t, tolerance_ms * MS)
    gap = np.abs(t[:, None] - fix_t[None, :])
    for k, j in zip(estimates, fixes, strict=True):
        assert gap[k, j] == gap[k].min() <= tolerance_ms * MS
    unpaired = np.setdiff1d(np.arange(t.size), estimates)
    assert np.all(gap[unpaired].min(axis=1, initial=np.iinfo(np.int64).max) > tolerance_ms * MS)


@pytest.mark.parametrize(
    ("fix_t_ns", "tolerance_ns", "match"),
    [
        (np.array([0, 10, 10]), 5, "increasing"),
        (np.array([10, 0]), 5, "increasing"),
        (np.array([0]), -1, ">= 0"),
    ],
)
def test_pairing_refuses_unsorted_fixes_and_a_negative_tolerance(fix_t_ns, tolerance_ns, match):
    with pytest.raises(ValueError, match=match):
        pair_with_fixes(np.array([0]), fix_t_ns, tolerance_ns)
