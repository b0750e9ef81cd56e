"""How well an occupancy grid agrees with the scans placed at reference poses: no ROS.

Each scan ``k`` (a :class:`turtlelib.sensing.range_scan.RangeScan` at stamp ``t_k``) is placed at the
reference pose read at its stamp (:meth:`~nuturtle_eval.metrics.PoseSeries.interpolate`; scans outside the
reference's time span are left out), with the LiDAR mount ``T_body_scan``; each return ``rho_b`` at bearing
``phi_b`` ends at::

    p_b = T_ref(t_k) T_body_scan [rho_b cos phi_b, rho_b sin phi_b]

The *reference cells* are the distinct cells of side ``CELL_M`` (0.05 m, on the lattice ``floor(p / CELL_M)``
of the reference frame) that some endpoint falls in; the map's *occupied cells* are those of the grid at or
above ``OCCUPIED_PERCENT`` (map_server's default ``occupied_thresh`` 0.65; the trinary files hold 100 there).
With every cell standing for its centre and ``RADIUS_M`` (0.10 m) the tolerance:

* ``found_fraction``: the fraction of the reference cells with an occupied cell of the map within
  ``RADIUS_M`` (what the map shows of what the scans hit);
* ``unexplained_fraction``: the fraction of the map's occupied cells with no reference cell within
  ``RADIUS_M`` (what the map shows that no scan at the reference poses hit: smeared or doubled walls).

Both use the map in the reference's frame (SLAM's ``map`` frame starts on the reference's pose).
"""

from __future__ import annotations

import math
from collections.abc import Iterable
from dataclasses import dataclass
from typing import TYPE_CHECKING

import numpy as np
from numpy.typing import NDArray
from scipy.spatial import cKDTree

from turtlelib import Transform2D
from turtlelib.mapping.occupancy_grid import GridMap
from turtlelib.sensing.range_scan import RangeScan

if TYPE_CHECKING:
    from .metrics import PoseSeries

CELL_M = 0.05
RADIUS_M = 0.10
OCCUPIED_PERCENT = 65


@dataclass(frozen=True)
class GridAgreement:
    """``reference_cells`` hit by the scans at the reference poses, the map's ``occupied_cells``, and the
    two fractions of the module docstring (NaN when there is nothing to take a fraction of)."""

    reference_cells: int
    occupied_cells: int
    found_fraction: float
    unexplained_fraction: float


def scan_endpoints(
    scans: Iterable[tuple[float, RangeScan]], reference: PoseSeries, T_body_scan: Transform2D
) -> NDArray[np.float64]:
    """The endpoints ``p_b`` (P, 2) (m, reference frame) of every return of the scans ``(t_s, scan)``
    whose stamp the reference covers (module docstring)."""
    points = [np.zeros((0, 2))]
    for t_s, scan in scans:
        if not reference.t_s[0] <= t_s <= reference.t_s[-1]:
            continue
        returns = scan.returns()
        rho = scan.ranges[returns]
        phi = scan.angle_min + scan.angle_increment * np.flatnonzero(returns)
        T_ref_scan = Transform2D(*reference.interpolate(np.array([t_s]))[0]) @ T_body_scan
        points.append(T_ref_scan @ np.column_stack([rho * np.cos(phi), rho * np.sin(phi)]))
    return np.vstack(points)


def reference_cells(endpoints_xy: NDArray[np.float64], cell_m: float = CELL_M) -> NDArray[np.float64]:
    """The centres (C, 2) of the distinct cells ``floor(p / cell_m)`` the endpoints (P, 2) fall in."""
    cells = np.unique(np.floor(np.asarray(endpoints_xy).reshape(-1, 2) / cell_m).astype(np.int64), axis=0)
    return (cells + 0.5) * cell_m


def occupied_cells(grid: GridMap, occupied_percent: int = OCCUPIED_PERCENT) -> NDArray[np.float64]:
    """The centres (M, 2) of the grid's cells at or above ``occupied_percent``, in its map frame: cell
    ``(row, col)`` at ``origin @ [(col + 1/2) res, (row + 1/2) res]``."""
    rows, cols = np.nonzero(grid.occupancy >= occupied_percent)
    res = grid.resolution_m
    return grid.origin @ np.column_stack([(cols + 0.5) * res, (rows + 0.5) * res])


def grid_agreement(
    reference_xy: NDArray[np.float64], occupied_xy: NDArray[np.float64], radius_m: float = RADIUS_M
) -> GridAgreement:
    """The agreement of the reference cells' centres (C, 2) and the map's occupied cells' centres (M, 2)
    within ``radius_m`` (module docstring)."""
    reference_xy = np.asarray(reference_xy, dtype=np.float64).reshape(-1, 2)
    occupied_xy = np.asarray(occupied_xy, dtype=np.float64).reshape(-1, 2)

    def near(points: NDArray[np.float64], others: NDArray[np.float64]) -> NDArray[np.bool_]:
        # a point is near when the nearest of the others is within the radius (inf: none is)
        if not others.shape[0]:
            return np.zeros(points.shape[0], dtype=bool)
        distance, _ = cKDTree(others).query(points, distance_upper_bound=radius_m * (1 + 1e-9))
        return np.isfinite(distance)

    found = near(reference_xy, occupied_xy)
    explained = near(occupied_xy, reference_xy)
    return GridAgreement(
        reference_cells=int(reference_xy.shape[0]),
        occupied_cells=int(occupied_xy.shape[0]),
        found_fraction=float(found.mean()) if found.size else math.nan,
        unexplained_fraction=float(1.0 - explained.mean()) if explained.size else math.nan,
    )


def scan_grid_agreement(
    scans: Iterable[tuple[float, RangeScan]], reference: PoseSeries, T_body_scan: Transform2D, grid: GridMap
) -> GridAgreement:
    """:func:`grid_agreement` of ``grid`` with the ``scans`` placed at the ``reference`` poses."""
    endpoints = scan_endpoints(scans, reference, T_body_scan)
    return grid_agreement(reference_cells(endpoints), occupied_cells(grid))
