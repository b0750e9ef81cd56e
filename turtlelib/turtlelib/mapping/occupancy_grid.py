"""Occupancy grid mapping from known poses: log-odds cells, vectorised ray casting, a grid that grows up to
a bound and then moves with the robot.

The grid
--------
Square cells of side ``resolution_m`` (m) aligned with the map frame. Cell ``(row, col)`` covers
``x in [(col + col0) res, (col + col0 + 1) res)`` and ``y in [(row + row0) res, (row + row0 + 1) res)``
where ``(col0, row0)`` are integers: the map frame's cell ``floor(x / res), floor(y / res)`` is the grid's
``(row, col) = (floor(y / res) - row0, floor(x / res) - col0)``. So the origin (the corner of cell
``(0, 0)``) is ``(col0 res, row0 res)`` and growing or moving the grid only changes the integers
``col0, row0``: every cell keeps its world position exactly. Rows run along +y and columns along +x,
row-major with row 0 at the origin: the layout of ``nav_msgs/OccupancyGrid`` (``data[row * width +
col]``, ``info.origin`` the pose of cell (0, 0)'s corner), which :meth:`OccupancyGrid.grid_map` gives as
int8 (-1 unknown, 0..100).

The inverse sensor model (log odds)
-----------------------------------
Each cell holds the log odds of being occupied, ``l = log(p / (1 - p))``, with inverse
``p = 1 / (1 + exp(-l))``; 0 (``p = 1/2``) before any observation. Under the usual independence
assumptions (each cell alone, observations independent given the cell's state, prior 1/2), Bayes' rule
for a cell observed by a scan is the sum ``l <- l + l_obs`` (Thrun, Burgard, Fox, *Probabilistic Robotics*,
ch. 9.2) with

* ``l_hit = log(p_hit / (1 - p_hit))`` for the cell a beam ends in (``hit_probability > 1/2``),
* ``l_miss = log(p_miss / (1 - p_miss))`` for a cell a beam passes through (``miss_probability < 1/2``),

then clamped to ``[l_min, l_max]`` (the log odds of ``min_probability`` and ``max_probability``), so a cell
that changes (a door opens) needs a bounded number of scans to flip (OctoMap's clamping: Hornung et al.,
"OctoMap", Autonomous Robots 2013; the defaults 0.7 / 0.4 / 0.12 / 0.97 are theirs). A cell is updated at
most once per scan: occupied if any beam of the scan ends in it, else free if any passes through it (an
end wins over a pass: a wall seen at a grazing angle is not cleared by the neighbouring beams). The
occupancy published is ``round(100 p)``; cells never observed are -1.

Near the end
------------
A cell a return passes within ``near_end_m`` of its end (``(1 - t) rho < near_end_m``, ``t`` where the
beam enters the cell) has the weaker ``l_near = log(p_near / (1 - p_near))`` (``near_miss_probability``,
between ``miss_probability`` and 1/2) instead of ``l_miss``; within one scan a far pass wins over a near
one (and an end over both). A 2D LiDAR sees most walls at grazing angles: a beam at incidence ``a`` runs
within one cell of the wall for ``res / sin a`` before its end (0.29 m at 10 deg), through the wall's cells,
and the beams that end beside a wall cell outnumber those that end in it, so with a pass's full weight the
wall is erased (OctoMap's model is a 3D one's, for dense head-on depth). Far from its end a beam's pass is
the evidence it always was: a person or a robot that walked away is cleared by the beams that reach past
where it stood. Measured with the scans of two real buildings placed at the reference's own poses (the grid's
model alone): 84 / 73 % of the wall cells kept with ``near_end_m = 0``, 89 / 79 % with 0.3 m and 0.49
(``docs/maps.md``).

The beams
---------
Beam ``b`` of a scan leaves the sensor at ``phi_b = angle_min + b angle_increment`` (sensor frame, rad).
A return ``range_min <= rho_b <= range_max`` (finite, > 0) ends at ``p = T_map_scan [rho_b cos phi_b,
rho_b sin phi_b]``: its end cell is hit, the cells from the sensor's up to the end's, that cell excluded,
are missed. Anything else (0, NaN, inf, out of the limits: what LiDARs write for no return, and what
``sensor_msgs/LaserScan`` says to discard) is a beam that saw nothing within its limits: it misses every
cell up to ``min(no_return_clear_m, range_max)`` along its direction and marks nothing occupied
(``no_return_clear_m = 0`` turns this off).

The cells a segment from ``s`` to ``e`` crosses (in the map frame's cell units ``u = x / res``, so that the
cells do not depend on the grid's current extent) are found in closed form, all beams at once (the
traversal of Amanatides & Woo, "A fast voxel traversal algorithm", 1987, with its steps counted instead of
iterated): the segment crosses ``n_x = |floor(e_x) - floor(s_x)|`` vertical cell borders at
``t_x(k) = (f_x + k) / |d_x|``, ``k = 0 .. n_x - 1`` (``d = e - s``, ``f_x`` the distance from ``s_x`` to
the first border in the direction of travel) and ``n_y`` horizontal ones at ``t_y(j)`` alike. After its
k-th vertical crossing the segment is in column ``floor(s_x) + sign(d_x) (k + 1)`` and in the row reached
after the horizontal crossings before it, ``c = #{j: t_y(j) < t_x(k)} = clip(ceil(t_x(k) |d_y| - f_y), 0,
n_y)`` (and the same for the horizontal crossings, a tie going to the vertical one): the cells entered are
known without ordering the crossings, and the last is the end cell. (Rounding can only matter where a
segment passes within rounding of a cell corner: both or neither of the corner's side cells is then listed.)

Continuing a saved grid
-----------------------
:meth:`OccupancyGrid.from_grid_map` starts a grid from a saved :class:`GridMap` (a map_server file read
back by `turtlelib.mapping.grid_map_file.load_grid_map`), so that a mapping session continues an earlier
one. The grid takes the saved extent and origin: ``col0 = origin_x / res``, ``row0 = origin_y / res``
must be whole numbers (a grid saved here always has them), so every saved cell keeps its world position.
A cell saved unknown (-1) starts unobserved; an observed one starts from the log odds of its saved
occupancy ``v`` (per cent), clamped: ``l = clip(log(v / (100 - v)), l_min, l_max)``. map_server's trinary
file holds only 0 (free) and 100 (occupied), so a saved free cell starts at ``l_min`` and an occupied one
at ``l_max``: the trinary file kept the decision, not the evidence behind it, and the clamping bound is
where a cell seen the same way scan after scan settles (after about 5 scans at the defaults, far fewer
than a saved map's cells were seen). A continued cell therefore needs the same bounded number of
contrary scans to flip as one mapped in a single run (at the defaults a free cell is saved occupied,
>= 65, after 4 hits, an occupied one saved free, <= 20, after 12 misses), and a stray beam of the new
session does not erase a saved wall. Cells saved in
between (map_server's ``scale`` or ``raw`` files) start from their own log odds. New scans are added as
usual (the grid grows and moves as in "The bound": what it leaves behind of the saved grid is
forgotten), and :meth:`ScanKeyframes.render` draws its keyframes over the same saved base.

The bound (memory)
------------------
The grid grows by whole cells, ``grow_margin_m`` to spare, as scans reach past it, up to ``n =
ceil(max_size_m / res)`` cells a side in x and in y: at most ``n^2`` cells of ``BYTES_PER_CELL = 6`` bytes
(float32 log odds, the observed flag, one scratch flag), 4,000,000 cells and 24 MB at the defaults
(:attr:`OccupancyGrid.nbytes`, :attr:`OccupancyGrid.max_nbytes`). A scan that reaches past the bound
(the grid and the scan together longer than ``n`` along an axis) never stops the mapping. Along that axis:

* if the scan's cells ``low..high`` fit in ``n``, the grid (now ``n`` long) moves toward them by the least
  whole number of cells that brings them inside, then up to ``grow_margin_m`` further while they stay
  inside (so it moves now and then, not at every scan); the cells it leaves on the far side are forgotten;
* if the scan alone is longer than ``n`` (a bound shorter than the LiDAR's reach), the grid is centred on
  the sensor's cell, and moved again only when the sensor comes within ``grow_margin_m`` of its edge.

The grid moves toward the robot because that is where a map is used (a planner plans around the robot),
and because a save renders the keyframes, which keep the newest: a grid that stayed where it reached its
bound would leave the rest of the run unmapped, one without a bound would grow with the building and
its memory with no limit. What then lies past the grid is clipped: beam ``b`` is cut where it leaves the
grid grown by half a cell, at ``t_b = min(1, t_x, t_y)`` with ``t_x = (X - s_x) / d_x`` (``X`` the grid's
high x border + 1/2 for ``d_x > 0``, its low border - 1/2 for ``d_x < 0``, ``t_x = inf`` for ``d_x = 0``;
``t_y`` alike). The cut segment is the beam up to half a cell past the grid, so its cells inside the grid
are the whole beam's (those past the grid are dropped): the cells up to the bound are traversed as
usual, and an end past the grid marks nothing occupied. The sensor's cell is always inside.
"""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass
from functools import partial

import numpy as np
from numpy.typing import ArrayLike, NDArray

from ..geometry.path_trail import PathTrail, PathTrailConfig
from ..geometry.se2 import Transform2D
from ..sensing.range_scan import RangeScan
from ..util.validation import in_range, integer, non_negative, positive, store

UNKNOWN = -1  # nav_msgs/OccupancyGrid's value of a cell never observed
# the state of one cell (bytes): float32 log odds, bool observed, bool scratch (the ends of a scan)
BYTES_PER_CELL = 6
# Largest side of a grid (cells): 2^15 x 2^15 cells are 6 GB of state, far beyond any TurtleBot's map
_MAX_CELLS = 2**15


def log_odds(probability: float | NDArray[np.float64]) -> float | NDArray[np.float64]:
    """``l = log(p / (1 - p))`` for ``p`` in (0, 1)."""
    return np.log(probability) - np.log1p(-probability)


def probability(log_odds_value: float | NDArray[np.float64]) -> float | NDArray[np.float64]:
    """``p = 1 / (1 + exp(-l))``, the inverse of :func:`log_odds`."""
    return 1.0 / (1.0 + np.exp(-log_odds_value))


@dataclass(frozen=True)
class GridConfig:
    """Occupancy grid mapping parameters (the names are the future ROS parameters).

    * ``resolution_m`` (m, > 0): the side of a cell;
    * ``initial_size_m`` (m, > 0): side of the square grid at the start, centred on the map origin;
    * ``max_size_m`` (m, >= ``initial_size_m``): the grid grows as scans reach past it, up to this side
      in x and in y (its memory bound); past it the grid moves toward the scans, forgetting its far side,
      and clips what still lies outside (module docstring, "The bound");
    * ``grow_margin_m`` (m, >= 0): the extra space added around a scan that needs a larger (or moved)
      grid, so the grid grows or moves now and then rather than at every scan;
    * ``hit_probability`` in (1/2, 1), ``miss_probability`` in (0, 1/2): the inverse sensor model of a
      beam's end cell and of the cells it passes through (module docstring);
    * ``near_end_m`` (m, >= 0), ``near_miss_probability`` in [``miss_probability``, 1/2): a cell a return
      passes within ``near_end_m`` of its end has this weaker model (module docstring, "Near the end");
    * ``min_probability`` in (0, ``miss_probability``], ``max_probability`` in [``hit_probability``, 1):
      the clamping bounds;
    * ``no_return_clear_m`` (m, >= 0): how far a beam without a return clears.

    ValueError for anything else.
    """

    resolution_m: float = 0.05
    initial_size_m: float = 4.0
    max_size_m: float = 100.0
    grow_margin_m: float = 2.0
    hit_probability: float = 0.7
    miss_probability: float = 0.4
    near_end_m: float = 0.3
    near_miss_probability: float = 0.49
    min_probability: float = 0.12
    max_probability: float = 0.97
    no_return_clear_m: float = 1.0

    def __post_init__(self) -> None:
        store(self, ("resolution_m", "initial_size_m", "max_size_m"), positive)
        store(self, ("grow_margin_m", "no_return_clear_m", "near_end_m"), non_negative)
        store(self, ("hit_probability",), partial(in_range, low=0.5, high=1.0, open_low=True, open_high=True))
        store(
            self, ("miss_probability",), partial(in_range, low=0.0, high=0.5, open_low=True, open_high=True)
        )
        store(
            self,
            ("near_miss_probability",),
            partial(in_range, low=self.miss_probability, high=0.5, open_high=True),
        )
        store(
            self,
            ("min_probability",),
            partial(in_range, low=0.0, high=self.miss_probability, open_low=True),
        )
        store(
            self,
            ("max_probability",),
            partial(in_range, low=self.hit_probability, high=1.0, open_high=True),
        )
        if self.max_size_m < self.initial_size_m:
            raise ValueError(
                f"max_size_m must be >= initial_size_m = {self.initial_size_m}, got {self.max_size_m}"
            )
        cells = self.max_size_m / self.resolution_m
        if cells > _MAX_CELLS:
            raise ValueError(f"max_size_m / resolution_m must be <= {_MAX_CELLS} cells a side, got {cells}")


@dataclass(frozen=True, eq=False)
class GridMap:
    """An occupancy grid as ``nav_msgs/OccupancyGrid`` carries it.

    ``occupancy`` (height, width) int8, -1 (unknown) or 0..100 (per cent occupied), row ``r`` along +y and
    column ``c`` along +x of the grid's frame (``data = occupancy.ravel()``, row-major, row 0 at the
    origin); ``resolution_m`` (m) the cell side; ``origin`` the pose in the map frame of cell (0, 0)'s
    corner (``info.origin``; yaw 0 for the grids made here). Stored read-only; ValueError for values
    outside -1..100, an empty grid or a resolution that is not finite and > 0.
    """

    occupancy: NDArray[np.int8]
    resolution_m: float
    origin: Transform2D

    def __post_init__(self) -> None:
        occupancy = np.array(self.occupancy)
        if occupancy.ndim != 2 or occupancy.size == 0:
            raise ValueError(f"occupancy must be a non-empty 2-D array, got shape {occupancy.shape}")
        if occupancy.dtype.kind not in "iu":
            raise ValueError(f"occupancy must hold integers, got {occupancy.dtype}")
        if occupancy.min() < UNKNOWN or occupancy.max() > 100:
            raise ValueError("occupancy values must be -1 (unknown) or 0..100")
        occupancy = occupancy.astype(np.int8)
        occupancy.flags.writeable = False
        object.__setattr__(self, "occupancy", occupancy)
        store(self, ("resolution_m",), positive)
        if not isinstance(self.origin, Transform2D):
            raise ValueError(f"origin must be a Transform2D, got {type(self.origin).__name__}")

    @property
    def width(self) -> int:
        return self.occupancy.shape[1]

    @property
    def height(self) -> int:
        return self.occupancy.shape[0]


class OccupancyGrid:
    """A log-odds occupancy grid that grows as scans reach past it, up to ``max_size_m`` a side, then moves
    toward them (module docstring).

    ``log_odds`` (height, width) float32 and ``observed`` (height, width) bool are the state; ``col0``,
    ``row0`` the integer cell offsets of cell (0, 0) (origin ``(col0 res, row0 res)``).
    """

    def __init__(self, config: GridConfig) -> None:
        self.config = config
        res = config.resolution_m
        self._l_hit = float(log_odds(config.hit_probability))
        self._l_miss = float(log_odds(config.miss_probability))
        self._l_near_miss = float(log_odds(config.near_miss_probability))
        self._l_min = float(log_odds(config.min_probability))
        self._l_max = float(log_odds(config.max_probability))
        self._max_side = math.ceil(config.max_size_m / res)
        half = math.ceil(0.5 * config.initial_size_m / res)
        self.col0 = self.row0 = -half
        self.log_odds = np.zeros((2 * half, 2 * half), dtype=np.float32)
        self.observed = np.zeros((2 * half, 2 * half), dtype=bool)
        self._marked_scratch = np.zeros(self.log_odds.size, dtype=bool)
        self._layout: tuple[int, float, float] | None = None
        self._directions = np.zeros((0, 2))

    @classmethod
    def from_grid_map(cls, saved: GridMap, config: GridConfig) -> OccupancyGrid:
        """A grid continuing ``saved`` (module docstring, "Continuing a saved grid"): its extent and
        origin, unknown cells unobserved, observed ones at ``clip(log(v / (100 - v)), l_min, l_max)`` for
        their occupancy ``v``. ValueError for a resolution other than ``config``'s, an origin turned or not
        on a whole number of cells, or a grid larger than ``max_size_m`` a side."""
        if not isinstance(saved, GridMap):
            raise ValueError(f"need a GridMap, got {type(saved).__name__}")
        res = config.resolution_m
        if not math.isclose(saved.resolution_m, res, rel_tol=1e-9):
            raise ValueError(
                f"the saved grid's resolution {saved.resolution_m!r} m is not resolution_m = {res!r} m"
            )
        origin = saved.origin
        offsets = origin.x / res, origin.y / res
        if origin.theta != 0.0 or any(abs(u - round(u)) > 1e-6 for u in offsets):
            raise ValueError(
                f"the saved grid's origin ({origin.x!r}, {origin.y!r}, {origin.theta!r}) is not a whole "
                f"number of {res!r} m cells with yaw 0, as the grids saved here are"
            )
        grid = cls(config)
        if max(saved.width, saved.height) > grid._max_side:
            raise ValueError(
                f"the saved grid ({saved.width} x {saved.height} cells) is larger than max_size_m = "
                f"{config.max_size_m!r} m ({grid._max_side} cells) a side"
            )
        observed = saved.occupancy != UNKNOWN
        percent = np.where(observed, saved.occupancy, 50).astype(np.float64)
        # l = log(v / (100 - v)): -inf for 0 and inf for 100 before the clamp
        with np.errstate(divide="ignore"):
            log_odds_grid = np.log(percent) - np.log(100.0 - percent)
        log_odds_grid = np.clip(log_odds_grid, grid._l_min, grid._l_max)
        grid.log_odds = np.where(observed, log_odds_grid, 0.0).astype(np.float32)
        grid.observed = observed
        grid.col0, grid.row0 = round(offsets[0]), round(offsets[1])
        grid._marked_scratch = np.zeros(grid.log_odds.size, dtype=bool)
        return grid

    @property
    def cells(self) -> int:
        """The number of cells now (height x width)."""
        return self.log_odds.size

    @property
    def nbytes(self) -> int:
        """The bytes the grid's state holds now (``BYTES_PER_CELL`` per cell)."""
        return self.log_odds.nbytes + self.observed.nbytes + self._marked_scratch.nbytes

    @property
    def max_cells(self) -> int:
        """The most cells the grid can hold: ``ceil(max_size_m / resolution_m)^2``."""
        return self._max_side**2

    @property
    def max_nbytes(self) -> int:
        """The most bytes the grid's state can hold: ``max_cells BYTES_PER_CELL``."""
        return self.max_cells * BYTES_PER_CELL

    @property
    def origin_m(self) -> tuple[float, float]:
        """``(x, y)`` (m) of cell (0, 0)'s corner in the map frame."""
        res = self.config.resolution_m
        return self.col0 * res, self.row0 * res

    def cell_of(self, p_map: ArrayLike) -> NDArray[np.int64]:
        """``(row, col)`` (N, 2) of points ``p_map`` (N, 2) (m), possibly outside the grid."""
        p = np.asarray(p_map, dtype=np.float64).reshape(-1, 2)
        res = self.config.resolution_m
        return np.column_stack(
            (
                np.floor(p[:, 1] / res).astype(np.int64) - self.row0,
                np.floor(p[:, 0] / res).astype(np.int64) - self.col0,
            )
        )

    def insert_scan(self, scan: RangeScan, T_map_scan: Transform2D) -> bool:
        """Update the grid with ``scan`` taken from the sensor pose ``T_map_scan`` (module docstring).

        The grid first grows if the scan reaches past it, or moves toward the scan if it would then be
        larger than ``max_size_m`` (what lies past it even so is clipped); True when the scan reached past
        that bound. ValueError (and no change) for anything but a RangeScan and a Transform2D.
        """
        if not isinstance(scan, RangeScan) or not isinstance(T_map_scan, Transform2D):
            raise ValueError(
                f"need a RangeScan and a Transform2D, got {type(scan).__name__}, {type(T_map_scan).__name__}"
            )
        res = self.config.resolution_m
        returns = scan.returns()
        reach_m = np.where(returns, scan.ranges, min(self.config.no_return_clear_m, scan.range_max))
        u_scan = self._unit_vectors(scan)
        c, s = math.cos(T_map_scan.theta), math.sin(T_map_scan.theta)
        # end points in the map frame, in cells: (R u rho + p) / res
        ex = (c * u_scan[:, 0] - s * u_scan[:, 1]) * reach_m + T_map_scan.x
        ey = (s * u_scan[:, 0] + c * u_scan[:, 1]) * reach_m + T_map_scan.y
        ex /= res
        ey /= res
        sx, sy = T_map_scan.x / res, T_map_scan.y / res
        past_bound = self._fit(
            (math.floor(min(sx, ex.min())), math.floor(max(sx, ex.max())), math.floor(sx)),
            (math.floor(min(sy, ey.min())), math.floor(max(sy, ey.max())), math.floor(sy)),
        )
        # cells in the map frame's cell units (independent of the grid's extent), then in the grid
        height, width = self.log_odds.shape
        start = (math.floor(sy) - self.row0) * width + math.floor(sx) - self.col0
        # every return (those ending past the grid too: their passes near the end are near ones)
        ends = returns
        if past_bound:  # the returns that end inside the grid (compared before any cast to integers)
            returns = returns & (ex >= self.col0) & (ex < self.col0 + width)
            returns &= (ey >= self.row0) & (ey < self.row0 + height)
            traversed, beam, t = self._clipped_traversed_cells(sx, sy, ex, ey)
        else:
            traversed, beam, t = _traversed_cells(sx, sy, ex, ey, width)
            traversed += start
        # a cell a return enters within near_end_m of its end: (1 - t) rho < near_end_m
        near = ends[beam] & ((1.0 - t) * reach_m[beam] < self.config.near_end_m)
        end_row = np.floor(ey[returns]).astype(np.int64) - self.row0
        hit = end_row * width + np.floor(ex[returns]).astype(np.int64) - self.col0
        # an end wins over a pass, a pass far from the end over one near it (a cell is updated once a scan):
        # the cells already given an update are marked in the scratch, which is left all False again
        marked = self._marked_scratch
        marked[hit] = True
        free = traversed[~near & ~marked[traversed]]
        if not marked[start] and reach_m.max() > 0.0:
            free = np.append(free, start)
        marked[free] = True
        near_free = traversed[near & ~marked[traversed]]
        marked[hit] = marked[free] = False
        flat_l = self.log_odds.reshape(-1)
        flat_observed = self.observed.reshape(-1)
        # duplicates in free (or hit) write the same value: each cell is updated once
        flat_l[free] = np.maximum(flat_l[free] + self._l_miss, self._l_min)
        flat_l[near_free] = np.maximum(flat_l[near_free] + self._l_near_miss, self._l_min)
        flat_l[hit] = np.minimum(flat_l[hit] + self._l_hit, self._l_max)
        flat_observed[free] = True
        flat_observed[near_free] = True
        flat_observed[hit] = True
        return past_bound

    def grid_map(self) -> GridMap:
        """The grid as ``nav_msgs/OccupancyGrid`` values: ``round(100 p)``, -1 where never observed."""
        percent = np.rint(100.0 * probability(self.log_odds.astype(np.float64))).astype(np.int8)
        occupancy = np.where(self.observed, percent, np.int8(UNKNOWN))
        x, y = self.origin_m
        return GridMap(occupancy, self.config.resolution_m, Transform2D(x, y, 0.0))

    def _unit_vectors(self, scan: RangeScan) -> NDArray[np.float64]:
        """``[cos(phi_b), sin(phi_b)]`` (B, 2) of the scan's beams, kept while the layout stays the same."""
        layout = (scan.ranges.shape[0], scan.angle_min, scan.angle_increment)
        if layout != self._layout:
            phi = scan.angle_min + scan.angle_increment * np.arange(layout[0], dtype=np.float64)
            self._directions = np.column_stack((np.cos(phi), np.sin(phi)))
            self._layout = layout
        return self._directions

    def _fit(self, x_cells: tuple[int, int, int], y_cells: tuple[int, int, int]) -> bool:
        """Grow or move the grid (:func:`_extent` along x and y) for a scan whose map-frame cells span
        ``(low, high, sensor)`` along each axis (the sensor's cell); True when the scan reached past the
        bound. The cells both extents share keep their values, the others start unknown."""
        height, width = self.log_odds.shape
        margin = math.ceil(self.config.grow_margin_m / self.config.resolution_m)
        col0, new_width, past_x = _extent(self.col0, width, *x_cells, self._max_side, margin)
        row0, new_height, past_y = _extent(self.row0, height, *y_cells, self._max_side, margin)
        if (col0, new_width, row0, new_height) == (self.col0, width, self.row0, height):
            return past_x or past_y
        log_odds_grid = np.zeros((new_height, new_width), dtype=np.float32)
        observed = np.zeros(log_odds_grid.shape, dtype=bool)
        # the map-frame cells both extents share, then where they are in the old grid and in the new
        col_low, col_high = max(col0, self.col0), min(col0 + new_width, self.col0 + width)
        row_low, row_high = max(row0, self.row0), min(row0 + new_height, self.row0 + height)
        if col_low < col_high and row_low < row_high:
            old = (
                slice(row_low - self.row0, row_high - self.row0),
                slice(col_low - self.col0, col_high - self.col0),
            )
            new = slice(row_low - row0, row_high - row0), slice(col_low - col0, col_high - col0)
            log_odds_grid[new] = self.log_odds[old]
            observed[new] = self.observed[old]
        self.log_odds, self.observed = log_odds_grid, observed
        self.col0, self.row0 = col0, row0
        if self._marked_scratch.size != log_odds_grid.size:  # (all false between scans)
            self._marked_scratch = np.zeros(log_odds_grid.size, dtype=bool)
        return past_x or past_y

    def _clipped_traversed_cells(
        self, sx: float, sy: float, ex: NDArray[np.float64], ey: NDArray[np.float64]
    ) -> tuple[NDArray[np.int64], NDArray[np.intp], NDArray[np.float64]]:
        """The grid cells (flat indices) the beams from ``(sx, sy)`` (inside the grid) to ``(ex_b, ey_b)``
        (cell units) enter, each beam cut where it leaves the grid grown by half a cell (module docstring,
        "The bound"), with the beam of each and where along the whole (uncut) beam it is entered
        (:func:`_traversed_cells`). The cut beams end at most one cell past the grid: they are traversed in
        a grid one cell wider on each side, whose border cells are then dropped."""
        height, width = self.log_odds.shape
        dx, dy = ex - sx, ey - sy
        t = np.ones_like(dx)
        for d, low, size, s in ((dx, self.col0, width, sx), (dy, self.row0, height, sy)):
            border = np.where(d > 0.0, low + size + 0.5, low - 0.5)
            # a beam nearly parallel to a border meets it never (inf), or past its end: either way t stays
            with np.errstate(over="ignore"):
                np.minimum(t, np.divide(border - s, d, out=np.full_like(d, np.inf), where=d != 0.0), out=t)
        padded = width + 2
        start = (math.floor(sy) - self.row0 + 1) * padded + math.floor(sx) - self.col0 + 1
        offsets, beam, t_cut = _traversed_cells(sx, sy, sx + t * dx, sy + t * dy, padded)
        row, col = np.divmod(offsets + start, padded)
        inside = (row >= 1) & (row <= height) & (col >= 1) & (col <= width)
        return (row[inside] - 1) * width + col[inside] - 1, beam[inside], (t_cut * t[beam])[inside]


def _extent(
    low_old: int, size_old: int, low: int, high: int, sensor: int, max_size: int, margin: int
) -> tuple[int, int, bool]:
    """Along one axis, the grid's first cell and length (cells) after a scan covering the cells
    ``low..high`` from the ``sensor``'s cell, when it now covers ``size_old`` cells from ``low_old``: grown
    to cover the scan (``margin`` cells to spare on each side that grows) within ``max_size`` cells, or
    moved toward it (module docstring, "The bound"); and whether the scan reached past the bound."""
    new_low, new_end = min(low_old, low), max(low_old + size_old, high + 1)
    if new_end - new_low <= max_size:
        if new_low < low_old:
            new_low = max(new_low - margin, new_end - max_size)
        if new_end > low_old + size_old:
            new_end = min(new_end + margin, new_low + max_size)
        return new_low, new_end - new_low, False
    if high + 1 - low <= max_size:
        # the least move that covers low..high, then up to margin further while it still does
        first = min(max(low_old, high + 1 - max_size), low)
        if first > low_old:
            first = min(first + margin, low)
        elif first < low_old:
            first = max(first - margin, high + 1 - max_size)
        return first, max_size, True
    # a scan longer than the grid: centred on the sensor, unless that is still margin inside the grid
    inner = min(margin, (max_size - 1) // 2)
    if size_old == max_size and low_old + inner <= sensor < low_old + size_old - inner:
        return low_old, size_old, True
    return sensor - max_size // 2, max_size, True


def _traversed_cells(
    sx: float, sy: float, ex: NDArray[np.float64], ey: NDArray[np.float64], width: int
) -> tuple[NDArray[np.int64], NDArray[np.intp], NDArray[np.float64]]:
    """The cells each segment from ``(sx, sy)`` to ``(ex_b, ey_b)`` (cell units: m / res) enters after
    leaving the start cell, end cells included (module docstring), as offsets ``d_row width + d_col`` from
    the start cell in a row-major grid ``width`` cells wide; with each the segment ``b`` it belongs to and
    the ``t`` in (0, 1] at which the segment enters it (``s + t (e - s)``)."""
    i0, j0 = math.floor(sx), math.floor(sy)
    dx, dy = ex - sx, ey - sy
    n_x = np.abs(np.floor(ex) - i0)
    n_y = np.abs(np.floor(ey) - j0)
    # a step along x is one cell, along y one row of the grid
    step_x = np.where(dx > 0.0, 1.0, -1.0)
    step_y = np.where(dy > 0.0, float(width), -float(width))
    # distance from the start to the first border crossed, per axis, in cells
    f_x = np.where(dx > 0.0, i0 + 1 - sx, sx - i0)
    f_y = np.where(dy > 0.0, j0 + 1 - sy, sy - j0)
    abs_dx, abs_dy = np.abs(dx), np.abs(dy)

    def crossings(n: NDArray[np.float64]) -> tuple[NDArray[np.intp], NDArray[np.float64]]:
        """The segment of each crossing and its number k along its axis."""
        counts = n.astype(np.intp)
        beam = np.repeat(np.arange(counts.shape[0]), counts)
        first = np.cumsum(n) - n
        return beam, np.arange(beam.shape[0], dtype=np.float64) - first[beam]

    # vertical borders: t = (f_x + k) / |d_x|; the row is the number of horizontal crossings before t
    beam_x, k = crossings(n_x)
    t_x = (f_x[beam_x] + k) / abs_dx[beam_x]
    before = np.minimum(np.maximum(np.ceil(t_x * abs_dy[beam_x] - f_y[beam_x]), 0.0), n_y[beam_x])
    offsets_x = step_x[beam_x] * (k + 1.0) + step_y[beam_x] * before
    # horizontal borders: the column is the number of vertical crossings at or before t
    beam_y, k = crossings(n_y)
    t_y = (f_y[beam_y] + k) / abs_dy[beam_y]
    before = np.minimum(np.maximum(np.floor(t_y * abs_dx[beam_y] - f_x[beam_y]) + 1.0, 0.0), n_x[beam_y])
    offsets_y = step_y[beam_y] * (k + 1.0) + step_x[beam_y] * before
    return (
        np.concatenate((offsets_x, offsets_y)).astype(np.int64),
        np.concatenate((beam_x, beam_y)),
        np.concatenate((t_x, t_y)),
    )


@dataclass(frozen=True)
class KeyframeConfig:
    """Which scans to keep for re-rendering: a scan is kept when the robot moved ``keyframe_step_m`` (m,
    >= 0) or turned ``keyframe_turn_rad`` (rad, >= 0) since the last kept one; at most ``max_keyframes``
    (>= 1), the oldest dropped. ValueError otherwise."""

    keyframe_step_m: float = 0.1
    keyframe_turn_rad: float = 0.2
    max_keyframes: int = 5000

    def __post_init__(self) -> None:
        store(self, ("keyframe_step_m", "keyframe_turn_rad"), non_negative)
        store(self, ("max_keyframes",), partial(integer, minimum=1))


class ScanKeyframes:
    """Decimated ``(stamp_ns, scan)`` keyframes, to render a fresh grid from corrected poses (after a loop
    closure, SLAM's estimate of past poses changes: the grid made incrementally keeps the old ones)."""

    def __init__(self, config: KeyframeConfig) -> None:
        self.config = config
        self._trail: PathTrail[tuple[int, RangeScan]] = PathTrail(
            PathTrailConfig(
                path_min_step_m=config.keyframe_step_m,
                path_min_turn_rad=config.keyframe_turn_rad,
                path_max_poses=config.max_keyframes,
                path_period=0.0,
            )
        )

    def __len__(self) -> int:
        return len(self._trail.items)

    @property
    def stamps_ns(self) -> list[int]:
        return [stamp_ns for stamp_ns, _ in self._trail.items]

    def offer(self, stamp_ns: int, T_map_body: Transform2D, scan: RangeScan) -> bool:
        """Keep ``scan`` (taken at ``stamp_ns``, int ns, with the body at ``T_map_body``) if the body moved
        enough since the last kept scan; True if kept."""
        return self._trail.offer(T_map_body, (integer("stamp_ns", stamp_ns), scan))

    def render(
        self,
        pose_at: Callable[[int], Transform2D | None],
        T_body_scan: Transform2D,
        config: GridConfig,
        base: GridMap | None = None,
    ) -> OccupancyGrid:
        """A new grid of every kept scan placed at ``pose_at(stamp_ns) @ T_body_scan`` (the corrected body
        pose at its stamp and the LiDAR mount); scans whose pose is None (unknown) are skipped. The grid
        starts empty, or from the saved ``base`` (:meth:`OccupancyGrid.from_grid_map`, ValueError as there)
        when this session continues one."""
        grid = OccupancyGrid(config) if base is None else OccupancyGrid.from_grid_map(base, config)
        for stamp_ns, scan in self._trail.items:
            T_map_body = pose_at(stamp_ns)
            if T_map_body is not None:
                grid.insert_scan(scan, T_map_body @ T_body_scan)
        return grid

    def clear(self) -> None:
        self._trail.clear()
