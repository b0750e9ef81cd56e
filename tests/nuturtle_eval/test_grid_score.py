"""nuturtle_eval.grid_score on hand-made grids: the true cells of a wall and a cylinder, where exact beams
end, and the two fractions of a grid against them (no ROS).

The hand case: a 1 m square grid of 0.05 m cells from the origin, a wall along y = 0.525 (the centres of
row 10) from x = 0 to 1; distances between cell centres are multiples of 0.05 m, so none falls on the
0.10 m tolerance."""

from __future__ import annotations

import math

import numpy as np
import pytest

from nuturtle_eval.grid_score import (
    GRID_TOLERANCE_M,
    OCCUPIED,
    GridScore,
    WorldOutline,
    score_grid,
    seen_points,
    true_cells,
)
from nuturtle_eval.run_evaluation import NotApplicable, RunScope
from turtlelib import Transform2D
from turtlelib.mapping.occupancy_grid import GridMap

RES = 0.05
WALL = WorldOutline(segments=[[0.0, 0.525, 1.0, 0.525]], circles=[])


def grid(cells: list[tuple[int, int]], value: int = 100) -> GridMap:
    occupancy = np.full((20, 20), -1, dtype=np.int8)
    occupancy[:5] = 0
    for row, col in cells:
        occupancy[row, col] = value
    return GridMap(occupancy, RES, Transform2D())


def test_true_cells_are_the_cells_the_outline_passes_through():
    wall = true_cells(WALL, RES, Transform2D())
    np.testing.assert_allclose(sorted(wall[:, 0]), 0.025 + RES * np.arange(21), atol=1e-12)
    np.testing.assert_allclose(wall[:, 1], 0.525, atol=1e-12)
    # a circle's cells: every centre within half a diagonal of the circle, at least one per cell of its
    # circumference, none repeated
    circle = true_cells(WorldOutline([], [[0.5, 0.5, 0.2]]), RES, Transform2D(0.01, 0.02, 0.0))
    distance = np.hypot(*(circle - 0.5).T)
    assert np.all(np.abs(distance - 0.2) <= RES / math.sqrt(2.0) + 1e-12)
    assert len(circle) >= 2.0 * math.pi * 0.2 / RES
    assert len(np.unique(np.round(circle, 9), axis=0)) == len(circle)


def test_seen_points_are_where_exact_beams_end_within_range():
    # from (0.5, 0.2) facing +y: beam 0 meets the wall 0.325 m ahead, beam pi / 4 at (0.825, 0.525)
    sensor = Transform2D(0.5, 0.2, math.pi / 2)
    points = seen_points(WALL, [sensor], np.array([0.0, -math.pi / 4, math.pi]), 0.5)
    np.testing.assert_allclose(points, [[0.5, 0.525], [0.825, 0.525]], atol=1e-12)
    assert seen_points(WALL, [sensor], np.array([0.0]), 0.3).shape == (0, 2)


def test_walls_found_and_false_occupied_of_a_hand_made_grid():
    # seen: the wall's cells in columns 0-9 (x < 0.5)
    seen = np.column_stack([0.025 + RES * np.arange(10), np.full(10, 0.525)])
    # occupied: columns 0-5 one row above the wall (0.05 m off), two cells 0.4 m off, one 0.15 m off
    occupied = [(11, c) for c in range(6)] + [(18, 0), (18, 1), (13, 15)]
    score = score_grid(grid(occupied), WALL, seen)
    # seen column k is sqrt((0.05 max(k - 5, 0))^2 + 0.05^2) from the nearest occupied: within 0.10 m up to
    # k = 6 (0.071 m), not from k = 7 (0.112 m)
    assert score.walls_found == pytest.approx(7 / 10, abs=1e-12)
    assert score.false_occupied == pytest.approx(3 / 9, abs=1e-12)
    assert (score.seen_cells, score.true_cells, score.occupied_cells) == (10, 21, 9)
    assert score.as_dict()["grid_walls_found_fraction"] == score.walls_found
    (found, false), met = score.rows(), [row[3] for row in score.rows()]
    assert found[1] == "70.0 % of 10 seen" and false[1] == "33.3 % of 9 occupied"
    assert met == [False, False]
    # a cell just below map_saver's threshold is not occupied
    below = score_grid(grid(occupied, value=OCCUPIED - 1), WALL, seen)
    assert below.occupied_cells == 0 and math.isnan(below.false_occupied) and below.walls_found == 0.0
    assert score.rows()[0][0].endswith(f"within {GRID_TOLERANCE_M} m)")


def test_a_grid_on_every_seen_wall_cell_meets_the_targets():
    seen = np.column_stack([0.025 + RES * np.arange(20), np.full(20, 0.525)])
    score = score_grid(grid([(10, c) for c in range(20)]), WALL, seen)
    assert (score.walls_found, score.false_occupied) == (1.0, 0.0)
    assert [row[3] for row in score.rows()] == [True, True]
    # nothing seen: not measured
    nothing = score_grid(grid([(10, 0)]), WALL, np.zeros((0, 2)))
    assert math.isnan(nothing.walls_found) and nothing.rows()[0][1:] == ("n/a", ">= 95 %", None)


def test_a_grid_loaded_for_localization_is_not_scored_as_mapped_by_the_run():
    poor = GridScore(walls_found=0.5, false_occupied=0.2, seen_cells=100, true_cells=120, occupied_cells=80)
    assert [row[3] for row in poor.rows()] == [False, False]
    # a localization run without a grid file maps its scans: the targets apply
    assert [row[3] for row in poor.rows(RunScope(mode="localization"))] == [False, False]
    loaded = poor.rows(RunScope(mode="localization", grid_loaded=True))
    assert [row[3] for row in loaded] == [NotApplicable("localization: the grid was loaded, not mapped")] * 2
