"""check_scan_layout: the layouts real drivers publish pass, self-contradicting ones are refused."""

from __future__ import annotations

import math

import numpy as np
import pytest

from turtlelib import check_scan_layout

DEG = math.pi / 180


@pytest.mark.parametrize(
    ("samples", "angle_min", "angle_max", "angle_increment"),
    [
        (360, 0.0, 359 * DEG, DEG),  # last beam at angle_max (nusim)
        (360, 0.0, 2 * math.pi, DEG),  # the LDS-01 driver: angle_max one increment past the last beam
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
        (360, 0.0, 359 * DEG, 2 * DEG, "more than one turn"),  # doubled
        (720, 0.0, 359 * DEG, DEG, "more than one turn"),  # 720 ranges for a 360-beam layout
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
