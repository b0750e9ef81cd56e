"""The driver's figure eight fitted to the world: the largest loop radius, up to the route's own, whose two
loops keep the robot clear of every cylinder, wall, box and leg. No ROS.

The route (``driver.py``) is two circles of radius ``R`` touching at the start pose ``T_world_start``: the
counter-clockwise one centred at ``T_world_start @ (0, R)``, the clockwise one at ``T_world_start @ (0, -R)``.
A radius fits when every point of both circles (sampled every ``2 pi / ROUTE_SAMPLES``) leaves the robot's
disc, grown by ``ROUTE_CLEARANCE_M`` for the tracking error, free in the simulated world, rooms and
furniture included (:meth:`nusim.house.WorldGeometry.first_collision`). Radii are tried from the route's
down by ``ROUTE_SHRINK`` at a time; in the default world the route's own 0.75 m fits, in turtlebot3_world
(spawn at (-2.0, -0.5) between the hexagon's south-west side and the first column of cylinders) a smaller
one does, and in rooms_world the living room holds the route's own.
"""

from __future__ import annotations

import math

import numpy as np
from numpy.typing import NDArray

from nusim.simulation import SimulationConfig
from turtlelib import Transform2D

# Clearance kept between the robot's disc and any cylinder or wall along the route (m)
ROUTE_CLEARANCE_M = 0.05
# Each radius tried is this fraction of the one before
ROUTE_SHRINK = 0.9
# Below this loop radius (m) the motors cannot follow the route at its speed: no fit
MIN_ROUTE_RADIUS_M = 0.2
# Points per loop checked
ROUTE_SAMPLES = 180


def route_points(T_world_start: Transform2D, radius_m: float) -> NDArray[np.float64]:
    """Points (2 ROUTE_SAMPLES, 2) on both loops of the figure eight of ``radius_m`` (m) from
    ``T_world_start``."""
    angles = np.linspace(0.0, 2.0 * math.pi, ROUTE_SAMPLES, endpoint=False)
    ring = radius_m * np.column_stack([np.cos(angles), np.sin(angles)])
    centres = T_world_start @ np.array([[0.0, radius_m], [0.0, -radius_m]])
    return np.vstack([centres[0] + ring, centres[1] + ring])


def route_collision(config: SimulationConfig, radius_m: float) -> str | None:
    """Why the figure eight of ``radius_m`` from the world's start is not clear (first blocked point), or
    None."""
    clearance_m = config.robot.collision_radius + ROUTE_CLEARANCE_M
    for p in route_points(config.arena.T_world_start, radius_m):
        collision = config.world.first_collision(p, clearance_m)
        if collision is not None:
            return f"at ({p[0]:.2f}, {p[1]:.2f}) m the robot {collision}"
    return None


def fitted_route_radius(config: SimulationConfig, radius_m: float) -> float:
    """The largest of ``radius_m``, ``radius_m ROUTE_SHRINK``, ... (>= MIN_ROUTE_RADIUS_M) whose figure
    eight is clear in the world ``config`` (module docstring). ValueError when none is."""
    candidate = radius_m
    while candidate >= MIN_ROUTE_RADIUS_M:
        if route_collision(config, candidate) is None:
            return candidate
        candidate *= ROUTE_SHRINK
    raise ValueError(
        f"no figure eight of radius {MIN_ROUTE_RADIUS_M} to {radius_m} m from the start pose clears the "
        f"world's cylinders, walls and furniture by {ROUTE_CLEARANCE_M} m "
        f"({route_collision(config, radius_m)}): choose another start or route radius"
    )
