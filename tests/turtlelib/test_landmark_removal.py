"""turtlelib.estimation.landmark_removal: a confirmed post that is gone is removed once the LiDAR sees
through where it was; posts that stay are never removed (the seeded world of slam_world, its posts
cylinders of radius 0.05 m in a 6 m square room scanned by an LDS-01 with 1 cm noise)."""

from __future__ import annotations

import numpy as np
import pytest
from slam_world import CONFIG, MOTION, N_SCANS, SCAN_PERIOD_NS, World

from turtlelib import EkfSlam, LidarConfig, RangeScan, Transform2D, simulate_scan
from turtlelib.estimation.landmark_removal import LandmarkRemoval, LandmarkRemovalConfig, MountedScan

POST_RADIUS = 0.05
POSTS = np.array([[1.2, 0.5], [-0.8, 0.9], [0.3, -0.6], [0.2, 1.7]])
ROOM = np.array([[-3, -3, 3, -3], [3, -3, 3, 3], [3, 3, -3, 3], [-3, 3, -3, -3]], dtype=float)
LIDAR = LidarConfig(noise=0.01, no_return=0.0)
REMOVAL = LandmarkRemovalConfig(see_through_radius=0.04)


def run(moved: bool, loops: int = 3, seed: int = 4) -> tuple[EkfSlam, LandmarkRemoval, World, float]:
    """Drive ``loops`` loops among ``POSTS``; with ``moved``, post 0 moves 0.5 m after the first. Returns the
    filter, the removal step, the world and the largest position error after the first loop."""
    world = World(seed, POSTS.copy())
    slam = EkfSlam(CONFIG, MOTION)
    removal = LandmarkRemoval(REMOVAL)
    worst_m = 0.0
    for k in range(loops * N_SCANS):
        if moved and k == N_SCANS:
            world.landmarks[0] += [0.0, 0.5]
        world.step(slam)
        stamp_ns = (k + 1) * SCAN_PERIOD_NS
        slam.update_unknown(world.observe()[1], stamp_ns=stamp_ns)
        T_world_scan = world.T_world_body @ CONFIG.T_body_sensor
        circles = np.column_stack([world.landmarks, np.full(len(POSTS), POST_RADIUS)])
        ranges = simulate_scan(T_world_scan, circles, ROOM, LIDAR, world.rng)
        scan = RangeScan(ranges, LIDAR.angle_min, LIDAR.angle_increment, LIDAR.range_min, LIDAR.range_max)
        removal.apply(slam, MountedScan(scan, CONFIG.T_body_sensor), stamp_ns)
        if k >= N_SCANS:
            error = slam.pose.translation - world.T_world_body.translation
            worst_m = max(worst_m, float(np.hypot(*error)))
    return slam, removal, world, worst_m


def test_a_post_moved_half_a_metre_is_removed_and_mapped_again_at_its_new_place():
    slam, removal, world, worst_m = run(moved=True)
    # the old post 0 is gone from the map, the moved one mapped where it is now, the others kept
    assert len(removal.removals) == 1
    assert removal.removals[0].landmark_id not in slam.landmark_ids
    assert np.linalg.norm(removal.removals[0].xy - POSTS[0]) < 0.05
    assert removal.removals[0].scans == REMOVAL.see_through_scans
    distances = np.linalg.norm(slam.landmarks[:, None] - world.landmarks[None], axis=2)
    assert len(slam.landmark_ids) == len(POSTS)
    assert distances.min(axis=0).max() < 0.05
    # the pose stays within the targets throughout
    assert worst_m < 0.05


def test_posts_that_stay_are_never_removed():
    slam, removal, _, worst_m = run(moved=False)
    assert removal.removals == []
    assert len(slam.landmark_ids) == len(POSTS)
    assert worst_m < 0.05


def test_scans_that_say_nothing_never_change_the_filter():
    """Every post out of reach (a scan whose range_max is 0.2 m): no count, the filter as without."""
    world = World(1, POSTS.copy())
    slam = EkfSlam(CONFIG, MOTION)
    for k in range(N_SCANS):
        world.step(slam)
        slam.update_unknown(world.observe()[1], stamp_ns=(k + 1) * SCAN_PERIOD_NS)
    before = slam.state.copy(), slam.covariance.copy()
    removal = LandmarkRemoval(REMOVAL)
    blind = RangeScan(np.full(360, np.inf), 0.0, 2 * np.pi / 360, 0.12, 0.2)
    for _ in range(10):
        removal.apply(slam, MountedScan(blind, Transform2D()), (N_SCANS + 1) * SCAN_PERIOD_NS)
    np.testing.assert_array_equal(slam.state, before[0])
    np.testing.assert_array_equal(slam.covariance, before[1])
    assert removal.removals == []


def test_remove_landmark_marginalises_it_out():
    slam, _, _, _ = run(moved=False, loops=1)
    ids, x, P = slam.landmark_ids, slam.state, slam.covariance
    slam.remove_landmark(int(ids[1]))
    keep = np.r_[0:5, 7 : len(x)]  # landmark ids[1] is at 5, 6
    np.testing.assert_array_equal(slam.landmark_ids, np.delete(ids, 1))
    np.testing.assert_allclose(slam.state, x[keep], rtol=0, atol=0)
    np.testing.assert_allclose(slam.covariance, P[np.ix_(keep, keep)], rtol=0, atol=1e-15)
    with pytest.raises(ValueError):
        slam.remove_landmark(int(ids[1]))


@pytest.mark.parametrize(
    ("field", "value"),
    [("see_through_scans", -1), ("see_through_scans", 1.5), ("see_through_sigmas", 0.0),
     ("see_through_radius", -0.1), ("see_through_travel", -1.0), ("see_through_range_std", 0.0)],
)  # fmt: skip
def test_invalid_config_is_a_value_error(field: str, value: object):
    with pytest.raises(ValueError):
        LandmarkRemovalConfig(**{field: value})
