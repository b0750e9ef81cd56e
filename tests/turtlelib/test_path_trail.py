"""PathTrail: distance/turn decimation and a bounded length."""

from __future__ import annotations

import math
from itertools import pairwise

import pytest
from hypothesis import given
from hypothesis import strategies as st

from turtlelib import Transform2D, normalize_angle
from turtlelib.geometry.path_trail import PathTrail, PathTrailConfig


def test_keeps_the_first_pose_then_only_after_the_step_or_turn_thresholds():
    trail = PathTrail(PathTrailConfig(path_min_step_m=0.1, path_min_turn_rad=0.5, path_max_poses=100))
    assert trail.offer(Transform2D(0.0, 0.0, 0.0), "start")
    assert not trail.offer(Transform2D(0.09, 0.0, 0.0), "too close")
    assert not trail.offer(Transform2D(0.06, 0.06, 0.49), "still too close")  # 0.085 m, 0.49 rad
    assert trail.offer(Transform2D(0.06, 0.08, 0.0), "0.1 m away")
    assert trail.offer(Transform2D(0.06, 0.08, -0.5), "turned 0.5 rad")
    # turning across +-pi counts the short way round: pi - 0.1 to -pi + 0.1 is 0.2 rad
    trail.offer(Transform2D(5.0, 5.0, math.pi - 0.1), "far")
    assert not trail.offer(Transform2D(5.0, 5.0, -math.pi + 0.1), "0.2 rad")
    assert list(trail.items) == ["start", "0.1 m away", "turned 0.5 rad", "far"]


def test_drops_the_oldest_beyond_the_maximum_length_and_clear_starts_again():
    trail = PathTrail(PathTrailConfig(path_min_step_m=0.0, path_min_turn_rad=0.0, path_max_poses=3))
    for k in range(5):
        assert trail.offer(Transform2D(float(k), 0.0, 0.0), k)
    assert list(trail.items) == [2, 3, 4]
    trail.clear()
    assert list(trail.items) == []
    assert trail.offer(Transform2D(4.0, 0.0, 0.0), "again")  # the first after clear is always kept


@given(st.lists(st.tuples(st.floats(-1, 1), st.floats(-1, 1), st.floats(-3, 3)), min_size=1, max_size=60))
def test_consecutive_kept_poses_are_separated_by_a_threshold(poses):
    config = PathTrailConfig(path_min_step_m=0.2, path_min_turn_rad=0.3, path_max_poses=1000)
    trail = PathTrail(config)
    for x, y, theta in poses:
        T = Transform2D(x, y, theta)
        trail.offer(T, T)
    kept = list(trail.items)
    assert kept[0] == Transform2D(*poses[0])
    for a, b in pairwise(kept):
        step = math.hypot(b.x - a.x, b.y - a.y)
        turn = abs(normalize_angle(b.theta - a.theta))
        assert step >= config.path_min_step_m or turn >= config.path_min_turn_rad


def test_the_trail_is_due_at_most_once_per_period_and_only_with_a_new_pose():
    trail = PathTrail(PathTrailConfig(path_min_step_m=0.1, path_min_turn_rad=1.0, path_period=1.0))
    assert not trail.publish_due(0)  # nothing kept yet
    trail.offer(Transform2D(0.0, 0.0, 0.0), "a")
    assert trail.publish_due(10**9)  # the first pose: at once
    trail.offer(Transform2D(0.5, 0.0, 0.0), "b")
    assert not trail.publish_due(10**9 + 999_999_999)  # within the period
    assert trail.publish_due(2 * 10**9)  # a period later, with "b"
    assert not trail.publish_due(5 * 10**9)  # nothing new since
    trail.offer(Transform2D(0.55, 0.0, 0.0), "too close")  # not kept: still nothing new
    assert not trail.publish_due(6 * 10**9)
    trail.offer(Transform2D(1.0, 0.0, 0.0), "c")
    assert trail.publish_due(3 * 10**9)  # time went back (a restarted clock): due again
    trail.clear()
    trail.offer(Transform2D(1.0, 0.0, 0.0), "again")
    assert trail.publish_due(3 * 10**9 + 1)  # after clear, the first pose at once


@given(st.lists(st.integers(0, 3 * 10**9), min_size=1, max_size=80), st.floats(0.0, 2.0))
def test_publications_are_a_period_apart_and_the_newest_pose_waits_at_most_one_period(gaps_ns, period_s):
    """Poses kept at increasing stamps: two publications are at least ``path_period`` apart, and each
    pose is published by the first stamp a period after the previous publication."""
    trail = PathTrail(PathTrailConfig(path_min_step_m=0.0, path_min_turn_rad=0.0, path_period=period_s))
    period_ns = round(period_s * 1e9)
    stamp_ns, published = 0, []
    for k, gap_ns in enumerate(gaps_ns):
        stamp_ns += gap_ns
        trail.offer(Transform2D(float(k), 0.0, 0.0), k)
        if trail.publish_due(stamp_ns):
            published.append(stamp_ns)
        elif published:
            assert stamp_ns - published[-1] < period_ns
    assert published and published[0] == gaps_ns[0]
    assert all(b - a >= period_ns for a, b in pairwise(published))


@pytest.mark.parametrize(
    "fields",
    [
        dict(path_period=-1.0),
        dict(path_period=math.inf),
        dict(path_min_step_m=-0.1),
        dict(path_min_step_m=math.nan),
        dict(path_min_turn_rad=math.inf),
        dict(path_max_poses=0),
    ],
)
def test_config_rejects_invalid_values(fields):
    with pytest.raises(ValueError, match=next(iter(fields))):
        PathTrailConfig(**fields)
