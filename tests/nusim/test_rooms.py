"""nusim's rooms (nusim.house, no ROS): the LiDAR against interior walls, boxes and legs (hand-computed
ranges), the robot stopped by a box, the furniture on legs placed from the seed, the configuration's
errors, and the rooms world files.

Hand-computed world: the 4 m square arena (|x|, |y| <= 2), an interior wall on x = 1 from y = -2 to
y = 0.5 (a doorway above it), a box centred at (-1, 0) of 0.4 m x 0.2 m (faces x = -1.2, -0.8 and
y = +-0.1), a table fixed at (0.168, 1.0), legs 0.4 m apart of radius 0.02 m (one at (-0.032, 0.8)). The
Burger at the origin facing +x: its LiDAR at (-0.032, 0).
"""

from __future__ import annotations

import math
from dataclasses import replace

import numpy as np
import pytest
from world_files import ROOMS_POSTS_WORLD, ROOMS_WORLD, world_config

from nusim.house import PLACEMENT_DRAWS, Boxes, InteriorWalls, Legs
from nusim.simulation import ArenaConfig, NoiseConfig, Obstacles, Simulation, SimulationConfig
from nuturtle_description.robot_params import RobotParams
from nuturtle_ros_common.ros_files import load_ros_parameters
from turtlelib import Transform2D
from turtlelib.sensing.scan_model import LidarConfig

R_ROBOT = 0.11
QUIET = NoiseConfig(input_noise=0.0, slip_fraction=0.0, basic_sensor_variance=0.0)
WALL = InteriorWalls((1.0,), (-2.0,), (1.0,), (0.5,))
BOX = Boxes((-1.0,), (0.0,), (0.4,), (0.2,), (0.0,))
TABLE = Legs((0.168,), (0.168,), (1.0,), (1.0,), (0.0,), (0.0,), (0.4,), (0.4,), (0.02,))


def rooms(start=(0.0, 0.0, 0.0), legs=TABLE, boxes=BOX, obstacles=((), (), ()), noise=QUIET):
    return SimulationConfig(
        arena=ArenaConfig(*start, 4.0, 4.0),
        obstacles=Obstacles(*obstacles),
        robot=RobotParams(),
        noise=noise,
        lidar=LidarConfig(noise=0.0, resolution=0.0),
        interior_walls=WALL,
        boxes=boxes,
        legs=legs,
    )


def test_the_lidar_sees_interior_walls_boxes_and_legs():
    ranges = Simulation(rooms()).scan().range_m
    # +x: the interior wall at x = 1
    assert ranges[0] == pytest.approx(1.032, abs=1e-12)
    # 20 deg: still the interior wall, (1 + 0.032) / cos 20
    assert ranges[20] == pytest.approx(1.032 / math.cos(math.radians(20.0)), abs=1e-12)
    # 30 deg: through the doorway (y = 0.596 > 0.5 at x = 1) to the arena's wall x = 2
    assert ranges[30] == pytest.approx(2.032 / math.cos(math.radians(30.0)), abs=1e-12)
    # +y: the table's leg at (-0.032, 0.8), radius 0.02
    assert ranges[90] == pytest.approx(0.78, abs=1e-12)
    # -x: the box's face x = -0.8
    assert ranges[180] == pytest.approx(0.768, abs=1e-12)
    # -y: the arena's wall
    assert ranges[270] == pytest.approx(2.0, abs=1e-12)


def test_the_robot_stops_at_a_box_and_cannot_be_put_inside_one():
    sim = Simulation(rooms(start=(0.0, 0.0, math.pi)))
    sim.command_wheels(6.0, 6.0)  # 0.198 m/s towards the box's face x = -0.8
    for _ in range(600):
        sim.step(0.01)
    np.testing.assert_allclose(sim.T_world_body.as_array(), [-0.8 + R_ROBOT, 0.0, math.pi], atol=1e-12)
    with pytest.raises(ValueError, match=r"cannot teleport to \(-1.0, 0.05\) m: the robot is inside box 0"):
        sim.teleport(Transform2D(-1.0, 0.05, 0.0))
    with pytest.raises(ValueError, match="the robot is 0.050 m from interior wall 0"):
        sim.teleport(Transform2D(0.95, -1.0, 0.0))
    with pytest.raises(ValueError, match=r"the robot overlaps leg 0 at \(-0.032, 0.800\) m"):
        sim.teleport(Transform2D(-0.032, 0.7, 0.0))


CHAIRS = Legs(
    x_min=(-1.8, 0.2), x_max=(-0.2, 1.8), y_min=(-1.8, -1.8), y_max=(-0.5, -0.5),
    yaw_min=(-math.pi, 0.0), yaw_max=(math.pi, 0.5), length=(0.4, 0.5), width=(0.4, 0.3), r=(0.02, 0.025),
)  # fmt: skip


def test_legs_are_placed_from_the_seed_inside_their_areas_and_free():
    placed = {seed: rooms(legs=CHAIRS, noise=replace(QUIET, seed=seed)).world.legs for seed in (0, 1, 2)}
    np.testing.assert_array_equal(rooms(legs=CHAIRS, noise=replace(QUIET, seed=1)).world.legs, placed[1])
    assert not np.allclose(placed[0], placed[1])
    assert not np.allclose(placed[1], placed[2])
    for seed, legs in placed.items():
        config = rooms(legs=CHAIRS, noise=replace(QUIET, seed=seed))
        for k, piece in enumerate(legs.reshape(2, 4, 3)):
            centre = piece[:, :2].mean(axis=0)
            assert CHAIRS.x_min[k] <= centre[0] <= CHAIRS.x_max[k]
            assert CHAIRS.y_min[k] <= centre[1] <= CHAIRS.y_max[k]
            # a rectangle of length x width between the legs' centres, legs of radius r
            sides = np.hypot(*np.diff(piece[[0, 1, 2, 3, 0], :2], axis=0).T)
            np.testing.assert_allclose(sides, [CHAIRS.length[k], CHAIRS.width[k]] * 2, atol=1e-12)
            np.testing.assert_array_equal(piece[:, 2], CHAIRS.r[k])
            others = replace(config.world, legs=np.delete(legs, np.s_[4 * k : 4 * k + 4], axis=0))
            assert all(others.first_collision(leg[:2], leg[2]) is None for leg in piece)
        # clear of the robot's start disc
        assert np.all(np.hypot(*legs[:, :2].T) >= R_ROBOT + legs[:, 2])
    # the noise streams do not depend on the placement: the same seed, the same wheel noise
    noisy = replace(QUIET, input_noise=0.1, seed=3)
    sims = [Simulation(rooms(legs=legs, noise=noisy)) for legs in (Legs(), CHAIRS)]
    for sim in sims:
        sim.command_wheels(1.0, 1.0)
        sim.step(0.01)
    np.testing.assert_array_equal(sims[0].wheel_speed_rad_s, sims[1].wheel_speed_rad_s)


@pytest.mark.parametrize(
    ("make", "message"),
    [
        (lambda: InteriorWalls((0.0,), (0.0,), (1.0,), ()), "interior_walls.x0, interior_walls.y0, "
         r"interior_walls.x1, interior_walls.y1 must have the same length, got 1, 1, 1, 0"),
        (lambda: InteriorWalls((1.0,), (1.0,), (1.0,), (1.0,)),
         r"interior wall 0 at \(1.0, 1.0\) m has zero length"),
        (lambda: InteriorWalls((math.nan,), (1.0,), (1.0,), (1.0,)),
         r"interior_walls.x0\[0\] must be a finite number, got nan"),
        (lambda: Boxes((0.0,), (0.0,), (1.0,), (-0.2,), (0.0,)), r"boxes.width\[0\] must be finite and > 0"),
        (lambda: Legs(*[(0.0,)] * 6, (0.4,), (0.4,), ()), r"legs.x_min, .* legs.r must have the same length"),
        (lambda: Legs((1.0,), (0.0,), *[(0.0,)] * 4, (0.4,), (0.4,), (0.02,)),
         r"legs.x_min\[0\] \(1.0\) must not exceed legs.x_max\[0\] \(0.0\)"),
        (lambda: Legs(*[(0.0,)] * 6, (0.4,), (0.04,), (0.02,)), "the legs of piece 0 overlap"),
        (lambda: rooms(start=(-1.0, 0.2, 0.0)), r"the robot's start .* is 0.100 m from a side of box 0"),
        (lambda: rooms(obstacles=((-1.1,), (0.0,), (0.038,))), r"obstacle 0 at \(-1.1, 0.0\) m with radius "
         r"0.038 m is inside box 0 at \(-1.000, 0.000\) m"),
        (lambda: rooms(legs=Legs((-1.0,), (-1.0,), (0.0,), (0.0,), (0.0,), (0.0,), (0.1,), (0.1,), (0.02,))),
         rf"piece 0 on legs \(centre in \[-1.0, -1.0\] x \[0.0, 0.0\] m\): no placement of its legs in "
         rf"{PLACEMENT_DRAWS} draws"),
    ],
)  # fmt: skip
def test_invalid_rooms_are_refused_with_the_reason(make, message):
    with pytest.raises(ValueError, match=message):
        make()


def test_the_rooms_worlds_differ_in_their_posts_alone():
    rooms_values, posts_values = load_ros_parameters(ROOMS_WORLD), load_ros_parameters(ROOMS_POSTS_WORLD)
    landmarks = ("obstacles.x", "obstacles.y", "obstacles.r")
    assert {k: v for k, v in rooms_values.items() if k not in landmarks} == {
        k: v for k, v in posts_values.items() if k not in landmarks
    }
    assert rooms_values["obstacles.x"] == []
    config = world_config(ROOMS_POSTS_WORLD)
    assert config.world.landmarks.shape == (5, 3)
    # the same rooms; the chairs move with the seed, the fixed table does not
    other = world_config(ROOMS_POSTS_WORLD, seed=1)
    np.testing.assert_array_equal(other.world.legs[:4], config.world.legs[:4])
    assert not np.allclose(other.world.legs[4:], config.world.legs[4:])
