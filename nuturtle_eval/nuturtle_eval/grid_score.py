"""An occupancy grid scored against the world's exact geometry: numpy, scipy and turtlelib only, no ROS.

Truth
-----
The world's outline (:class:`WorldOutline`): wall segments ``[x0, y0, x1, y1]`` (the arena's, interior
walls, furniture's sides) and circles ``[x, y, r]`` (landmarks, posts, legs), in the grid's map frame (m).
Its *true cells* on a grid's lattice (cell side ``res``, cell ``(row, col)`` covering
``origin @ ([col, col + 1) res x [row, row + 1) res)``) are the cells a boundary passes through, found
from points every ``res / OUTLINE_SAMPLES_PER_CELL`` along it (:func:`true_cells`). The *seen* cells are
those in which the LiDAR's exact beams end from the true scan poses (:func:`seen_points`: ray casting
without noise, within ``range_max``): the part of the world a run could have mapped.

Score (:func:`score_grid`), distances between cell centres, tolerance ``d = GRID_TOLERANCE_M``:

* walls found: the fraction of the seen true cells with an occupied cell of the grid within ``d``;
* false occupied: the fraction of the grid's occupied cells with no true cell (seen or not) within ``d``.

A cell is occupied at ``>= rint(100 occupied_thresh)`` (map_saver's trinary threshold, 65: black in
map.pgm). Targets: walls found >= 95 %, false occupied <= 1 %.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray
from scipy.spatial import cKDTree

from turtlelib import Transform2D
from turtlelib.mapping.grid_map_file import OCCUPIED_THRESH
from turtlelib.mapping.occupancy_grid import GridMap
from turtlelib.sensing.scan_model import cast_beams

from .run_evaluation import MAPPING_SCOPE, Row, RunScope

# Distance between cell centres within which a true cell and an occupied cell match (m)
GRID_TOLERANCE_M = 0.10
# Points per cell side sampled along each boundary when rendering the true cells
OUTLINE_SAMPLES_PER_CELL = 4
# The grid's occupied cells (per cent): map_saver's trinary threshold
OCCUPIED = int(np.rint(100.0 * OCCUPIED_THRESH))
WALLS_FOUND_TARGET = 0.95
FALSE_OCCUPIED_TARGET = 0.01


@dataclass(frozen=True)
class WorldOutline:
    """The world's boundaries (m): ``segments`` (K, 4) rows ``[x0, y0, x1, y1]`` and ``circles`` (M, 3)
    rows ``[x, y, r]``; any empty input becomes the empty array of its shape."""

    segments: NDArray[np.float64]
    circles: NDArray[np.float64]

    def __post_init__(self) -> None:
        object.__setattr__(self, "segments", np.asarray(self.segments, dtype=np.float64).reshape(-1, 4))
        object.__setattr__(self, "circles", np.asarray(self.circles, dtype=np.float64).reshape(-1, 3))

    def points(self, spacing_m: float) -> NDArray[np.float64]:
        """Points (N, 2) along every boundary, at most ``spacing_m`` apart, the ends included."""
        parts = [np.zeros((0, 2))]
        for x0, y0, x1, y1 in self.segments:
            n = max(int(np.ceil(np.hypot(x1 - x0, y1 - y0) / spacing_m)), 1)
            s = np.linspace(0.0, 1.0, n + 1)[:, None]
            # a + s (b - a)
            parts.append(np.array([x0, y0]) + s * np.array([x1 - x0, y1 - y0]))
        for x, y, r in self.circles:
            n = max(int(np.ceil(2.0 * np.pi * r / spacing_m)), 8)
            phi = np.linspace(0.0, 2.0 * np.pi, n, endpoint=False)
            parts.append(np.column_stack([x + r * np.cos(phi), y + r * np.sin(phi)]))
        return np.vstack(parts)


def _cell_centres(
    points: NDArray[np.float64], resolution_m: float, origin: Transform2D
) -> NDArray[np.float64]:
    """The centres (N, 2) of the distinct lattice cells holding ``points`` (map frame, m)."""
    if points.shape[0] == 0:
        return np.zeros((0, 2))
    # cell = floor(origin^-1 p / res); its centre origin @ ((cell + 1/2) res)
    cells = np.unique(np.floor((origin.inverse() @ points) / resolution_m), axis=0)
    return origin @ ((cells + 0.5) * resolution_m)


def true_cells(outline: WorldOutline, resolution_m: float, origin: Transform2D) -> NDArray[np.float64]:
    """The centres (N, 2) of the cells of the lattice (``resolution_m``, ``origin``: module docstring) that
    the outline passes through."""
    return _cell_centres(outline.points(resolution_m / OUTLINE_SAMPLES_PER_CELL), resolution_m, origin)


def seen_points(
    outline: WorldOutline,
    T_world_scans: list[Transform2D],
    angles_rad: NDArray[np.float64],
    range_max_m: float,
) -> NDArray[np.float64]:
    """Where the exact beams ``angles_rad`` (B,) (sensor frame) from each sensor pose end on the outline
    within ``range_max_m`` (:func:`turtlelib.sensing.scan_model.cast_beams`), (N, 2) (m)."""
    directions = np.column_stack([np.cos(angles_rad), np.sin(angles_rad)])
    hits = [np.zeros((0, 2))]
    for T_world_scan in T_world_scans:
        range_m, _ = cast_beams(T_world_scan, angles_rad, outline.circles, outline.segments)
        ends = range_m <= range_max_m
        hits.append(T_world_scan @ (range_m[ends, None] * directions[ends]))
    return np.vstack(hits)


@dataclass(frozen=True)
class GridScore:
    """``walls_found`` and ``false_occupied`` (fractions, NaN when there is nothing to count: no seen true
    cell, no occupied cell), over ``seen_cells`` seen true cells of ``true_cells`` and ``occupied_cells``
    occupied cells of the grid (module docstring)."""

    walls_found: float
    false_occupied: float
    seen_cells: int
    true_cells: int
    occupied_cells: int

    def as_dict(self) -> dict[str, float | int]:
        """The metrics.json entries."""
        return {
            "grid_walls_found_fraction": self.walls_found,
            "grid_false_occupied_fraction": self.false_occupied,
            "grid_true_cells_seen": self.seen_cells,
            "grid_true_cells": self.true_cells,
            "grid_occupied_cells": self.occupied_cells,
        }

    def rows(self, scope: RunScope = MAPPING_SCOPE) -> list[Row]:
        """Rows of the results table (:func:`nuturtle_eval.run_evaluation.results_table`): (label, value,
        target, met; None when not measured; ``NotApplicable`` when ``scope``'s grid was loaded, not
        mapped by the run)."""
        not_applicable = scope.grid_mapping()

        def row(label: str, value: float, count: str, target: str, met: bool) -> Row:
            if np.isnan(value):
                return (label, "n/a", target, None)
            return (
                label,
                f"{100.0 * value:.1f} % of {count}",
                target,
                met if not_applicable is None else not_applicable,
            )

        return [
            row(
                f"grid: walls found (an occupied cell within {GRID_TOLERANCE_M} m)",
                self.walls_found,
                f"{self.seen_cells} seen",
                f">= {100.0 * WALLS_FOUND_TARGET:.0f} %",
                self.walls_found >= WALLS_FOUND_TARGET,
            ),
            row(
                f"grid: false occupied (no wall within {GRID_TOLERANCE_M} m)",
                self.false_occupied,
                f"{self.occupied_cells} occupied",
                f"<= {100.0 * FALSE_OCCUPIED_TARGET:.0f} %",
                self.false_occupied <= FALSE_OCCUPIED_TARGET,
            ),
        ]


def score_grid(grid: GridMap, outline: WorldOutline, seen_xy: NDArray[np.float64]) -> GridScore:
    """``grid``'s score against ``outline`` (module docstring), the seen true cells being those holding the
    points ``seen_xy`` (N, 2) (:func:`seen_points`), both on the grid's own lattice."""
    res, origin = grid.resolution_m, grid.origin
    truth = true_cells(outline, res, origin)
    seen = _cell_centres(np.asarray(seen_xy, dtype=np.float64).reshape(-1, 2), res, origin)
    rows, cols = np.nonzero(grid.occupancy >= OCCUPIED)
    occupied = origin @ ((np.column_stack([cols, rows]) + 0.5) * res) if rows.size else np.zeros((0, 2))
    walls_found = false_occupied = float("nan")
    if seen.shape[0]:
        walls_found = float(np.mean(_nearest_m(seen, occupied) <= GRID_TOLERANCE_M))
    if occupied.shape[0]:
        false_occupied = float(np.mean(_nearest_m(occupied, truth) > GRID_TOLERANCE_M))
    return GridScore(walls_found, false_occupied, seen.shape[0], truth.shape[0], occupied.shape[0])


def _nearest_m(points: NDArray[np.float64], others: NDArray[np.float64]) -> NDArray[np.float64]:
    """Each point's distance (m) to the nearest of ``others`` (inf without any)."""
    if others.shape[0] == 0:
        return np.full(points.shape[0], np.inf)
    distance_m, _ = cKDTree(others).query(points)
    return distance_m
