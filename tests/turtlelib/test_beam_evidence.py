"""turtlelib.sensing.beam_evidence: what a scan's beams say about posts expected at known places
(hand-computed scans on the LDS-01 layout: 360 beams of 1 degree from 0)."""

from __future__ import annotations

import math

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from turtlelib import LidarConfig, RangeScan, Transform2D, simulate_scan
from turtlelib.sensing.beam_evidence import Evidence, post_evidence

STEP = 2.0 * math.pi / 360.0
# a post of radius 0.1 m expected 1 m ahead: its core is beams -5..5 (asin(0.1) = 5.74 degrees)
POST = np.array([[1.0, 0.0]])
CERTAIN = 1e-8 * np.eye(2)[None]
RADIUS, RANGE_STD, SIGMAS = 0.1, 0.01, 3.0
CORE = np.r_[355:360, 0:6]


def lds01(ranges: np.ndarray) -> RangeScan:
    return RangeScan(ranges, 0.0, STEP, 0.12, 3.5)


def evidence(ranges: np.ndarray, p: np.ndarray = POST, covariance: np.ndarray = CERTAIN) -> list[int]:
    return post_evidence(lds01(ranges), p, covariance, RADIUS, RANGE_STD, SIGMAS).tolist()


def walls_at(range_m: float) -> np.ndarray:
    return np.full(360, range_m)


def test_a_post_in_front_of_a_wall_is_present_and_seen_through_once_gone():
    there = walls_at(2.0)
    there[CORE] = 0.9  # the post's near face
    assert evidence(there) == [Evidence.PRESENT]
    # gone: the core beams reach the wall, 2 m > 1 + 0.1 + 3 * 0.01
    assert evidence(walls_at(2.0)) == [Evidence.SEEN_THROUGH]
    # a wall just behind the post's far side (within the margin): something is there
    assert evidence(walls_at(1.12)) == [Evidence.PRESENT]


def test_a_post_hidden_by_a_nearer_one_is_no_evidence():
    hidden = walls_at(2.0)
    hidden[CORE] = 0.5
    assert evidence(hidden) == [Evidence.NONE]
    # partly hidden, the other core beams beyond: still nothing said
    hidden = walls_at(2.0)
    hidden[0:6] = 0.5
    assert evidence(hidden) == [Evidence.NONE]


def test_beams_without_a_return_count_as_beyond_but_dropouts_do_not():
    assert evidence(walls_at(math.inf)) == [Evidence.SEEN_THROUGH]
    assert evidence(walls_at(3.5)) == [Evidence.SEEN_THROUGH]  # at range_max: REP 117's no return
    assert evidence(walls_at(0.0)) == [Evidence.NONE]  # LDS-01: 0.0 for any missing return
    assert evidence(walls_at(math.nan)) == [Evidence.NONE]
    one_dropout = walls_at(math.inf)
    one_dropout[2] = 0.0
    assert evidence(one_dropout) == [Evidence.NONE]


def test_a_post_at_the_edge_of_range_or_out_of_range_is_no_evidence():
    # far side 3.4 + 0.1 + 0.03 beyond range_max 3.5: a no-return there proves nothing
    assert evidence(walls_at(math.inf), np.array([[3.4, 0.0]])) == [Evidence.NONE]
    assert evidence(walls_at(math.inf), np.array([[3.3, 0.0]])) == [Evidence.SEEN_THROUGH]
    # nearer than range_min
    assert evidence(walls_at(math.inf), np.array([[0.15, 0.0]])) == [Evidence.NONE]


def test_a_post_at_the_edge_of_the_field_of_view_is_no_evidence():
    # a front half scan: 181 beams from -90 to 90 degrees
    front = RangeScan(np.full(181, 2.0), -math.pi / 2, STEP, 0.12, 3.5)
    ahead, edge, behind = [1.0, 0.0], [0.0, 1.0], [-1.0, 0.0]
    got = post_evidence(front, np.array([ahead, edge, behind]), np.repeat(CERTAIN, 3, 0), RADIUS, 0.01, 3.0)
    assert got.tolist() == [Evidence.SEEN_THROUGH, Evidence.NONE, Evidence.NONE]
    # the full turn wraps: a post at bearing 0 has its core on both ends of the beams
    assert evidence(walls_at(2.0), np.array([[1.0, -0.0]])) == [Evidence.SEEN_THROUGH]


def test_an_uncertain_post_has_no_beam_surely_on_it():
    # bearing std 0.05 rad: 3 sigma (0.15) is wider than the silhouette's half-width (0.1)
    uncertain = np.diag([1e-6, 0.05**2])[None]
    assert evidence(walls_at(2.0), POST, uncertain) == [Evidence.NONE]
    # range std 0.3 m at 1.5 m: the wall at 2 m is within 3 sigma of the far side (2.5 m)
    uncertain = np.diag([0.3**2, 1e-8])[None]
    assert evidence(walls_at(2.0), np.array([[1.5, 0.0]]), uncertain) == [Evidence.PRESENT]
    # at 1 m its near side's margin (0.1 m) reaches below range_min: out of reach
    assert evidence(walls_at(2.0), POST, uncertain) == [Evidence.NONE]


def test_posts_are_judged_together():
    p = np.array([[1.0, 0.0], [0.0, 1.0], [3.4, 0.0], [-2.4, 0.0]])  # the last against the wall
    ranges = walls_at(2.5)
    ranges[85:96] = 0.9  # the post at (0, 1) is there
    got = post_evidence(lds01(ranges), p, np.repeat(CERTAIN, 4, 0), RADIUS, 0.01, 3.0)
    assert got.tolist() == [Evidence.SEEN_THROUGH, Evidence.PRESENT, Evidence.NONE, Evidence.PRESENT]
    assert post_evidence(lds01(ranges), np.zeros((0, 2)), np.zeros((0, 2, 2)), RADIUS, 0.01, 3.0).shape == (
        0,
    )


@settings(max_examples=60, deadline=None)
@given(
    seed=st.integers(0, 2**32 - 1),
    range_m=st.floats(0.3, 3.2),
    bearing=st.floats(-math.pi, math.pi),
    radius=st.floats(0.02, 0.2),
)
def test_a_post_that_is_there_is_never_seen_through(seed: int, range_m: float, bearing: float, radius: float):
    """A post of ``radius`` (its estimate off by a draw of its covariance) among walls, scanned with 1 cm
    noise: judged with any radius up to its own, it is never seen through."""
    rng = np.random.default_rng(seed)
    covariance = np.diag([0.01**2, 0.02**2])
    true_xy = range_m * np.array([math.cos(bearing), math.sin(bearing)])
    expected_xy = true_xy + rng.multivariate_normal(np.zeros(2), covariance) / 3.0
    walls = np.array(
        [[-4.0, -4.0, 4.0, -4.0], [4.0, -4.0, 4.0, 4.0], [4.0, 4.0, -4.0, 4.0], [-4.0, 4.0, -4.0, -4.0]]
    )
    lidar = LidarConfig(noise=0.01, no_return=0.0)
    ranges = simulate_scan(Transform2D(), np.array([[*true_xy, radius]]), walls, lidar, rng)
    scan = RangeScan(ranges, lidar.angle_min, lidar.angle_increment, lidar.range_min, lidar.range_max)
    judged = post_evidence(scan, expected_xy[None], covariance[None], radius, 0.01, 3.0)
    assert judged[0] != Evidence.SEEN_THROUGH


@pytest.mark.parametrize("bad", [np.zeros((1, 3)), np.zeros((2, 2))])
def test_shapes_must_agree(bad: np.ndarray):
    with pytest.raises(ValueError):
        post_evidence(lds01(walls_at(2.0)), bad, np.repeat(CERTAIN, 2, 0)[:1], RADIUS, 0.01, 3.0)
