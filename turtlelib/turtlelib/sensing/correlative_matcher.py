"""Correlative scan matching (Olson 2009, "Real-time correlative scan matching"): an exhaustive search over
``x, y, theta`` for the pose of a scan in a rasterised likelihood grid of a submap, coarse then fine, exact.

Likelihood grid
---------------
The submap's points ``q_j`` (its frame) are rasterised at ``resolution_m``; each cell ``c`` holds::

    G(c) = exp(-d(c)^2 / (2 sigma^2)),     d(c) = distance from c's centre to the nearest occupied cell

(``sigma = sigma_m``: the scan's and the submap's noise together, and the slack of the grid), so that a scan
point that lands on a wall scores 1 and one more than ``3 sigma`` from every wall scores nothing. The
score of a pose ``T = (t, theta)`` for the scan's points ``p_i`` (n, body frame) is the mean::

    s(T) = 1/n sum_i G(cell(R(theta) p_i + t))     in [0, 1]

a fraction of the scan explained by the submap (points that see what the submap never saw score 0).

Search
------
Over ``theta`` in steps of ``resolution_m / r_90`` (``r_90`` the 90th percentile of the points' ranges: the
step moves those points by one cell) and translations in whole cells, within a window around a guess.
The coarse grid ``G_c(c) = max over the m x m cells from c of G`` (``m = coarse_cells``) bounds from above
the score of every fine translation in the coarse cell, so branch and bound is exact: coarse cells are
visited in decreasing coarse score and each is searched at the fine resolution, until the next coarse score
is no better than the best fine score found. The same bound gives the best score of a pose *distinct* from
the best (further than ``distinct_m`` in translation or ``distinct_rad`` in heading): the runner-up, whose
ratio to the best measures the ambiguity of the match (a corridor matches along itself, a square room at
each quarter turn).
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from functools import partial

import numpy as np
from numpy.typing import NDArray
from scipy.ndimage import distance_transform_edt

from ..geometry.se2 import Transform2D, normalize_angle
from ..util.validation import integer, positive, store
from .scan_registration import voxel_centroids

# the angle step's bounds (rad): a scan of short ranges is not searched finer than this, nor coarser
_ANGLE_STEP_RAD = (math.radians(0.25), math.radians(2.0))


@dataclass(frozen=True)
class CorrelativeConfig:
    """The matcher (module docstring); every value > 0 (ValueError otherwise).

    * ``resolution_m`` (m): the likelihood grid's cell, the fine translation step; the scan is thinned to
      one point per cell;
    * ``sigma_m`` (m): the width of a wall's likelihood;
    * ``coarse_cells`` (int >= 2): fine cells per side of a coarse cell;
    * ``max_points`` (int >= 10): the scan is subsampled evenly to at most this many points;
    * ``distinct_m`` (m), ``distinct_rad`` (rad): how far a pose must be from the best to be its runner-up.
    """

    resolution_m: float = 0.05
    sigma_m: float = 0.1
    coarse_cells: int = 8
    max_points: int = 400
    distinct_m: float = 0.5
    distinct_rad: float = 0.17

    def __post_init__(self) -> None:
        store(self, ("resolution_m", "sigma_m", "distinct_m", "distinct_rad"), positive)
        store(self, ("coarse_cells",), partial(integer, minimum=2))
        store(self, ("max_points",), partial(integer, minimum=10))


@dataclass(frozen=True)
class CorrelativeMatch:
    """The search's result: the best pose ``T_submap_body``, its ``score`` and the ``runner_up`` score (the
    best of the poses distinct from it; 0 if none), both in [0, 1], and the number of coarse cells searched
    at the fine resolution (``refined``)."""

    T_submap_body: Transform2D
    score: float
    runner_up: float
    refined: int


class LikelihoodGrid:
    """The likelihood grid ``G`` of submap points ``q_submap`` (m, 2) and its coarse bound ``G_c`` (module
    docstring), with a border of zero cells so that points beyond it score 0."""

    def __init__(self, q_submap: NDArray[np.float64], config: CorrelativeConfig) -> None:
        if len(q_submap) == 0:
            raise ValueError("a likelihood grid needs at least one submap point")
        self.config = config
        res = config.resolution_m
        margin = 3.0 * config.sigma_m + 2.0 * res
        self.origin = q_submap.min(axis=0) - margin
        shape = np.ceil((q_submap.max(axis=0) + margin - self.origin) / res).astype(int) + 1
        cells = np.floor((q_submap - self.origin) / res).astype(int)
        free = np.ones(shape, dtype=bool)
        free[cells[:, 0], cells[:, 1]] = False
        # d(c): the distance from each cell to the nearest occupied one (m)
        d = distance_transform_edt(free) * res
        G = np.exp(-0.5 * (d / config.sigma_m) ** 2)
        G[[0, -1], :] = 0.0
        G[:, [0, -1]] = 0.0
        self.G = G
        # G_c(c) = max of G over the cells c + [0, m) x [0, m), separably; past the edge, the zero border
        m = config.coarse_cells
        padded = np.pad(G, ((0, m - 1), (0, m - 1)))
        rows = np.lib.stride_tricks.sliding_window_view(padded, m, axis=0).max(axis=-1)
        self.G_coarse = np.lib.stride_tricks.sliding_window_view(rows, m, axis=1).max(axis=-1)

    def cells(self, p_submap: NDArray[np.float64]) -> NDArray[np.int64]:
        """The cell indices (n, 2) of points ``p_submap`` (n, 2), not clipped."""
        return np.floor((p_submap - self.origin) / self.config.resolution_m).astype(np.int64)

    def lookup(self, grid: NDArray[np.float64], ix: NDArray[np.int64], iy: NDArray[np.int64]):
        """``grid`` at cells ``(ix, iy)`` (broadcast), a cell beyond the grid read at its zero border."""
        nx, ny = grid.shape
        return grid[np.clip(ix, 0, nx - 1), np.clip(iy, 0, ny - 1)]


def thin_scan(p_body: NDArray[np.float64], config: CorrelativeConfig) -> NDArray[np.float64]:
    """The scan ``p_body`` (n, 2) thinned to one point per cell, then evenly to at most ``max_points``."""
    p = voxel_centroids(p_body, config.resolution_m)
    if len(p) > config.max_points:
        p = p[np.linspace(0, len(p) - 1, config.max_points).round().astype(int)]
    return p


def correlative_match(
    p_body: NDArray[np.float64],
    grid: LikelihoodGrid,
    T_guess: Transform2D,
    window_m: float,
    window_rad: float,
) -> CorrelativeMatch:
    """The best pose of the scan ``p_body`` (n, 2, body frame; thinned with :func:`thin_scan`) in ``grid``
    within ``|t - t_guess|_inf <= window_m`` and ``|theta - theta_guess| <= window_rad`` of the guess
    ``T_guess`` (``T_submap_body``), with its runner-up (module docstring). ValueError for an empty scan or a
    negative window."""
    if len(p_body) == 0:
        raise ValueError("a correlative match needs at least one scan point")
    if not (window_m >= 0.0 and window_rad >= 0.0):
        raise ValueError(f"the search window must be >= 0, got {window_m} m, {window_rad} rad")
    config = grid.config
    res, m = config.resolution_m, config.coarse_cells
    r_90 = float(np.percentile(np.hypot(p_body[:, 0], p_body[:, 1]), 90))
    step = float(np.clip(res / max(r_90, res), *_ANGLE_STEP_RAD))
    n_theta = int(math.floor(min(window_rad, math.pi) / step))
    thetas = T_guess.theta + step * np.arange(-n_theta, n_theta + 1)
    W = int(math.ceil(window_m / res))
    # fine offsets -W..W in cells; coarse cell a covers offsets -W + m a .. -W + m a + m - 1
    n_coarse = (2 * W) // m + 1
    coarse0 = -W + m * np.arange(n_coarse)
    base = np.empty((len(thetas), len(p_body), 2), dtype=np.int64)
    coarse = np.empty((len(thetas), n_coarse, n_coarse))
    t_guess = np.array([T_guess.x, T_guess.y])
    for k, theta in enumerate(thetas):
        c, s = math.cos(theta), math.sin(theta)
        # R(theta) p_i + t_guess, in cells
        base[k] = grid.cells(p_body @ np.array([[c, s], [-s, c]]) + t_guess)
        ix = base[k, :, 0, None, None] + coarse0[None, :, None]
        iy = base[k, :, 1, None, None] + coarse0[None, None, :]
        coarse[k] = grid.lookup(grid.G_coarse, ix, iy).sum(axis=0)
    coarse /= len(p_body)
    order = np.argsort(coarse, axis=None)[::-1]
    fine_cache: dict[int, NDArray[np.float64]] = {}

    def fine(flat: int) -> tuple[NDArray[np.float64], NDArray[np.int64], NDArray[np.int64], int]:
        k, a, b = np.unravel_index(flat, coarse.shape)
        ox = coarse0[a] + np.arange(m)
        oy = coarse0[b] + np.arange(m)
        ox, oy = ox[ox <= W], oy[oy <= W]
        if flat not in fine_cache:
            ix = base[k, :, 0, None, None] + ox[None, :, None]
            iy = base[k, :, 1, None, None] + oy[None, None, :]
            fine_cache[flat] = grid.lookup(grid.G, ix, iy).sum(axis=0) / len(p_body)
        return fine_cache[flat], ox, oy, int(k)

    # branch and bound for the best
    best, best_pose = -1.0, (0, 0, 0)
    for flat in order:
        if coarse.flat[flat] <= best:
            break
        scores, ox, oy, k = fine(flat)
        a, b = np.unravel_index(np.argmax(scores), scores.shape)
        if scores[a, b] > best:
            best, best_pose = float(scores[a, b]), (k, int(ox[a]), int(oy[b]))
    # branch and bound for the runner-up: the best of the poses distinct from best_pose
    k_best, x_best, y_best = best_pose
    far_turn = np.abs(thetas - thetas[k_best]) > config.distinct_rad
    runner_up = 0.0
    for flat in order:
        if coarse.flat[flat] <= runner_up:
            break
        scores, ox, oy, k = fine(flat)
        if not far_turn[k]:
            near = np.hypot((ox[:, None] - x_best), (oy[None, :] - y_best)) * res <= config.distinct_m
            scores = np.where(near, 0.0, scores)
        runner_up = max(runner_up, float(scores.max()))
    k, ox, oy = best_pose
    T = Transform2D(T_guess.x + ox * res, T_guess.y + oy * res, normalize_angle(float(thetas[k])))
    return CorrelativeMatch(T, best, runner_up, len(fine_cache))
