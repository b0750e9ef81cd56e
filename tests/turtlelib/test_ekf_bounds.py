"""The filter's bounds on implausible input: min_range, max_observations, max_landmarks, a motion step that
overflows, and the timeline's waiting queue (max_observation_lead, newest-first eviction)."""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest

from turtlelib import DiffDrive, DiffDriveMotion, SlamTimeline, TimelineConfig, WheelAngles
from turtlelib.estimation.ekf_slam import EkfSlam, ObservationStatus, SlamConfig

BURGER = DiffDrive(wheel_radius=0.033, track_width=0.16)
MOTION = DiffDriveMotion(BURGER, 0.05)
CONFIG = SlamConfig(initial_xy_std=0.01, initial_theta_std=0.01, confirm_count=1)
MS = 1_000_000  # ns


def state_of(slam: EkfSlam):
    return slam.state.copy(), slam.covariance.copy(), slam.landmark_ids.copy(), slam.tentative_ids.copy()


def assert_same(a, b):
    for x, y in zip(a, b, strict=True):
        np.testing.assert_array_equal(x, y)


def ring(count: int, range_m: float = 1.0) -> np.ndarray:
    """``count`` observations [range, bearing] around the sensor, far apart."""
    return np.column_stack([np.full(count, range_m), np.linspace(-3.0, 3.0, count)])


def update(slam: EkfSlam, association: str, z, ids=None, stamp_ns: int = 0):
    """One update in either mode (``ids`` default: 0, 1, ... for known association)."""
    if association == "known":
        return slam.update_known(np.arange(len(z)) if ids is None else ids, z)
    return slam.update_unknown(z, stamp_ns=stamp_ns)


@pytest.mark.parametrize("association", ["known", "unknown"])
def test_an_observation_nearer_than_min_range_is_rejected_and_changes_nothing(association):
    slam = EkfSlam(CONFIG, MOTION)
    update(slam, association, [[1.0, 0.3]])
    before = state_of(slam)
    # 1 nm away, and just inside range_min
    result = update(slam, association, [[1e-9, 0.0], [CONFIG.min_range * 0.99, 1.0]], ids=[5, 6], stamp_ns=1)
    assert (result.status == ObservationStatus.REJECTED).all()
    assert_same(before, state_of(slam))
    # at min_range exactly it is used
    result = update(slam, association, [[CONFIG.min_range, 1.0]], ids=[7], stamp_ns=2)
    assert result.status.tolist() == [ObservationStatus.NEW]


@pytest.mark.parametrize("association", ["known", "unknown"])
def test_more_than_max_observations_in_one_update_raise_and_change_nothing(association):
    slam = EkfSlam(dataclasses.replace(CONFIG, max_observations=10), MOTION)
    before = state_of(slam)
    with pytest.raises(ValueError, match="max_observations = 10"):
        update(slam, association, ring(11))
    assert_same(before, state_of(slam))
    update(slam, association, ring(10))
    assert len(slam.landmark_ids) == 10


def test_known_association_stops_adding_landmarks_at_max_landmarks():
    slam = EkfSlam(dataclasses.replace(CONFIG, max_landmarks=3), MOTION)
    result = slam.update_known([10, 11, 12, 13, 14], ring(5))
    assert result.status.tolist() == [ObservationStatus.NEW] * 3 + [ObservationStatus.REJECTED] * 2
    assert result.landmark_ids.tolist() == [10, 11, 12, -1, -1]
    assert slam.map_full and slam.landmark_ids.tolist() == [10, 11, 12]
    assert slam.covariance.shape == (3 + 2 * 3, 3 + 2 * 3)
    # the mapped ones are still fused
    again = slam.update_known([12, 15], ring(5)[[2, 3]])
    assert again.status.tolist() == [ObservationStatus.MATCHED, ObservationStatus.REJECTED]


def test_unknown_association_stops_starting_landmarks_at_max_landmarks_until_one_is_dropped():
    config = dataclasses.replace(CONFIG, max_landmarks=2, confirm_count=3, tentative_timeout=0.5)
    slam = EkfSlam(config, MOTION)
    result = slam.update_unknown(ring(4), stamp_ns=0)
    assert (result.status == ObservationStatus.NEW).sum() == 2
    assert (result.status == ObservationStatus.REJECTED).sum() == 2
    assert slam.map_full
    # the two tentative ones expire unconfirmed: room again
    slam.update_unknown(np.zeros((0, 2)), stamp_ns=600 * MS)
    assert not slam.map_full
    assert (slam.update_unknown(ring(4)[2:], stamp_ns=700 * MS).status == ObservationStatus.NEW).all()


def test_a_motion_step_that_overflows_raises_and_leaves_the_filter_unchanged():
    slam = EkfSlam(CONFIG, MOTION)
    slam.update_known([0, 1], ring(2))
    before = state_of(slam)
    for u in [(1e200, 1e200), (1e200, -1e200), (1e308, 0.0)]:
        with np.errstate(over="ignore", invalid="ignore"), pytest.raises(ValueError):
            slam.predict(u)
        with np.errstate(over="ignore", invalid="ignore"), pytest.raises(ValueError):
            slam.propagated_pose_along([u])
        assert_same(before, state_of(slam))
        assert np.isfinite(slam.covariance).all()


@pytest.mark.parametrize(
    ("field", "value"),
    [
        ("min_range", -0.1),
        ("min_range", 3.5),  # not below max_range
        ("max_landmarks", 0),
        ("max_landmarks", 2.5),
        ("max_observations", 0),
    ],
)
def test_invalid_bounds_raise(field, value):
    with pytest.raises(ValueError):
        dataclasses.replace(CONFIG, **{field: value})


# --- the waiting queue ------------------------------------------------------------------------------------


def timeline(**config) -> SlamTimeline:
    t = SlamTimeline(EkfSlam(CONFIG, MOTION), WheelAngles(), TimelineConfig(**config))
    t.add_motion(0, (0.0, 0.0))
    t.add_motion(50 * MS, (0.1, 0.1))
    return t


def test_an_observation_stamped_beyond_max_observation_lead_is_refused():
    t = timeline(max_observation_lead=1.0)
    with pytest.raises(ValueError, match="max_observation_lead"):
        t.add_observations(50 * MS + 1_000 * MS + 1, ring(1))
    assert t.pending_count == 0
    assert t.add_observations(50 * MS + 1_000 * MS, ring(1)) == []
    assert t.pending_count == 1


def test_a_full_queue_lets_an_older_observation_displace_the_newest_waiting_one():
    t = timeline(max_pending_observations=3, max_observation_lead=1000.0)
    # three observations stamped far ahead fill the queue
    for k in range(3):
        t.add_observations((500 + 100 * k) * MS, ring(1))
    with pytest.raises(ValueError, match="already wait"):
        t.add_observations(900 * MS, ring(1))
    # a real one just past the newest sample takes the newest one's place, and is applied when motion
    # reaches it
    t.add_observations(60 * MS, ring(1))
    assert t.pending_count == 3
    applied = t.add_motion(100 * MS, (0.2, 0.2))
    assert [result.t_ns for result in applied] == [60 * MS]
    assert t.pending_count == 2
