"""RangeScan: the one validated scan the detector and the occupancy grid take."""

import math

import numpy as np
import pytest

from turtlelib import RangeScan

DEG = math.radians(1.0)


def test_a_scan_keeps_a_read_only_float64_copy_and_finds_its_returns():
    ranges = [0.5, 0.0, math.nan, math.inf, -1.0, 0.1, 3.5, 3.6]
    scan = RangeScan(ranges, 0.0, DEG, 0.12, 3.5)
    assert scan.ranges.dtype == np.float64 and not scan.ranges.flags.writeable
    np.testing.assert_array_equal(scan.returns(), [True, False, False, False, False, False, True, False])


@pytest.mark.parametrize(
    ("arguments", "message"),
    [
        (([], 0.0, DEG, 0.12, 3.5), "ranges must be a non-empty 1-D array"),
        (([[1.0, 1.0]], 0.0, DEG, 0.12, 3.5), "ranges must be a non-empty 1-D array"),
        (([1.0, 1.0], 0.0, 0.0, 0.12, 3.5), "angle_increment must be non-zero"),
        (([1.0, 1.0], 0.0, math.nan, 0.12, 3.5), "angle_increment must be a finite number"),
        (([1.0, 1.0], math.nan, DEG, 0.12, 3.5), "angle_min must be a finite number"),
        (([1.0, 1.0], math.inf, DEG, 0.12, 3.5), "angle_min must be a finite number"),
        (([1.0, 1.0], 0.0, DEG, 3.5, 3.5), "need range_min < range_max"),
        (([1.0, 1.0], 0.0, DEG, 3.5, 0.12), "need range_min < range_max"),
        (([1.0, 1.0], 0.0, DEG, math.nan, 3.5), "range_min"),
        (([1.0, 1.0], 0.0, DEG, 0.12, math.inf), "range_max must be a finite number"),
    ],
)
def test_an_invalid_scan_is_refused_with_the_reason(arguments, message):
    with pytest.raises(ValueError, match=message):
        RangeScan(*arguments)
