"""nuturtle_eval.grid_agreement: hand-computed endpoints, cells and fractions; a grid mapped at the
reference poses agrees with them, one mapped at shifted poses does not."""

import math

import numpy as np
import pytest

from nuturtle_eval.grid_agreement import (
    grid_agreement,
    occupied_cells,
    reference_cells,
    scan_endpoints,
    scan_grid_agreement,
)
from nuturtle_eval.metrics import PoseSeries
from turtlelib import LidarConfig, Transform2D, arena_walls, simulate_scan
from turtlelib.mapping.occupancy_grid import GridConfig, GridMap, OccupancyGrid
from turtlelib.sensing.range_scan import RangeScan


def test_endpoints_hand_computed_at_the_interpolated_pose_with_the_mount():
    reference = PoseSeries(np.array([0.0, 2.0]), np.array([[0.0, 2.0, 0.0], [2.0, 2.0, math.pi]]))
    # at t = 1 s the robot is at (1, 2) facing +y; the LiDAR sits 0.1 m ahead of the body
    scan = RangeScan(np.array([1.0, np.inf, 0.5]), -math.pi / 2, math.pi / 2, 0.1, 3.5)
    late = RangeScan(np.array([1.0]), 0.0, 0.1, 0.1, 3.5)
    points = scan_endpoints([(1.0, scan), (3.0, late)], reference, Transform2D(0.1, 0.0, 0.0))
    # beam 0 points along the body's -y (world +x), beam 2 along +y (world -x); the no-return is dropped
    np.testing.assert_allclose(points, [[2.0, 2.1], [0.5, 2.1]], atol=1e-12)


def test_cells_and_fractions_hand_computed():
    np.testing.assert_allclose(reference_cells([[0.01, 0.02], [0.04, 0.01], [-0.01, 0.0]]),
                               [[-0.025, 0.025], [0.025, 0.025]])  # fmt: skip
    occupancy = np.array([[100, 0], [-1, 70]], dtype=np.int8)
    grid = GridMap(occupancy, 0.1, Transform2D(1.0, 2.0, 0.0))
    np.testing.assert_allclose(occupied_cells(grid), [[1.05, 2.05], [1.15, 2.15]])
    agreement = grid_agreement([[0.0, 0.0], [1.0, 0.0]], [[0.05, 0.05], [3.0, 3.0]])
    # (0, 0) has an occupied cell 0.07 m away, (1, 0) none; (3, 3) no reference cell near
    assert (agreement.reference_cells, agreement.occupied_cells) == (2, 2)
    assert agreement.found_fraction == 0.5 and agreement.unexplained_fraction == 0.5
    empty = grid_agreement(np.zeros((0, 2)), [[0.0, 0.0]])
    assert math.isnan(empty.found_fraction) and empty.unexplained_fraction == 1.0


def _mapped(poses, scans, lidar):
    grid = OccupancyGrid(GridConfig(max_size_m=12.0))
    for pose, ranges in zip(poses, scans, strict=True):
        grid.insert_scan(RangeScan(ranges, lidar.angle_min, lidar.angle_increment, lidar.range_min,
                                   lidar.range_max), Transform2D(*pose))  # fmt: skip
    return grid.grid_map()


@pytest.mark.parametrize(("shift_m", "agrees"), [(0.0, True), (0.3, False)])
def test_a_grid_mapped_at_the_reference_poses_agrees_with_them(shift_m, agrees):
    lidar = LidarConfig(range_max=6.0)
    walls = arena_walls(5.0, 4.0)
    t = np.arange(20.0)
    poses = np.column_stack([-1.5 + 0.15 * t, 0.3 * np.sin(0.3 * t), 0.1 * t])
    scans = [simulate_scan(Transform2D(*pose), np.zeros((0, 3)), walls, lidar) for pose in poses]
    grid = _mapped(poses + [shift_m, 0.0, 0.0], scans, lidar)
    stamped = [(float(k), RangeScan(r, lidar.angle_min, lidar.angle_increment, lidar.range_min,
                                   lidar.range_max)) for k, r in zip(t, scans, strict=True)]  # fmt: skip
    agreement = scan_grid_agreement(stamped, PoseSeries(t, poses), Transform2D(), grid)
    assert agreement.reference_cells > 200
    if agrees:
        assert agreement.found_fraction > 0.95 and agreement.unexplained_fraction < 0.05
    else:
        assert agreement.found_fraction < 0.7 and agreement.unexplained_fraction > 0.3
