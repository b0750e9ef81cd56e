"""The demo's figure eight fitted to the world and the model (nuturtle_demo.route_fit, no ROS node): the
default world keeps the route's 0.75 m loops, nusim's turtlebot3_world (nusim/config/turtlebot3_world.yaml,
read as the demo reads a world) keeps a Burger at its spawn with smaller loops and places a Waffle's loops
elsewhere, each clear of the cylinders and the hexagon by the model's radius and margin and within its
wheel speeds, and the rooms world's living room holds the route's own."""

from __future__ import annotations

import math
from dataclasses import replace
from pathlib import Path

import numpy as np
import pytest
from world_files import ROOMS_POSTS_WORLD, world_config

from nusim.free_space import wall_distances
from nusim.simulation import ArenaConfig, Obstacles, SimulationConfig
from nuturtle_demo.driver import FigureEight, RouteConfig
from nuturtle_demo.route_fit import (
    ROUTE_CLEARANCE_M,
    ROUTE_SHRINK,
    ROUTE_WHEEL_SHARE,
    FittedRoute,
    fit_route,
    fleet_route,
    fleet_spacing,
    loop_centres,
    route_collision,
)
from nuturtle_description.robot_params import model_params
from turtlelib import Transform2D

WORLD = Path(__file__).resolve().parents[2] / "nusim" / "config" / "turtlebot3_world.yaml"


def turtlebot3_world(model: str) -> SimulationConfig:
    return replace(world_config(WORLD), robot=model_params(model))


def loop_points(T_world_start: Transform2D, radius_m: float, samples: int = 720) -> np.ndarray:
    """Points (2 samples, 2) on both loops, sampled independently of the fit's closed form."""
    angles = np.linspace(0.0, 2.0 * math.pi, samples, endpoint=False)
    ring = radius_m * np.column_stack([np.cos(angles), np.sin(angles)])
    return np.vstack([c + ring for c in loop_centres(T_world_start, radius_m)])


def test_loop_centres_lie_left_and_right_of_the_start():
    # from (1, 2) facing +y: the counter-clockwise loop centred R to the left (-x), the other to the right
    np.testing.assert_allclose(loop_centres(Transform2D(1.0, 2.0, np.pi / 2), 0.5), [[0.5, 2.0], [1.5, 2.0]])


def test_the_default_world_keeps_the_route_s_radius():
    route = fit_route(SimulationConfig(), RouteConfig())
    assert (route.radius_m, route.moved) == (RouteConfig().radius, False)


@pytest.mark.parametrize("model", ["burger", "waffle", "waffle_pi"])
def test_turtlebot3_world_route_clears_the_world_within_the_wheel_limits(model):
    config = turtlebot3_world(model)
    assert route_collision(config, RouteConfig().radius) is not None  # the route's own loops hit something
    route = fit_route(config, RouteConfig())
    assert route_collision(config, route.radius_m, route.T_world_start) is None
    # every point of the loops clears walls and cylinders by the model's radius and the margin
    clearance = config.robot.collision_radius + ROUTE_CLEARANCE_M
    circles = config.obstacles.circles()
    for p in loop_points(route.T_world_start, route.radius_m):
        assert wall_distances(p, config.wall_segments).min() >= clearance
        assert np.all(np.hypot(*(circles[:, :2] - p).T) >= circles[:, 2] + clearance)
    # the loop's commanded wheel speeds leave the tracking its share below the motors' limit
    loop = FigureEight.for_robot(RouteConfig(radius=route.radius_m), config.robot)
    assert max(map(abs, loop.wheel_speeds_rad_s)) <= ROUTE_WHEEL_SHARE * config.robot.max_wheel_speed


def test_turtlebot3_world_keeps_the_burger_s_route():
    # the route of before: 0.75 m shrunk 10 times (0.262 m) from the spawn (-2.0, -0.5) facing +x
    radius = RouteConfig().radius
    for _ in range(10):
        radius *= ROUTE_SHRINK
    route = fit_route(turtlebot3_world("burger"), RouteConfig())
    assert (route.radius_m, route.moved) == (radius, False)
    assert route.T_world_start == turtlebot3_world("burger").arena.T_world_start


def test_turtlebot3_world_places_a_waffle_s_route_away_from_its_spawn():
    config = turtlebot3_world("waffle")
    # at the spawn even the smallest loops the wheels allow meet the south-west wall: no fit there
    with pytest.raises(ValueError, match="from the start pose"):
        fit_route(config, RouteConfig(), place=False)
    route = fit_route(config, RouteConfig())
    assert route.moved
    assert route.radius_m > 0.3


@pytest.mark.parametrize("seed", [0, 1, 2])
def test_the_rooms_world_keeps_the_route_s_radius_in_its_living_room(seed):
    # the chairs move with the seed, never onto the route; rooms_world.yaml is this world without posts
    route = fit_route(world_config(ROOMS_POSTS_WORLD, seed=seed), RouteConfig())
    assert (route.radius_m, route.moved) == (RouteConfig().radius, False)


def test_no_clear_route_is_a_clear_error():
    # a cylinder 0.4 m ahead: a loop of radius R passes sqrt(0.16 + R^2) - R < 0.25 m from its centre
    # for every R >= 0.2 m, so within the robot's radius, the cylinder's and the margin
    config = SimulationConfig(obstacles=Obstacles((0.4,), (0.0,), (0.1,)))
    with pytest.raises(ValueError, match="no figure eight of radius .* from the start pose"):
        fit_route(config, RouteConfig(), place=False)
    # a Waffle in a 1 m square arena: no loop the wheels allow fits anywhere
    small = SimulationConfig(
        arena=ArenaConfig(arena_x_length=1.0, arena_y_length=1.0),
        obstacles=Obstacles((), (), ()),
        robot=model_params("waffle"),
    )
    with pytest.raises(ValueError, match="anywhere in this world"):
        fit_route(small, RouteConfig())


def test_robots_on_one_figure_eight_are_spaced_to_stay_apart():
    """Two robots half a loop apart are always 2 R apart (opposite on one loop, or mirrored across the
    crossing), three robots a third of a loop apart sqrt(3) R; each starts on the route where it joins it,
    and robots that would come nearer than their grown discs are refused."""
    assert fleet_spacing(2) == 0.5
    assert fleet_spacing(3) == pytest.approx(1.0 / 3.0)
    burger = model_params("burger")
    figure = FigureEight.for_robot(RouteConfig(), burger)
    start = Transform2D(0.2, -0.1, 0.3)
    two = fleet_route(FittedRoute(start, 0.75, False), figure, 2, burger)
    # the loops as driven: radius v / omega of the motors' rounded wheel speeds (close to 0.75 m)
    radius_m = figure.left_loop.vx / figure.left_loop.omega
    assert two.gap_m == pytest.approx(2.0 * radius_m, rel=1e-4)
    assert two.route_starts_s == pytest.approx((0.0, 0.5 * figure.loop_period_s))
    # half a loop in: the far side of the first loop, 2 R to the start's left, heading back
    assert two.starts[0] == start
    T_first_second = start.inverse() @ two.starts[1]
    np.testing.assert_allclose(T_first_second.translation, [0.0, 2.0 * radius_m], atol=1e-9)
    assert abs(T_first_second.theta) == pytest.approx(math.pi, abs=1e-9)
    three = fleet_route(FittedRoute(start, 0.75, False), figure, 3, burger)
    assert three.gap_m == pytest.approx(math.sqrt(3.0) * radius_m, rel=1e-3)
    assert fleet_route(FittedRoute(start, 0.75, False), figure, 1, burger).starts == (start,)
    small = FigureEight.for_robot(RouteConfig(radius=0.25), burger)
    with pytest.raises(ValueError, match="6 robots on the figure eight of 0.250 m loops come"):
        fleet_route(FittedRoute(start, 0.25, False), small, 6, burger)
