"""The demo's figure eight fitted to the world (nuturtle_demo.route_fit, no ROS): the default world keeps
the route's 0.75 m loops, nusim's turtlebot3_world (nusim/config/turtlebot3_world.yaml, read as the demo
reads a world) gets the largest smaller radius whose loops clear its cylinders and hexagon, and the rooms
world's living room holds the route's own."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
from world_files import ROOMS_POSTS_WORLD, world_config

from nusim.free_space import wall_distances
from nusim.simulation import ArenaConfig, Obstacles, SimulationConfig, Walls
from nuturtle_demo.driver import RouteConfig
from nuturtle_demo.route_fit import (
    MIN_ROUTE_RADIUS_M,
    ROUTE_CLEARANCE_M,
    ROUTE_SHRINK,
    fitted_route_radius,
    route_collision,
    route_points,
)
from nuturtle_ros_common.ros_files import load_ros_parameters
from turtlelib import Transform2D

WORLD = Path(__file__).resolve().parents[2] / "nusim" / "config" / "turtlebot3_world.yaml"


def turtlebot3_world() -> SimulationConfig:
    values = load_ros_parameters(WORLD)
    return SimulationConfig(
        arena=ArenaConfig(values["x0"], values["y0"], values["theta0"]),
        obstacles=Obstacles(values["obstacles.x"], values["obstacles.y"], values["obstacles.r"]),
        walls=Walls(values["walls.x"], values["walls.y"]),
    )


def test_route_points_are_the_two_loops_touching_at_the_start():
    # from (1, 2) facing +y: the counter-clockwise loop centred R to the left (-x), the other to the right
    points = route_points(Transform2D(1.0, 2.0, np.pi / 2), 0.5)
    left, right = points[: len(points) // 2], points[len(points) // 2 :]
    np.testing.assert_allclose(np.hypot(*(left - [0.5, 2.0]).T), 0.5, atol=1e-12)
    np.testing.assert_allclose(np.hypot(*(right - [1.5, 2.0]).T), 0.5, atol=1e-12)


def test_the_default_world_keeps_the_route_s_radius():
    assert fitted_route_radius(SimulationConfig(), RouteConfig().radius) == RouteConfig().radius


def test_turtlebot3_world_gets_the_largest_clear_smaller_loops():
    config = turtlebot3_world()
    radius = RouteConfig().radius
    assert route_collision(config, radius) is not None  # the route's own loops hit a cylinder or wall
    fitted = fitted_route_radius(config, radius)
    assert MIN_ROUTE_RADIUS_M <= fitted < radius
    assert route_collision(config, fitted) is None
    assert route_collision(config, fitted / ROUTE_SHRINK) is not None
    # every point of the fitted loops clears walls and cylinders by the robot's radius and the margin
    clearance = config.robot.collision_radius + ROUTE_CLEARANCE_M
    circles = config.obstacles.circles()
    for p in route_points(config.arena.T_world_start, fitted):
        assert wall_distances(p, config.wall_segments).min() >= clearance
        assert np.all(np.hypot(*(circles[:, :2] - p).T) >= circles[:, 2] + clearance)


@pytest.mark.parametrize("seed", [0, 1, 2])
def test_the_rooms_world_keeps_the_route_s_radius_in_its_living_room(seed):
    # the chairs move with the seed, never onto the route; rooms_world.yaml is this world without posts
    config = world_config(ROOMS_POSTS_WORLD, seed=seed)
    assert fitted_route_radius(config, RouteConfig().radius) == RouteConfig().radius


def test_no_clear_route_is_a_clear_error():
    # a cylinder 0.4 m ahead: a loop of radius R passes sqrt(0.16 + R^2) - R < 0.25 m from its centre
    # for every R >= 0.2 m, so within the robot's radius, the cylinder's and the margin
    config = SimulationConfig(obstacles=Obstacles((0.4,), (0.0,), (0.1,)))
    with pytest.raises(ValueError, match="no figure eight of radius"):
        fitted_route_radius(config, 0.75)
