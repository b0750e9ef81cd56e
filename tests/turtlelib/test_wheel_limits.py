"""Curvature-preserving wheel speed saturation: hand-computed cases and properties."""

from __future__ import annotations

import math

import pytest
from hypothesis import given
from hypothesis import strategies as st

from turtlelib.motion.wheel_limits import limit_wheel_speeds

LIMIT = 265 / 41.6666667  # the Burger's 6.36 rad/s

speeds = st.floats(-1e6, 1e6, allow_nan=False)
limits = st.floats(1e-3, 1e3)


def test_speeds_within_the_limit_are_unchanged():
    assert limit_wheel_speeds(1.5, -6.0, LIMIT) == (1.5, -6.0, 1.0)
    assert limit_wheel_speeds(LIMIT, -LIMIT, LIMIT) == (LIMIT, -LIMIT, 1.0)
    assert limit_wheel_speeds(0.0, 0.0, LIMIT) == (0.0, 0.0, 1.0)


def test_hand_computed_saturation_scales_both_wheels_by_one_factor():
    # (4, 8) with limit 6: s = 6 / 8 = 0.75 -> (3, 6)
    assert limit_wheel_speeds(4.0, 8.0, 6.0) == pytest.approx((3.0, 6.0, 0.75), abs=1e-15)
    # (-10, 2.5) with limit 5: s = 0.5 -> (-5, 1.25)
    assert limit_wheel_speeds(-10.0, 2.5, 5.0) == pytest.approx((-5.0, 1.25, 0.5), abs=1e-15)
    # spinning in place over the limit stays a spin in place
    assert limit_wheel_speeds(-12.72, 12.72, LIMIT) == pytest.approx((-LIMIT, LIMIT, 0.5), abs=1e-9)


def test_clipping_wheel_by_wheel_would_change_the_arc_but_scaling_does_not():
    # (8, 4) clipped to 6 each would be (6, 4): curvature (R - L) / (R + L) changes from -1/3 to -1/5
    left, right, _ = limit_wheel_speeds(8.0, 4.0, 6.0)
    assert (right - left) / (right + left) == pytest.approx(-1.0 / 3.0, rel=1e-15)


@given(speeds, speeds, limits)
def test_saturated_speeds_respect_the_limit_exactly_and_keep_the_ratio(left, right, limit):
    new_left, new_right, scale = limit_wheel_speeds(left, right, limit)
    assert abs(new_left) <= limit and abs(new_right) <= limit
    assert 0.0 < scale <= 1.0 or (left == right == 0.0 and scale == 1.0)
    assert new_left == pytest.approx(scale * left, rel=1e-12, abs=1e-300)
    assert new_right == pytest.approx(scale * right, rel=1e-12, abs=1e-300)
    # same direction of every wheel and the same ratio: cross product of (L, R) and (L', R') is zero
    assert math.copysign(1.0, new_left) == math.copysign(1.0, left) or new_left == left == 0.0
    assert abs(left * new_right - right * new_left) <= 1e-12 * max(abs(left), abs(right)) * limit
    if scale < 1.0:
        assert max(abs(new_left), abs(new_right)) == pytest.approx(limit, rel=1e-15)


@pytest.mark.parametrize(
    "args",
    [
        (math.nan, 0.0, 1.0),
        (0.0, math.inf, 1.0),
        (1.0, 1.0, 0.0),
        (1.0, 1.0, -1.0),
        (1.0, 1.0, math.inf),
    ],
)
def test_invalid_input_raises(args):
    with pytest.raises(ValueError):
        limit_wheel_speeds(*args)
