"""A 2D LiDAR scan model: ray casting against cylinders (circles) and walls (line segments).

Beam geometry
-------------
Beam ``b = 0 .. samples-1`` leaves the sensor origin along ``phi_b = angle_min + b * angle_increment``
(rad, counter-clockwise from the sensor's x axis), direction ``u_b = [cos(phi_b), sin(phi_b)]``. Its
true range is the smallest ``t > 0`` with ``t u_b`` on an object's boundary (everything in the sensor
frame), or ``inf`` when it hits nothing:

* circle, centre ``c``, radius ``r``: ``|t u - c|^2 = r^2``, i.e. ``t^2 - 2 t beta + q = 0`` with
  ``beta = u . c`` and ``q = |c|^2 - r^2``; from outside (``q > 0``) the near root is
  ``t = beta - sqrt(beta^2 - q) = q / (beta + sqrt(beta^2 - q))`` (the second form has no cancellation),
  from inside (``q < 0``) the far root ``t = beta + sqrt(beta^2 - q)``;
* segment ``p0 + s e``, ``e = p1 - p0``, ``s`` in [0, 1]: ``t u - s e = p0`` gives
  ``t = (p0 x e) / (u x e)`` and ``s = (p0 x u) / (u x e)`` (``a x b = a_x b_y - a_y b_x``); a beam
  parallel to the segment (``u x e = 0``) never hits it.

Measurement: ``range = quantise(t + n)``, ``n ~ N(0, noise^2)``,
``quantise(v) = resolution * round(v / resolution)`` (no quantisation when ``resolution == 0``), and a
beam reads ``no_return`` when the measured range lies outside ``[range_min, range_max]`` or it hit
nothing: 0.0 on the LDS-01, NaN on the LDS-02, inf in Gazebo.

Beam layout of each scan (:meth:`LidarConfig.scan_layout`): fixed, or, for a LiDAR whose driver reports
each turn as the sensor spins it (the LDS-02's ``ld08_driver``), drawn per scan: the sensor measures a
fixed number of points per second, so a spin rate ``(1 + u)`` times the nominal spaces its points by
``d = angle_increment (1 + u)``, ``u ~ U(-spin_spread, spin_spread)``. The turn's points lie at
``angle_min + (v + k) d``, ``v ~ U(0, 1)``, for every ``k >= 0`` short of ``angle_min + 2 pi``; the
driver's scan runs from the first point (``angle_min``) to the last (``angle_max``) in
``ceil((angle_max - angle_min) / d)`` beams of ``d``, so it holds every point but the last.
"""

from __future__ import annotations

import dataclasses
import math
from dataclasses import dataclass
from functools import partial
from numbers import Real

import numpy as np
from numpy.typing import ArrayLike, NDArray

from ..geometry.se2 import Transform2D
from ..util.validation import finite_real, in_range, integer, non_negative, positive, store
from .range_scan import RangeScan

# Tolerance on the beams' span <= 2 pi (beams may not wrap past a full turn).
_FULL_TURN_SLACK_RAD = 1e-9


def _no_return(name: str, value: object) -> float:
    """``value`` as a float; ValueError unless it is 0.0, NaN or +inf (what LiDAR drivers write)."""
    if (
        isinstance(value, bool)
        or not isinstance(value, Real)
        or not (value == 0.0 or math.isnan(value) or value == math.inf)
    ):
        raise ValueError(f"{name} must be 0.0, nan or inf, got {value!r}")
    return float(value)


@dataclass(frozen=True)
class LidarConfig:
    """Geometry and noise of a 2D LiDAR; defaults are the TurtleBot3 LDS-01 (360 beams of 1 deg).

    Field names match the nusim parameters ``lidar.<field>``. Ranges in m, angles in rad:

    * ``range_min``, ``range_max``: valid measured ranges, ``0 <= range_min < range_max``;
    * ``angle_min``: direction of beam 0; ``angle_increment > 0``: angle between beams;
    * ``samples``: number of beams (int >= 1), within one turn: ``(samples - 1) angle_increment <= 2 pi``
      (Gazebo's last beam repeats its first: 360 beams of 6.28 / 359 rad); a spinning LiDAR's scans
      have the beams of their turn instead (see ``spin_spread``);
    * ``noise``: standard deviation of the Gaussian range noise (m, >= 0);
    * ``resolution``: range quantisation step (m, >= 0; 0 means none);
    * ``no_return``: what a beam without a return reads: 0.0 (LDS-01), NaN (LDS-02) or inf (Gazebo);
    * ``spin_spread`` in [0, 0.5): 0 for a fixed beam layout, else the relative spread of the spin rate
      of a LiDAR that reports each turn, whose layout then changes from scan to scan (the module
      docstring); ``angle_increment`` is then the spacing at the nominal spin and at most pi / 2.

    Invalid values raise ValueError.
    """

    range_min: float = 0.12
    range_max: float = 3.5
    angle_min: float = 0.0
    angle_increment: float = 2.0 * math.pi / 360.0
    samples: int = 360
    noise: float = 0.0
    resolution: float = 0.0
    no_return: float = 0.0
    spin_spread: float = 0.0

    def __post_init__(self) -> None:
        store(self, ("range_max", "angle_min"), finite_real, prefix="lidar ")
        store(self, ("range_min", "noise", "resolution"), non_negative, prefix="lidar ")
        store(self, ("angle_increment",), positive, prefix="lidar ")
        store(self, ("samples",), partial(integer, minimum=1), prefix="lidar ")
        store(self, ("no_return",), _no_return, prefix="lidar ")
        store(self, ("spin_spread",), partial(in_range, low=0.0, high=0.5, open_high=True), prefix="lidar ")
        if not self.range_min < self.range_max:
            raise ValueError(f"need range_min < range_max, got {self.range_min}, {self.range_max}")
        if (self.samples - 1) * self.angle_increment > 2.0 * math.pi + _FULL_TURN_SLACK_RAD:
            raise ValueError(
                f"(samples - 1) * angle_increment = {(self.samples - 1) * self.angle_increment} exceeds a "
                "full turn"
            )
        if self.spin_spread > 0.0 and self.angle_increment > 0.5 * math.pi:
            raise ValueError(f"a spinning LiDAR needs angle_increment <= pi / 2, got {self.angle_increment}")

    def angles(self) -> NDArray[np.float64]:
        """Beam directions ``phi_b = angle_min + b * angle_increment`` (rad), shape (samples,)."""
        return self.angle_min + self.angle_increment * np.arange(self.samples, dtype=np.float64)

    def range_scan(self, range_m: ArrayLike) -> RangeScan:
        """``range_m`` (samples,) (m) measured on this layout, as the detector and the grid take a scan."""
        return RangeScan(range_m, self.angle_min, self.angle_increment, self.range_min, self.range_max)

    def scan_layout(self, rng: np.random.Generator) -> LidarConfig:
        """The layout of the next scan: this one when ``spin_spread`` is 0 (nothing is drawn), else one
        turn of a spinning LiDAR drawn from ``rng`` (two uniform numbers; the module docstring)."""
        if self.spin_spread == 0.0:
            return self
        u, v = rng.uniform(-self.spin_spread, self.spin_spread), rng.uniform(0.0, 1.0)
        # points at angle_min + (v + k) d while (v + k) d < 2 pi: ceil(2 pi / d - v) of them (at least 2, as
        # d < 3 pi / 4), all but the last in the scan
        spacing = self.angle_increment * (1.0 + u)
        points = math.ceil(2.0 * math.pi / spacing - v)
        return dataclasses.replace(
            self,
            angle_min=self.angle_min + v * spacing,
            angle_increment=spacing,
            samples=points - 1,
            spin_spread=0.0,
        )


def _as_objects(values: ArrayLike, columns: int, name: str) -> NDArray[np.float64]:
    """A finite float array of shape (M, columns); any empty input is (0, columns)."""
    array = np.asarray(values, dtype=np.float64)
    if array.size == 0:
        return np.empty((0, columns))
    if array.ndim != 2 or array.shape[1] != columns:
        raise ValueError(f"{name} must have shape (M, {columns}), got {array.shape}")
    if not np.all(np.isfinite(array)):
        raise ValueError(f"{name} must be finite")
    return array


def cast_beams(
    T_world_sensor: Transform2D,
    angles_rad: ArrayLike,
    circles: ArrayLike,
    segments: ArrayLike,
) -> tuple[NDArray[np.float64], NDArray[np.intp]]:
    """Exact nearest hits of beams from the sensor pose (no noise, no range limits).

    ``circles`` (M, 3) rows ``[x, y, r]`` and ``segments`` (K, 4) rows ``[x0, y0, x1, y1]`` are in the
    world frame (m; radii > 0); ``angles_rad`` (B,) are beam directions in the sensor frame. Returns
    ``range_m`` (B,), the true range (``inf`` where nothing is hit), and ``hit`` (B,), the index of the
    object hit: ``0 .. M-1`` for circles, ``M .. M+K-1`` for segments, ``-1`` for none. Vectorised over
    beams x objects (see the module docstring for the intersection formulas). ValueError on bad shapes,
    non-finite values or radii <= 0.
    """
    phi = np.asarray(angles_rad, dtype=np.float64)
    if phi.ndim != 1 or not np.all(np.isfinite(phi)):
        raise ValueError(f"angles_rad must be a finite 1-D array, got shape {phi.shape}")
    circles_world = _as_objects(circles, 3, "circles")
    segments_world = _as_objects(segments, 4, "segments")
    if np.any(circles_world[:, 2] <= 0.0):
        raise ValueError("circle radii must be > 0")

    # objects in the sensor frame: p_sensor = T_sensor_world @ p_world
    T_sensor_world = T_world_sensor.inverse()
    u = np.stack((np.cos(phi), np.sin(phi)), axis=1)  # (B, 2)
    t = np.full((phi.size, circles_world.shape[0] + segments_world.shape[0]), np.inf)

    if circles_world.shape[0]:
        c = T_sensor_world @ circles_world[:, :2]  # (M, 2)
        r = circles_world[:, 2]
        beta = u @ c.T  # (B, M), beta = u . c
        q = np.einsum("mi,mi->m", c, c) - r * r  # q = |c|^2 - r^2
        disc = beta * beta - q
        root = np.sqrt(np.maximum(disc, 0.0))
        with np.errstate(divide="ignore", invalid="ignore"):
            # outside: t = q / (beta + sqrt(beta^2 - q)); inside: t = beta + sqrt(beta^2 - q)
            t_circle = np.where(q > 0.0, q / (beta + root), beta + root)
        hit = (disc >= 0.0) & ((q <= 0.0) | (beta > 0.0)) & (t_circle > 0.0)
        t[:, : c.shape[0]] = np.where(hit, t_circle, np.inf)

    if segments_world.shape[0]:
        p0 = T_sensor_world @ segments_world[:, :2]  # (K, 2)
        e = T_sensor_world @ segments_world[:, 2:] - p0
        u_cross_e = np.outer(u[:, 0], e[:, 1]) - np.outer(u[:, 1], e[:, 0])  # (B, K)
        p0_cross_e = p0[:, 0] * e[:, 1] - p0[:, 1] * e[:, 0]  # (K,)
        p0_cross_u = np.outer(u[:, 1], p0[:, 0]) - np.outer(u[:, 0], p0[:, 1])  # (B, K)
        with np.errstate(divide="ignore", invalid="ignore"):
            # t = (p0 x e) / (u x e),  s = (p0 x u) / (u x e)
            t_segment = p0_cross_e / u_cross_e
            s = p0_cross_u / u_cross_e
        hit = (u_cross_e != 0.0) & (t_segment > 0.0) & (s >= 0.0) & (s <= 1.0)
        t[:, circles_world.shape[0] :] = np.where(hit, t_segment, np.inf)

    if t.shape[1] == 0:
        return np.full(phi.size, np.inf), np.full(phi.size, -1, dtype=np.intp)
    nearest = np.argmin(t, axis=1)
    range_m = t[np.arange(phi.size), nearest]
    return range_m, np.where(np.isfinite(range_m), nearest, -1)


def simulate_scan(
    T_world_sensor: Transform2D,
    circles: ArrayLike,
    segments: ArrayLike,
    config: LidarConfig,
    rng: np.random.Generator | None = None,
) -> NDArray[np.float64]:
    """A simulated scan: measured ranges (m), shape (config.samples,), ``no_return`` where there is none.

    ``T_world_sensor`` is the sensor pose, ``circles`` (M, 3) ``[x, y, r]`` and ``segments`` (K, 4)
    ``[x0, y0, x1, y1]`` the world (m). Each beam's true range from :func:`cast_beams` becomes
    ``quantise(t + n)`` with ``n ~ N(0, noise^2)``; a beam reads ``no_return`` when nothing was hit or
    the measured range falls outside ``[range_min, range_max]``. ``rng`` draws the noise (a fresh,
    OS-seeded generator when None and ``config.noise > 0``; pass a seeded one for reproducible scans).
    The layout is ``config``'s own: draw a spinning LiDAR's with :meth:`LidarConfig.scan_layout` first.
    """
    true_range_m, _ = cast_beams(T_world_sensor, config.angles(), circles, segments)
    range_m = true_range_m
    if config.noise > 0.0:
        rng = np.random.default_rng() if rng is None else rng
        # t + n,  n ~ N(0, noise^2)
        range_m = range_m + rng.normal(0.0, config.noise, size=range_m.shape)
    if config.resolution > 0.0:
        # resolution * round(v / resolution)
        with np.errstate(invalid="ignore"):
            range_m = config.resolution * np.round(range_m / config.resolution)
    returned = (range_m >= config.range_min) & (range_m <= config.range_max)
    return np.where(returned, range_m, config.no_return)


def arena_walls(x_length: float, y_length: float) -> NDArray[np.float64]:
    """The inner faces of a rectangular arena centred at the world origin, shape (4, 4).

    Rows ``[x0, y0, x1, y1]`` (m) run counter-clockwise: bottom (y = -y_length/2), right, top, left
    (:func:`polygon_walls` of the corners from ``(-x_length/2, -y_length/2)``). Both lengths must be
    finite and > 0 (ValueError).
    """
    for name, value in (("x_length", x_length), ("y_length", y_length)):
        if not (math.isfinite(value) and value > 0.0):
            raise ValueError(f"arena {name} must be finite and > 0, got {value!r}")
    hx, hy = 0.5 * x_length, 0.5 * y_length
    return polygon_walls([[-hx, -hy], [hx, -hy], [hx, hy], [-hx, hy]])


def polygon_walls(corners: ArrayLike) -> NDArray[np.float64]:
    """The walls of a closed polygon, shape (N, 4): row ``k`` is ``[x_k, y_k, x_k+1, y_k+1]`` (m), from
    corner ``k`` to the next (the last back to the first), for ``corners`` (N, 2) in order.

    ValueError unless the polygon is simple: at least 3 finite corners, no edge of zero length, no two
    edges that touch other than neighbours at their shared corner, and a non-zero area.
    """
    p = np.asarray(corners, dtype=np.float64)
    if p.ndim != 2 or p.shape[1] != 2 or p.shape[0] < 3 or not np.all(np.isfinite(p)):
        raise ValueError(f"a polygon needs at least 3 finite (x, y) corners, got {p.tolist()}")
    walls = np.hstack([p, np.roll(p, -1, axis=0)])
    if np.any(np.hypot(walls[:, 2] - walls[:, 0], walls[:, 3] - walls[:, 1]) == 0.0):
        raise ValueError("a polygon's consecutive corners must differ")
    n = p.shape[0]
    for i in range(n):
        for j in range(i + 1, n):
            if j == i + 1 or (i == 0 and j == n - 1):
                continue  # neighbours share a corner
            if _segments_touch(walls[i], walls[j]):
                raise ValueError(f"the polygon's edges {i} and {j} cross: it must be simple")
    # shoelace: 2 A = sum x_k y_k+1 - x_k+1 y_k
    if np.sum(walls[:, 0] * walls[:, 3] - walls[:, 2] * walls[:, 1]) == 0.0:
        raise ValueError("the polygon has no area")
    return walls


def _segments_touch(a: NDArray[np.float64], b: NDArray[np.float64]) -> bool:
    """Whether segments ``[x0, y0, x1, y1]`` ``a`` and ``b`` share a point (orientation tests)."""

    def cross(o: NDArray[np.float64], p: NDArray[np.float64], q: NDArray[np.float64]) -> float:
        return float((p[0] - o[0]) * (q[1] - o[1]) - (p[1] - o[1]) * (q[0] - o[0]))

    def on(o: NDArray[np.float64], p: NDArray[np.float64], q: NDArray[np.float64]) -> bool:
        # q, collinear with o -> p, lies within its bounding box
        return bool(np.all(np.minimum(o, p) <= q) and np.all(q <= np.maximum(o, p)))

    a0, a1, b0, b1 = a[:2], a[2:], b[:2], b[2:]
    d1, d2, d3, d4 = cross(b0, b1, a0), cross(b0, b1, a1), cross(a0, a1, b0), cross(a0, a1, b1)
    if ((d1 > 0) != (d2 > 0)) and ((d3 > 0) != (d4 > 0)) and 0 not in (d1, d2, d3, d4):
        return True
    return (
        (d1 == 0 and on(b0, b1, a0))
        or (d2 == 0 and on(b0, b1, a1))
        or (d3 == 0 and on(a0, a1, b0))
        or (d4 == 0 and on(a0, a1, b1))
    )
