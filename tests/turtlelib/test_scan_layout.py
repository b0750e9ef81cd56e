"""check_scan_layout: the layouts real drivers publish pass, self-contradicting ones are refused;
beams_in_one_turn: the beams of one full turn, what the detector keeps."""

from __future__ import annotations

import math

import numpy as np
import pytest
from hypothesis import assume, given, settings
from hypothesis import strategies as st

from turtlelib import beams_in_one_turn, check_scan_layout

DEG = math.pi / 180
# Gazebo's LiDAR (turtlebot3_gazebo, every model), as the float32 fields of the first /scan of the shared
# recording tb3_gazebo_burger read them back: 360 beams from 0 to 6.28 rad, so the increment is 6.28 / 359
GAZEBO = (360, 0.0, 6.28000020980835, 0.01749303564429283)
# an LDS-02 scan (ld08_driver): angle_min and angle_max are the first and last measured angles of the
# turn, the increment comes from the spin rate (2160 deg/s / 2300 = 0.939 deg), and the beams number
# ceil((angle_max - angle_min) / angle_increment)
LDS02_INCREMENT = 2160.0 / 2300.0 * DEG
LDS02 = (382, 0.3 * DEG, 0.3 * DEG + 382 * LDS02_INCREMENT - 0.2 * LDS02_INCREMENT, LDS02_INCREMENT)


@pytest.mark.parametrize(
    ("samples", "angle_min", "angle_max", "angle_increment"),
    [
        (360, 0.0, 359 * DEG, DEG),  # last beam at angle_max (nusim)
        (360, 0.0, 2 * math.pi, DEG),  # the LDS-01 driver: angle_max one increment past the last beam
        GAZEBO,  # more than one turn: the last beam repeats the first
        LDS02,  # the last beam a fraction of an increment before angle_max
        (361, 0.0, 2 * math.pi, DEG),  # the first beam repeated exactly
        (720, -math.pi, math.pi - 0.5 * DEG, 0.5 * DEG),  # half-degree, centred
        (181, math.pi / 2, -math.pi / 2, -DEG),  # clockwise
        (1, 0.3, 0.3, DEG),  # a single beam
        # float32 rounding of every field, as the message carries them
        (360, float(np.float32(0.0)), float(np.float32(2 * math.pi)), float(np.float32(DEG))),
    ],
)
def test_real_layouts_pass(samples, angle_min, angle_max, angle_increment):
    check_scan_layout(samples, angle_min, angle_max, angle_increment)


@pytest.mark.parametrize(
    ("samples", "angle_min", "angle_max", "angle_increment", "message"),
    [
        (360, 0.0, 359 * DEG, -DEG, "contradicts itself"),  # increment negated, angle_max unchanged
        (360, 0.0, 359 * DEG, 2 * DEG, "contradicts itself"),  # doubled
        (360, 0.0, 2 * math.pi, 2 * DEG, "contradicts itself"),  # doubled, LDS-01's angle_max
        (720, 0.0, 359 * DEG, DEG, "contradicts itself"),  # 720 ranges for a 360-beam layout
        (720, 0.0, 6.28, 6.28 / 359, "contradicts itself"),  # twice Gazebo's ranges
        (360, 0.0, 6.28, -6.28 / 359, "contradicts itself"),  # Gazebo's increment negated
        (360, 0.0, 3.14, 6.28 / 359, "contradicts itself"),  # Gazebo's angle_max halved
        (358, 0.0, 359 * DEG, DEG, "contradicts itself"),  # two beams short
        (360, 1e10, 1e10 + 359 * DEG, DEG, "more than a turn from 0"),
        (360, math.nan, 359 * DEG, DEG, "finite"),
        (360, 0.0, math.inf, DEG, "finite"),
        (360, 0.0, 359 * DEG, 0.0, "!= 0"),
        (0, 0.0, 0.0, DEG, "non-empty"),
    ],
)
def test_contradicting_layouts_are_refused(samples, angle_min, angle_max, angle_increment, message):
    with pytest.raises(ValueError, match=message):
        check_scan_layout(samples, angle_min, angle_max, angle_increment)


@pytest.mark.parametrize(
    ("samples", "angle_increment", "kept"),
    [
        (360, DEG, 360),  # nusim, LDS-01: one turn exactly
        (360, float(np.float32(DEG)), 360),  # as float32
        (GAZEBO[0], GAZEBO[3], 359),  # beam 359 lies 0.0032 rad short of a turn: it repeats beam 0
        (GAZEBO[0], -GAZEBO[3], 359),  # clockwise
        (LDS02[0], LDS02[3], LDS02[0]),
        (361, DEG, 360),  # beam 360 is beam 0 again
        (720, 0.5 * DEG, 720),
        (1000, DEG, 360),  # several turns: the first
        (1, 10.0, 1),  # one beam is always kept
        (3, 4.0, 2),  # beams at 0 and 4 rad; 8 rad is 1.7 rad past the first
        (3, 5.0, 1),  # 5 rad is 1.3 rad short of a turn, more than half a step
    ],
)
def test_beams_in_one_turn_hand_computed(samples, angle_increment, kept):
    assert beams_in_one_turn(samples, angle_increment) == kept


@settings(max_examples=200, deadline=None)
@given(
    samples=st.integers(1, 5000),
    angle_increment=st.floats(1e-3, 7.0) | st.floats(-7.0, -1e-3),
)
def test_beams_in_one_turn_keep_distinct_directions_and_close_the_turn(samples, angle_increment):
    kept = beams_in_one_turn(samples, angle_increment)
    step = abs(angle_increment)
    assert 1 <= kept <= samples
    # every kept beam but the first lies more than half a step before the first beam one turn on
    assert (kept - 1) * step < math.tau - 0.5 * step or kept == 1
    if kept < samples:
        # the first dropped beam points within half a step of the first beam, one turn on, or further
        assert kept * step >= math.tau - 0.5 * step - 1e-12


@settings(max_examples=200, deadline=None)
@given(
    samples=st.integers(4, 2000),
    angle_min=st.floats(-math.pi, math.pi),
    turn_fraction=st.floats(1e-3, 1.0),
    clockwise=st.booleans(),
)
def test_a_consistent_layout_passes_and_its_contradicting_twins_do_not(
    samples, angle_min, turn_fraction, clockwise
):
    # the beams span up to one turn; angle_max is the last beam, as nusim and Gazebo publish it
    angle_increment = (-1.0 if clockwise else 1.0) * turn_fraction * 2.0 * math.pi / (samples - 1)
    angle_max = angle_min + (samples - 1) * angle_increment
    assume(abs(angle_max) <= 2.0 * math.pi)
    check_scan_layout(samples, angle_min, angle_max, angle_increment)
    # with angle_max unchanged, each twin's last beam lands more than its own increment off: (samples - 1)
    # increments for the doubled one (tolerance two), 2 (samples - 1) for the negated, samples for twice
    # the ranges
    for twin in (
        (samples, angle_min, angle_max, 2.0 * angle_increment),  # doubled increment
        (samples, angle_min, angle_max, -angle_increment),  # negated increment
        (2 * samples, angle_min, angle_max, angle_increment),  # twice the ranges
    ):
        with pytest.raises(ValueError, match="contradicts itself"):
            check_scan_layout(*twin)
