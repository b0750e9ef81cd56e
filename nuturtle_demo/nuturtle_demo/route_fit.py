"""The driver's figure eight fitted to the world and to the model: the largest loop radius, up to the route's
own, whose two loops keep the robot clear of every cylinder, wall, box and leg and whose wheel speeds the
robot's motors hold with room left for the tracking. No ROS node.

The route (``driver.py``) is two circles of radius ``R`` touching at the start pose ``T_world_start``: the
counter-clockwise one centred at ``T_world_start @ (0, R)``, the clockwise one at ``T_world_start @ (0, -R)``.
A radius fits at a start pose when

- every point of both circles (sampled every ``2 pi / ROUTE_SAMPLES``) leaves the robot's disc, of the
  model's ``collision_radius`` grown by ``ROUTE_CLEARANCE_M`` for the tracking error, free in the simulated
  world, rooms and furniture included (:meth:`nusim.house.WorldGeometry.first_collision`);
- the loop's wheel speeds ``phi_dot = H(0) [v / R, v, 0]`` as the motors hold them
  (:class:`nuturtle_demo.driver.FigureEight`) stay within ``ROUTE_WHEEL_SHARE`` of the model's
  ``max_wheel_speed``: the rest is the tracking law's, which turns harder when the robot is off the route.
  This bounds the radius from below: ``R >= v W / 2 / (ROUTE_WHEEL_SHARE phi_max r - v)`` (wheel radius
  ``r``, track ``W``): about 0.23 m for the Burger and 0.20 m for the Waffle at the route's 0.14 m/s.

Radii are tried from the route's own down by ``ROUTE_SHRINK`` at a time. :func:`fit_route` first keeps the
world's start pose: the largest radius that fits there. When none does (the Waffle, 0.22 m in radius, at
turtlebot3_world's spawn between the hexagon's south-west side and the first column of cylinders), it
places the route: for each radius, largest first, every start on a ``PLACEMENT_STEP_M`` grid inside the
world and ``PLACEMENT_HEADINGS`` headings (a figure eight and the one turned by pi cover the same ground)
is tried, and the first radius with a clear placement is taken at the start nearest the world's. In the
default world the route's own 0.75 m fits at the start, in turtlebot3_world a Burger keeps its spawn with
smaller loops and a Waffle's loops move into the strip between the cylinders and the south wall, and in
rooms_world the living room holds the route's own.

Several robots (:func:`fleet_route`) share the one fitted figure eight, spaced along it in time: robot
``k`` joins the route at ``s_k = s_0 + k Delta T`` (``T`` one loop's period, ``s_0`` the run's
``--route-start``) and starts at ``T_world_start @ T_start_ref(s_k)``, so they drive it one after the other
and never meet. On loops of
radius ``R`` the robots at ``f`` and ``f + Delta`` (in loops) are ``R d(f, Delta)`` apart; the spacing
``Delta`` among FLEET_SPACINGS that keeps the smallest distance of every pair over the route's two loops
the largest is taken: half a loop for two robots (always ``2 R`` apart: opposite on one loop or mirrored
across the crossing), two thirds for three (``sqrt(3) R``), about a quarter for four (``1.41 R``). It
fits when that distance, measured along the route as driven (:class:`FigureEight`), keeps the robots'
discs grown by ROUTE_CLEARANCE_M apart.
"""

from __future__ import annotations

import math
from collections.abc import Iterator
from dataclasses import dataclass, replace

import numpy as np
from numpy.typing import NDArray

from nusim.house import WorldGeometry
from nusim.simulation import SimulationConfig
from nuturtle_description.robot_params import RobotParams
from turtlelib import Transform2D

from .driver import FigureEight, RouteConfig

# Clearance kept between the robot's disc and any cylinder or wall along the route (m)
ROUTE_CLEARANCE_M = 0.05
# Each radius tried is this fraction of the one before
ROUTE_SHRINK = 0.9
# The share of the motors' max_wheel_speed the loop's own wheel speeds may take (the rest is the tracking's)
ROUTE_WHEEL_SHARE = 0.9
# Grid spacing (m) of the start positions tried when the world's start fits no route
PLACEMENT_STEP_M = 0.05
# Start headings tried there (rad): 0 to pi in steps of pi / 6 (the hexagon's and the grid's symmetries)
PLACEMENT_HEADINGS = tuple(k * math.pi / 6.0 for k in range(6))
# Spacings tried between consecutive robots on the route (in loops: fractions of one loop's period), and
# the samples per loop where their distances are measured
FLEET_SPACINGS = tuple(k / 240.0 for k in range(1, 481))
FLEET_SAMPLES_PER_LOOP = 360


@dataclass(frozen=True)
class FittedRoute:
    """The figure eight: loops of ``radius_m`` (m) from ``T_world_start``; ``moved``: that start is not the
    world's (no route fits there)."""

    T_world_start: Transform2D
    radius_m: float
    moved: bool

    def describe(self) -> str:
        x, y, theta = self.T_world_start.x, self.T_world_start.y, self.T_world_start.theta
        where = "placed at" if self.moved else "from the start"
        return f"route: figure eight of {self.radius_m:.3f} m loops {where} ({x:.2f}, {y:.2f}, {theta:.3f})"


def loop_centres(T_world_start: Transform2D, radius_m: float) -> NDArray[np.float64]:
    """The centres (2, 2) of the figure eight's loops of ``radius_m`` (m) from ``T_world_start``: counter-
    clockwise then clockwise."""
    return T_world_start @ np.array([[0.0, radius_m], [0.0, -radius_m]])


def loop_margins(world: WorldGeometry, c_world: NDArray[np.float64], radius_m: float, clearance_m: float):
    """How far (m) each circle of ``radius_m`` centred at ``c_world`` (..., 2) keeps a disc of
    ``clearance_m`` from every wall, box side and cylinder: ``(margins (...,), nearest (...,))``, negative
    where it meets one; ``nearest`` indexes ``world.segments`` then ``world.circles`` after them.

    Along a segment the distance ``t = |p - c|`` takes every value in ``[d_near, d_far]`` (its nearest point
    to ``c``, its farther end), so the circle ``|p - c| = R`` is ``max(d_near - R, R - d_far, 0)`` from it; a
    cylinder ``(q, r)`` is ``| |q - c| - R | - r`` from it. The start inside the arena and out of every box,
    a circle clear of every wall stays so (whether ``c`` is inside is not checked here)."""
    c = c_world[..., None, :]
    segments, circles = world.segments, world.circles
    a, b = segments[:, :2], segments[:, 2:]
    e = b - a
    # d_near = |c - (a + s e)|, s = clip((c - a).e / e.e, 0, 1); d_far = max(|c - a|, |c - b|)
    s = np.clip(np.sum((c - a) * e, axis=-1) / np.sum(e * e, axis=-1), 0.0, 1.0)
    near_m = np.linalg.norm(c - a - s[..., None] * e, axis=-1)
    far_m = np.maximum(np.linalg.norm(c - a, axis=-1), np.linalg.norm(c - b, axis=-1))
    wall_m = np.maximum(np.maximum(near_m - radius_m, radius_m - far_m), 0.0)
    # | |q - c| - R | - r
    circle_m = np.abs(np.linalg.norm(c - circles[:, :2], axis=-1) - radius_m) - circles[:, 2]
    distances_m = np.concatenate([wall_m, circle_m], axis=-1)
    return distances_m.min(axis=-1) - clearance_m, distances_m.argmin(axis=-1)


def route_clearance_m(robot: RobotParams) -> float:
    """The robot's collision radius grown by ROUTE_CLEARANCE_M (m)."""
    return robot.collision_radius + ROUTE_CLEARANCE_M


def route_collision(
    config: SimulationConfig, radius_m: float, T_world_start: Transform2D | None = None
) -> str | None:
    """Why the figure eight of ``radius_m`` from ``T_world_start`` (default: the world's start) is not
    clear (its start, or the loop nearest an obstacle), or None."""
    if T_world_start is None:
        T_world_start = config.arena.T_world_start
    world = config.world
    clearance_m = route_clearance_m(config.robot)
    start_reason = world.first_collision(T_world_start.translation, clearance_m)
    if start_reason is not None:
        return f"at the start the robot {start_reason}"
    centres = loop_centres(T_world_start, radius_m)
    margins, nearest = loop_margins(world, centres, radius_m, clearance_m)
    k = int(np.argmin(margins))
    if margins[k] >= 0.0:
        return None
    n_walls = len(world.segments)
    if nearest[k] < n_walls:
        x0, y0, x1, y1 = world.segments[nearest[k]]
        what = f"the wall ({x0:.2f}, {y0:.2f}) -> ({x1:.2f}, {y1:.2f})"
    else:
        x, y, r = world.circles[nearest[k] - n_walls]
        what = f"the cylinder of radius {r} m at ({x:.2f}, {y:.2f})"
    distance_m = margins[k] + clearance_m
    passes = "crosses" if distance_m == 0.0 else f"passes {distance_m:.3f} m from"
    return f"the loop centred at ({centres[k, 0]:.2f}, {centres[k, 1]:.2f}) m {passes} {what}"


def wheel_speeds_fit(robot: RobotParams, route: RouteConfig) -> bool:
    """Whether the loop's wheel speeds (as the motors hold them) are within ROUTE_WHEEL_SHARE of the
    robot's ``max_wheel_speed``."""
    try:
        wheel_rad_s = FigureEight.for_robot(route, robot).wheel_speeds_rad_s
    except ValueError:  # above max_wheel_speed, or too wide to turn at the motors' resolution
        return False
    return max(abs(w) for w in wheel_rad_s) <= ROUTE_WHEEL_SHARE * robot.max_wheel_speed


def candidate_radii(robot: RobotParams, route: RouteConfig) -> Iterator[float]:
    """``R, R ROUTE_SHRINK, ...`` from the route's own radius while the wheel speeds fit (they only grow
    as the radius shrinks)."""
    radius_m = route.radius
    while wheel_speeds_fit(robot, replace(route, radius=radius_m)):
        yield radius_m
        radius_m *= ROUTE_SHRINK


def placement_starts(config: SimulationConfig) -> NDArray[np.float64]:
    """Start positions (n, 2) on the PLACEMENT_STEP_M grid over the walls' extent where the robot's disc,
    grown by the route's clearance, is free, nearest the world's start first."""
    segments = config.wall_segments
    lo = np.minimum(segments[:, :2], segments[:, 2:]).min(axis=0)
    hi = np.maximum(segments[:, :2], segments[:, 2:]).max(axis=0)
    xs, ys = (np.arange(lo[k], hi[k] + PLACEMENT_STEP_M, PLACEMENT_STEP_M) for k in range(2))
    grid = np.stack(np.meshgrid(xs, ys), axis=-1).reshape(-1, 2)
    clearance_m = route_clearance_m(config.robot)
    starts = np.array([p for p in grid if config.world.first_collision(p, clearance_m) is None]).reshape(
        -1, 2
    )
    return starts[np.argsort(np.hypot(*(starts - config.arena.T_world_start.translation).T), kind="stable")]


def placed_start(
    config: SimulationConfig, radius_m: float, starts: NDArray[np.float64]
) -> Transform2D | None:
    """The clear figure eight of ``radius_m`` whose start comes first in ``starts`` (n, 2) (any heading of
    PLACEMENT_HEADINGS, the first of them on a tie), or None."""
    headings = np.array(PLACEMENT_HEADINGS)
    # loop centres (n, headings, 2 loops, 2): p +- R (-sin theta, cos theta)
    left = radius_m * np.column_stack([-np.sin(headings), np.cos(headings)])
    centres = starts[:, None, None, :] + np.stack([left, -left], axis=1)[None]
    margins, _ = loop_margins(config.world, centres, radius_m, route_clearance_m(config.robot))
    clear = np.all(margins >= 0.0, axis=2)
    if not np.any(clear):
        return None
    k, h = np.argwhere(clear)[0]
    return Transform2D(float(starts[k, 0]), float(starts[k, 1]), float(headings[h]))


def fit_route(config: SimulationConfig, route: RouteConfig, place: bool = True) -> FittedRoute:
    """The figure eight for the world and robot of ``config`` (module docstring): the world's start with
    the largest fitting radius, else (with ``place``) the largest radius placed nearest that start.
    ValueError naming the model and the world's start when none fits."""
    radii = list(candidate_radii(config.robot, route))
    T_start = config.arena.T_world_start
    for radius_m in radii:
        if route_collision(config, radius_m) is None:
            return FittedRoute(T_start, radius_m, moved=False)
    if place and radii:
        starts = placement_starts(config)
        for radius_m in radii:
            T_placed = placed_start(config, radius_m, starts)
            if T_placed is not None:
                return FittedRoute(T_placed, radius_m, moved=True)
    robot = config.robot
    if not radii:
        raise ValueError(
            f"loops of radius {route.radius} m at {route.velocity} m/s need wheel speeds above "
            f"{ROUTE_WHEEL_SHARE} of the max wheel speed {robot.max_wheel_speed:.3f} rad/s"
        )
    raise ValueError(
        f"no figure eight of radius {radii[-1]:.3f} to {route.radius} m at {route.velocity} m/s fits a robot "
        f"of collision radius {robot.collision_radius} m (max wheel speed {robot.max_wheel_speed:.3f} rad/s) "
        f"{'anywhere' if place else 'from the start pose'} in this world, clear of its cylinders, walls "
        f"and furniture by {ROUTE_CLEARANCE_M} m ({route_collision(config, radii[-1])})"
    )


@dataclass(frozen=True)
class FleetRoute:
    """Robots on one figure eight (module docstring): robot ``k`` joins the route at ``route_starts_s[k]``
    (s) and starts at ``starts[k]`` (nusim/world); ``gap_m``: the smallest distance (m) between two of them
    along the route as driven."""

    starts: tuple[Transform2D, ...]
    route_starts_s: tuple[float, ...]
    gap_m: float


def unit_route_xy(f_loops: NDArray[np.float64]) -> NDArray[np.float64]:
    """The figure eight of unit radius from the origin facing +x at ``f_loops`` loops into it (..., 2):
    ``(sin a, 1 - cos a)`` on the counter-clockwise loop, ``(sin a, cos a - 1)`` on the clockwise one,
    ``a = 2 pi frac(f)``."""
    angle = 2.0 * np.pi * np.mod(f_loops, 1.0)
    y = 1.0 - np.cos(angle)
    return np.stack([np.sin(angle), np.where(np.mod(f_loops, 2.0) < 1.0, y, -y)], axis=-1)


def fleet_spacing(n: int) -> float:
    """The spacing (loops) among FLEET_SPACINGS, up to two loops over ``n``, that keeps ``n`` robots on the
    unit figure eight farthest apart (the smallest pairwise distance over its two loops the largest; the
    smallest spacing on a tie)."""
    f = np.arange(2 * FLEET_SAMPLES_PER_LOOP) / FLEET_SAMPLES_PER_LOOP
    spacings = np.array([d for d in FLEET_SPACINGS if d <= 2.0 / n + 1e-12])
    # xy (spacings, robots, samples, 2)
    xy = unit_route_xy(f[None, None, :] + spacings[:, None, None] * np.arange(n)[None, :, None])
    a, b = np.triu_indices(n, 1)
    gaps = np.linalg.norm(xy[:, a] - xy[:, b], axis=-1).min(axis=(1, 2))
    return float(spacings[int(np.argmax(gaps))])


def fleet_route(
    fitted: FittedRoute, figure: FigureEight, n: int, robot: RobotParams, route_start_s: float = 0.0
) -> FleetRoute:
    """``n`` (>= 1) robots on the fitted figure eight (module docstring), the first ``route_start_s`` (s)
    into it. ValueError when two of them would come nearer than their discs grown by ROUTE_CLEARANCE_M."""
    if n < 1:
        raise ValueError(f"the number of robots must be >= 1, got {n}")
    if n == 1:
        return FleetRoute(
            (fitted.T_world_start @ figure.reference(route_start_s),), (route_start_s,), math.inf
        )
    period_s = figure.loop_period_s
    route_starts_s = tuple(route_start_s + k * fleet_spacing(n) * period_s for k in range(n))
    tau_s = np.arange(2 * FLEET_SAMPLES_PER_LOOP) * period_s / FLEET_SAMPLES_PER_LOOP
    # each robot's positions along the route as driven: T_start_ref(tau + s_k)
    xy = np.array([[figure.reference(t + s).translation for t in tau_s] for s in route_starts_s])
    a, b = np.triu_indices(n, 1)
    gap_m = float(np.linalg.norm(xy[a] - xy[b], axis=-1).min())
    needed_m = 2.0 * route_clearance_m(robot)
    if gap_m < needed_m:
        raise ValueError(
            f"{n} robots on the figure eight of {fitted.radius_m:.3f} m loops come {gap_m:.3f} m near each "
            f"other, less than two collision radii and their clearance ({needed_m:.3f} m)"
        )
    starts = tuple(fitted.T_world_start @ figure.reference(s) for s in route_starts_s)
    return FleetRoute(starts, route_starts_s, gap_m)
