"""nusim.simulation (no ROS): motor quantisation, exact kinematics, noise and slip statistics, encoders,
collisions (stop at contact), the LiDAR and fake landmark sensor, seeding and validation.

Hand-computed numbers: the Burger (r = 0.033 m, d = 0.16 m, 1 mcu = 1 / 41.6666667 rad/s, 4096 ticks
per turn, collision radius R = 0.11 m) and the LDS-01 mounted at x = -0.032 m in base_footprint.
"""

from __future__ import annotations

import math
from dataclasses import replace

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from nusim.free_space import FreeBall, clearance_m, contact_fraction, first_collision, wall_distances
from nusim.simulation import (
    LIDAR_MODELS,
    ArenaConfig,
    LidarChoice,
    MultiRobotSimulation,
    NoiseConfig,
    Obstacles,
    Robots,
    Simulation,
    SimulationConfig,
    Walls,
    default_lidar,
    robot_streams,
    seed_streams,
)
from nuturtle_description.robot_params import RobotParams
from turtlelib import Transform2D
from turtlelib.sensing.scan_model import LidarConfig, arena_walls, polygon_walls

R_WHEEL = 0.033
TRACK = 0.16
MCU_PER_RAD_S = 1.0 / 0.024
TICKS_PER_RAD = 4096.0 / (2.0 * math.pi)
R_ROBOT = 0.11
LIDAR_X = -0.032
DT = 0.01
QUIET = NoiseConfig(input_noise=0.0, slip_fraction=0.0, basic_sensor_variance=0.0)
EXACT_LIDAR = LidarConfig(noise=0.0, resolution=0.0)


def world(
    obstacles=((), (), ()),
    arena=(4.0, 3.0),
    start=(0.0, 0.0, 0.0),
    noise=QUIET,
    lidar=EXACT_LIDAR,
    walls=None,
) -> Simulation:
    x0, y0, theta0 = start
    return Simulation(
        SimulationConfig(
            arena=ArenaConfig(x0, y0, theta0, *arena),
            obstacles=Obstacles(*obstacles),
            robot=RobotParams(),
            noise=noise,
            lidar=lidar,
            walls=Walls() if walls is None else walls,
        )
    )


def run(sim: Simulation, steps: int, dt_s: float = DT) -> list[Transform2D]:
    poses = []
    for _ in range(steps):
        sim.step(dt_s)
        poses.append(sim.T_world_body)
    return poses


# --- motors ---------------------------------------------------------------------------------------------


@pytest.mark.parametrize(
    ("left", "right", "expected_mcu"),
    [
        (1.0, -1.0, (42, -42)),  # 41.67 rounds to 42 mcu
        (0.011, -0.011, (0, 0)),  # below half a unit: the motor stops
        (6.0, 7.0, (250, 265)),  # 291.7 clamps at motor_cmd_max
        (-1e308, 1e308, (-265, 265)),  # overflowing products saturate too
    ],
)
def test_wheel_commands_are_quantised_to_motor_units_and_clamped(left, right, expected_mcu):
    sim = world()
    assert tuple(sim.command_wheels(left, right)) == expected_mcu
    np.testing.assert_allclose(sim.commanded_speed_rad_s, np.array(expected_mcu) * 0.024, rtol=1e-7)


@pytest.mark.parametrize("bad", [math.nan, math.inf])
def test_non_finite_wheel_commands_raise_and_keep_the_previous_command(bad):
    sim = world()
    sim.command_wheels(1.0, 1.0)
    with pytest.raises(ValueError, match="finite"):
        sim.command_wheels(bad, 1.0)
    assert tuple(sim.motor_cmd) == (42, 42)


# --- exact kinematics and encoders ----------------------------------------------------------------------


def test_straight_drive_moves_r_phi_and_encoders_count_phi_quantised_to_ticks():
    sim = world()
    sim.command_wheels(1.0, 1.0)  # 42 mcu = 1.008 rad/s
    run(sim, 100)  # 1 s
    phi_rad = 42 / MCU_PER_RAD_S * 1.0
    np.testing.assert_allclose(sim.T_world_body.as_array(), [R_WHEEL * phi_rad, 0.0, 0.0], atol=1e-12)
    assert tuple(sim.encoder_ticks) == (round(phi_rad * TICKS_PER_RAD),) * 2
    np.testing.assert_allclose(sim.wheel_angles_rad, phi_rad, atol=0.5 / TICKS_PER_RAD)
    np.testing.assert_allclose(sim.wheel_speed_rad_s, 42 / MCU_PER_RAD_S, rtol=1e-15)
    np.testing.assert_allclose(sim.V_body, [0.0, R_WHEEL * phi_rad, 0.0], atol=1e-12)


def test_constant_wheel_speeds_follow_the_one_exact_arc():
    # 100 steps of a constant twist compose to the single arc exp(100 dt V_b)
    sim = world(start=(0.2, -0.3, 0.4))
    sim.command_wheels(-2.0, 5.0)
    left_rad_s, right_rad_s = sim.commanded_speed_rad_s
    run(sim, 100)
    expected = sim.drive.step(Transform2D(0.2, -0.3, 0.4), left_rad_s * 1.0, right_rad_s * 1.0)
    np.testing.assert_allclose(sim.T_world_body.as_array(), expected.as_array(), atol=1e-12)
    # omega = r (w_r - w_l) / d,  vx = r (w_l + w_r) / 2
    np.testing.assert_allclose(
        sim.V_body,
        [R_WHEEL * (right_rad_s - left_rad_s) / TRACK, R_WHEEL * (left_rad_s + right_rad_s) / 2, 0.0],
        atol=1e-12,
    )


def test_a_stopped_robot_neither_moves_nor_gets_wheel_noise():
    sim = world(noise=NoiseConfig(input_noise=1.0, slip_fraction=0.5))
    run(sim, 200)
    assert sim.T_world_body == Transform2D(0.0, 0.0, 0.0)
    assert tuple(sim.encoder_ticks) == (0, 0)


def test_slip_moves_the_body_while_the_encoders_count_the_commanded_rotation():
    slip = 0.2
    sim = world(noise=NoiseConfig(input_noise=0.0, slip_fraction=slip), arena=(100.0, 100.0))
    sim.command_wheels(2.0, 2.0)
    w_rad_s = sim.commanded_speed_rad_s[0]
    steps = 3000
    ratios = []
    T_previous = sim.T_world_body
    for _ in range(steps):
        sim.step(DT)
        # the wheel increments the body actually made: dphi = H(0) log(T_prev^-1 T)
        omega, vx, vy = (T_previous.inverse() @ sim.T_world_body).log().as_array()
        assert abs(vy) < 1e-12
        dphi = np.array([vx - omega * TRACK / 2, vx + omega * TRACK / 2]) / R_WHEEL
        ratios.append(dphi / (w_rad_s * DT))
        T_previous = sim.T_world_body
    ratios = np.array(ratios)
    np.testing.assert_array_less(ratios, 1.0 + slip + 1e-9)
    np.testing.assert_array_less(1.0 - slip - 1e-9, ratios)
    # U(-s, s): mean 0, variance s^2 / 3; 5-sigma bounds on the sample mean and variance
    np.testing.assert_allclose(ratios.mean(axis=0), 1.0, atol=5 * slip / math.sqrt(3 * steps))
    np.testing.assert_allclose(ratios.var(axis=0), slip**2 / 3, rtol=5 * math.sqrt(0.8 / steps))
    # the encoders saw the commanded rotation only
    np.testing.assert_allclose(sim.wheel_angles_rad, w_rad_s * steps * DT, atol=0.5 / TICKS_PER_RAD)


def test_wheel_speed_noise_has_the_configured_sigma_and_the_encoders_count_it():
    sigma = 0.5
    sim = world(noise=NoiseConfig(input_noise=sigma, slip_fraction=0.0), arena=(100.0, 100.0))
    sim.command_wheels(3.0, -3.0)  # spin in place
    w = sim.commanded_speed_rad_s
    speeds = []
    for _ in range(4000):
        sim.step(DT)
        speeds.append(sim.wheel_speed_rad_s)
    n = np.array(speeds) - w
    np.testing.assert_allclose(n.mean(axis=0), 0.0, atol=5 * sigma / math.sqrt(4000))
    np.testing.assert_allclose(n.std(axis=0), sigma, rtol=5 / math.sqrt(2 * 4000))
    # phi = sum of w'' dt
    np.testing.assert_allclose(
        sim.wheel_angles_rad, np.sum(speeds, axis=0) * DT, atol=0.5 / TICKS_PER_RAD + 1e-9
    )


# --- collisions -----------------------------------------------------------------------------------------


def test_contact_fraction_hand_cases():
    half = arena_walls(4.0, 4.0)
    circle = np.array([[2.0, 0.0, 0.5]])
    origin = np.zeros(2)
    # inflated radius 1: contact at x = 1
    assert contact_fraction(origin, np.array([2.0, 0.0]), circle, half, 0.5) == pytest.approx(0.5, abs=1e-15)
    assert contact_fraction(origin, np.array([0.5, 0.0]), circle, half, 0.5) == 1.0
    # touching and moving away (or along the tangent) is free; moving in is blocked at once
    touching = np.array([1.0, 0.0])
    assert contact_fraction(touching, np.array([-0.3, 0.0]), circle, half, 0.5) == 1.0
    assert contact_fraction(touching, np.array([0.0, 0.3]), circle, half, 0.5) == 1.0
    assert contact_fraction(touching, np.array([0.3, 0.1]), circle, half, 0.5) == 0.0
    # a 60 deg oblique approach: first contact where |p + s d - c| = 1
    d = np.array([4.0, 0.0])
    start = np.array([-1.0, math.sqrt(3) / 2])
    s = contact_fraction(start, d, circle, arena_walls(18.0, 18.0), 0.5)
    assert np.hypot(*(start + s * d - circle[0, :2])) == pytest.approx(1.0, abs=1e-12)
    assert start[0] + s * d[0] == pytest.approx(1.5, abs=1e-12)
    # walls at |x| = 2 - 0.5 for the centre
    no_circles = np.empty((0, 3))
    assert contact_fraction(origin, np.array([3.0, 0.0]), no_circles, half, 0.5) == pytest.approx(0.5)
    assert contact_fraction(origin, np.array([-1.0, -6.0]), no_circles, half, 0.5) == pytest.approx(0.25)


def test_driving_into_a_cylinder_stops_at_contact_and_the_wheels_keep_turning():
    sim = world(obstacles=((1.0,), (0.0,), (0.05,)))
    sim.command_wheels(6.0, 6.0)  # 0.198 m/s
    poses = run(sim, 800)
    distance_m = np.array([np.hypot(T.x - 1.0, T.y) for T in poses])
    assert distance_m.min() >= R_ROBOT + 0.05 - 1e-12
    np.testing.assert_allclose(distance_m[-1], R_ROBOT + 0.05, atol=1e-12)
    np.testing.assert_allclose(sim.V_body, 0.0, atol=1e-12)
    # the wheels turned 8 s at 6 rad/s although the body moved only 0.84 m
    np.testing.assert_allclose(sim.wheel_angles_rad, 250 / MCU_PER_RAD_S * 8.0, atol=1e-3)
    # backing off is free again
    sim.command_wheels(-6.0, -6.0)
    run(sim, 10)
    assert sim.T_world_body.x < 1.0 - R_ROBOT - 0.05 - 0.01


def test_contact_with_a_slanted_wall_and_a_corner_pointing_in():
    """Hand cases on the walls of NOTCHED (R = 0.5): its slanted edge (1.5, 1.5) -> (0, 1) is the line
    x - 3 y + 3 = 0, normal (1, -3) / sqrt(10); its corner (0, 1) points into the arena."""
    walls = polygon_walls(NOTCHED)
    no_circles = np.empty((0, 3))
    # from (0.9, 0) straight up: the centre meets the line offset by 0.5 where (0.9 - 3 y + 3) / sqrt(10)
    # = 0.5, i.e. y = (3.9 - 0.5 sqrt(10)) / 3 = 0.773; its foot lies within the edge
    s = contact_fraction(np.array([0.9, 0.0]), np.array([0.0, 1.0]), no_circles, walls, 0.5)
    assert s == pytest.approx((3.9 - 0.5 * math.sqrt(10.0)) / 3.0, abs=1e-12)
    # from (0, 0) straight up: the corner (0, 1) is met first, at y = 0.5 (both edges slope away from it)
    s = contact_fraction(np.zeros(2), np.array([0.0, 1.0]), no_circles, walls, 0.5)
    assert s == pytest.approx(0.5, abs=1e-12)
    # touching the corner and moving away is free
    assert contact_fraction(np.array([0.0, 0.5]), np.array([0.0, -0.3]), no_circles, walls, 0.5) == 1.0
    assert first_collision(np.array([0.0, 0.51]), no_circles, walls, 0.5).startswith(
        "is not inside the arena"
    )
    assert first_collision(np.array([0.0, 1.2]), no_circles, walls, 0.1) == (
        "is not inside the arena (outside its walls)"
    )
    assert first_collision(np.array([1.0, 1.2]), no_circles, walls, 0.1) is None


def test_a_scan_in_a_hexagonal_arena_sees_its_walls():
    """turtlebot3_world's hexagon (flat sides at y = +-2.54, corners at (+-2.933, 0)), no cylinders, the
    sensor at the origin facing +x (the robot at x = 0.032): along +-y the flat sides, along +x the corner."""
    hexagon = ((2.933, 0.0), (1.466, 2.54), (-1.466, 2.54), (-2.933, 0.0), (-1.466, -2.54), (1.466, -2.54))
    sim = world(
        start=(-LIDAR_X, 0.0, 0.0),
        walls=Walls(*zip(*hexagon, strict=True)),
        lidar=replace(EXACT_LIDAR, range_max=3.5),
    )
    ranges = sim.scan().range_m
    assert ranges[90] == pytest.approx(2.54, abs=1e-12)
    assert ranges[270] == pytest.approx(2.54, abs=1e-12)
    assert ranges[0] == pytest.approx(2.933, abs=1e-12)


def test_driving_obliquely_into_a_wall_stops_at_the_wall():
    sim = world(arena=(4.0, 2.0), start=(0.0, 0.0, math.pi / 4))
    sim.command_wheels(6.0, 6.0)
    run(sim, 1000)
    # the first wall hit is y = 1: the centre stops R short of it, on the 45 deg line
    np.testing.assert_allclose(
        sim.T_world_body.as_array(), [1.0 - R_ROBOT, 1.0 - R_ROBOT, math.pi / 4], atol=1e-12
    )


def test_default_world_circles_are_collision_free_and_always_see_landmarks():
    config = SimulationConfig()
    circles = config.obstacles.circles()
    for radius_m in (0.5, 0.75, 1.0):
        for side in (1.0, -1.0):
            for angle in np.linspace(0.0, 2.0 * math.pi, 90):
                # a circle through the origin, centre (0, side * radius)
                p = np.array([radius_m * math.sin(angle), side * radius_m * (1.0 - math.cos(angle))])
                assert first_collision(p, circles, config.wall_segments, R_ROBOT) is None
                in_range = np.hypot(*(circles[:, :2] - p).T) <= config.noise.max_range
                assert in_range.sum() >= 3


crowded = (
    (0.0, 0.5, -0.6, 0.7, -0.3, 0.3),
    (0.5, 0.0, 0.2, -0.6, -0.5, 0.9),
    (0.05, 0.01, 0.1, 0.038, 0.2, 0.05),
)
# a 3 m square whose top side is pushed in to a corner at (0, 1) (a reflex corner)
NOTCHED = ((-1.5, -1.5), (1.5, -1.5), (1.5, 1.5), (0.0, 1.0), (-1.5, 1.5))
NOTCHED_WALLS = Walls(*zip(*NOTCHED, strict=True))


@settings(max_examples=40, deadline=None)
@given(
    start=st.tuples(st.floats(-1.2, 1.2), st.floats(-1.2, 1.2), st.floats(-math.pi, math.pi)),
    commands=st.lists(st.tuples(st.floats(-7.0, 7.0), st.floats(-7.0, 7.0)), min_size=1, max_size=6),
    dt_s=st.sampled_from([0.01, 0.2, 2.0]),
    seed=st.integers(0, 2**32),
)
def test_the_robot_never_overlaps_or_passes_through_anything(start, commands, dt_s, seed):
    """Among crowded cylinders in an arena whose walls are a polygon with a corner pointing in (NOTCHED):
    every pose is free and no straight move between poses crosses a cylinder or a wall."""
    circles = np.array(crowded).T
    walls = polygon_walls(NOTCHED)
    if first_collision(np.array(start[:2]), circles, walls, R_ROBOT) is not None:
        return
    sim = world(
        obstacles=crowded,
        start=start,
        noise=NoiseConfig(input_noise=0.5, slip_fraction=0.3, seed=seed),
        walls=NOTCHED_WALLS,
    )
    p_previous = sim.T_world_body.translation
    for left, right in commands:
        sim.command_wheels(left, right)
        for T in run(sim, 15, dt_s):
            p = T.translation
            assert first_collision(p, circles, walls, R_ROBOT - 1e-9) is None
            # nor does the straight move cross an (inflated) cylinder: the closest chord point is clear
            d = p - p_previous
            s = np.clip(((circles[:, :2] - p_previous) @ d) / max(d @ d, 1e-300), 0.0, 1.0)
            closest = p_previous + s[:, None] * d
            assert np.all(np.hypot(*(closest - circles[:, :2]).T) >= R_ROBOT + circles[:, 2] - 1e-9)
            # or a wall (the chord sampled every 1/50 of its length)
            for f in np.linspace(0.0, 1.0, 51):
                assert wall_distances(p_previous + f * d, walls).min() >= R_ROBOT - 1e-9
            p_previous = p


@settings(max_examples=40, deadline=None)
@given(
    start=st.tuples(st.floats(-1.4, 1.4), st.floats(-1.4, 1.4)),
    moves=st.lists(
        st.tuples(st.floats(-0.3, 0.3), st.floats(-0.3, 0.3), st.booleans()), min_size=1, max_size=30
    ),
)
def test_the_free_ball_gives_the_contact_fraction_of_every_move(start, moves):
    """FreeBall answers as contact_fraction, move after move (short and long, some jumping elsewhere as a
    teleport does), among crowded cylinders and the walls of NOTCHED; and clearance_m is the distance to the
    nearest inflated obstacle."""
    circles, walls = np.array(crowded).T, polygon_walls(NOTCHED)
    ball = FreeBall(circles, walls, R_ROBOT)
    p = np.array(start)
    for dx, dy, jump in moves:
        d = np.array([dx, dy]) * (0.01 if not jump else 1.0)
        assert ball.contact_fraction(p, d) == contact_fraction(p, d, circles, walls, R_ROBOT)
        p = p + (d if jump else d * contact_fraction(p, d, circles, walls, R_ROBOT))
    nearest = min(np.min(np.hypot(*(p - circles[:, :2]).T) - circles[:, 2]), wall_distances(p, walls).min())
    assert clearance_m(p, circles, walls, R_ROBOT) == pytest.approx(nearest - R_ROBOT, abs=1e-12)
    assert clearance_m(p, np.empty((0, 3)), np.empty((0, 4)), R_ROBOT) == math.inf


# --- sensors --------------------------------------------------------------------------------------------


def test_scan_is_cast_from_the_robot_s_lidar_mount():
    """Another robot's mount (lidar_x, lidar_y, lidar_yaw in its description) moves the scan with it."""
    config = SimulationConfig(
        arena=ArenaConfig(0.0, 0.0, 0.0, 4.0, 3.0),
        obstacles=Obstacles((1.0,), (0.0,), (0.05,)),
        robot=RobotParams(lidar_x=0.1, lidar_y=0.2, lidar_yaw=math.pi / 2),
        noise=QUIET,
        lidar=EXACT_LIDAR,
    )
    ranges = Simulation(config).scan().range_m
    # the sensor at (0.1, 0.2) facing +y: beam 0 hits the wall y = 1.5, beam 90 (towards -x) the wall
    # x = -2, beam 270 (towards +x) passes 0.2 m beside the cylinder of radius 0.05 and hits x = 2
    assert ranges[0] == pytest.approx(1.5 - 0.2, abs=1e-12)
    assert ranges[90] == pytest.approx(2.0 + 0.1, abs=1e-12)
    assert ranges[270] == pytest.approx(2.0 - 0.1, abs=1e-12)
    assert ranges[180] == pytest.approx(1.5 + 0.2, abs=1e-12)


def test_scan_at_a_known_pose_matches_the_arena():
    # arena 4 m x 3 m, a cylinder of radius 0.05 m at (1, 0); robot at the origin facing +x
    sim = world(obstacles=((1.0,), (0.0,), (0.05,)))
    ranges = sim.scan().range_m
    assert ranges.shape == (360,)
    assert ranges[0] == pytest.approx(1.0 - 0.05 - LIDAR_X, abs=1e-12)  # cylinder dead ahead
    assert ranges[180] == pytest.approx(2.0 + LIDAR_X, abs=1e-12)  # back wall at x = -2
    assert ranges[90] == pytest.approx(1.5, abs=1e-12)  # left wall at y = 1.5
    assert ranges[270] == pytest.approx(1.5, abs=1e-12)
    # at (1, -1) facing +y: the sensor at (1, -1.032), the cylinder dead ahead, walls x = +-2, y = -1.5
    sim.teleport(Transform2D(1.0, -1.0, math.pi / 2))
    ranges = sim.scan().range_m
    assert ranges[0] == pytest.approx(1.0 - LIDAR_X - 0.05, abs=1e-12)
    assert ranges[90] == pytest.approx(3.0, abs=1e-12)
    assert ranges[180] == pytest.approx(1.5 - (1.0 - LIDAR_X), abs=1e-12)
    assert ranges[270] == pytest.approx(1.0, abs=1e-12)
    # beyond range_max 3.5 m nothing returns: corners of a large arena
    far = world(arena=(8.0, 8.0))
    assert far.scan().range_m[45] == 0.0


def test_scan_noise_and_resolution_quantise_ranges():
    sim = world(obstacles=((1.0,), (0.0,), (0.05,)), lidar=LidarConfig(noise=0.01, resolution=0.01))
    beams = np.array([sim.scan().range_m[0] for _ in range(400)])
    np.testing.assert_allclose(beams / 0.01, np.round(beams / 0.01), atol=1e-9)
    assert beams.mean() == pytest.approx(0.982, abs=5 * 0.011 / math.sqrt(400))


def test_the_default_lidar_model_is_todays_lds01_and_an_unknown_one_names_the_choices():
    assert LidarChoice().model.sensor == default_lidar()
    with pytest.raises(ValueError, match=r"lidar_model must be one of \('lds01', 'lds02', 'gazebo'\)"):
        LidarChoice("lds03")


@pytest.mark.parametrize(
    ("lidar_model", "samples", "no_return", "reach_m"),
    [
        ("lds01", {360}, 0.0, 3.5),
        ("lds02", set(range(374, 392)), math.nan, 8.0),
        ("gazebo", {360}, math.inf, 3.5),
    ],
)
def test_each_lidar_model_reads_its_no_return_value_beyond_its_reach(
    lidar_model, samples, no_return, reach_m
):
    # from the centre of an arena 20 m long the end walls are out of reach; a cylinder 1.5 m ahead is in
    # reach, and so are the side walls 3.3 m away (every LiDAR) or 7.9 m away (the LDS-02 only)
    lidar = replace(LIDAR_MODELS[lidar_model].sensor, noise=0.0)
    for y_m in (3.3, 7.9):
        sim = world(obstacles=((1.5,), (0.0,), (0.15,)), arena=(20.0, 2.0 * y_m), lidar=lidar)
        scan = sim.scan()
        assert scan.layout.samples in samples and scan.range_m.shape == (scan.layout.samples,)
        bearing = scan.layout.angle_min + scan.layout.angle_increment * np.arange(scan.layout.samples)
        ahead = np.argmin(np.abs(np.remainder(bearing + math.pi, 2 * math.pi) - math.pi))
        left = np.argmin(np.abs(bearing - math.pi / 2))
        behind = np.argmin(np.abs(bearing - math.pi))
        assert scan.range_m[ahead] == pytest.approx(1.5 - 0.15 - LIDAR_X, abs=lidar.resolution + 1e-3)
        np.testing.assert_array_equal(scan.range_m[behind], no_return)
        if y_m < reach_m:
            assert scan.range_m[left] == pytest.approx(y_m, abs=0.01)
        else:
            np.testing.assert_array_equal(scan.range_m[left], no_return)


def test_fake_sensor_reports_only_landmarks_in_range_with_their_ids():
    obstacles = ((0.5, 0.0, -3.0, 2.0), (0.0, 1.5, 0.0, 0.0), (0.05, 0.05, 0.05, 0.05))
    sim = world(obstacles=obstacles, arena=(8.0, 8.0), start=(0.0, 0.0, math.pi / 2))
    readings = sim.sense_landmarks()
    # obstacle 3 sits exactly at max_range = 2 m: in range
    assert readings.ids.tolist() == [0, 1, 3]
    # in the body frame (facing +y): (0.5, 0) is to the right, (0, 1.5) ahead
    np.testing.assert_allclose(readings.p_body, [[0.0, -0.5], [1.5, 0.0], [0.0, -2.0]], atol=5 * 0.01)


def test_fake_sensor_noise_has_the_configured_variance():
    variance = 4e-4
    sim = world(
        obstacles=((0.5,), (0.3,), (0.05,)),
        noise=replace(QUIET, basic_sensor_variance=variance),
        start=(0.0, 0.0, 1.0),
    )
    p_true = Transform2D(0.0, 0.0, 1.0).inverse() @ np.array([0.5, 0.3])
    e = np.array([sim.sense_landmarks().p_body[0] for _ in range(4000)]) - p_true
    np.testing.assert_allclose(e.mean(axis=0), 0.0, atol=5 * math.sqrt(variance / 4000))
    np.testing.assert_allclose(e.var(axis=0), variance, rtol=5 * math.sqrt(2 / 4000))
    assert abs(np.corrcoef(e.T)[0, 1]) < 5 / math.sqrt(4000)


# --- seeding, teleport, reset ---------------------------------------------------------------------------


def trace(seed: int) -> tuple[np.ndarray, ...]:
    sim = Simulation(SimulationConfig(noise=NoiseConfig(input_noise=0.2, slip_fraction=0.1, seed=seed)))
    poses, ticks, scans, landmarks = [], [], [], []
    for left, right in [(3.0, 4.0), (5.0, 5.0), (-2.0, 2.0)] * 3:
        sim.command_wheels(left, right)
        poses += [T.as_array() for T in run(sim, 50)]
        ticks.append(sim.encoder_ticks)
        scans.append(sim.scan().range_m)
        landmarks.append(sim.sense_landmarks().p_body)
    return np.array(poses), np.array(ticks), np.array(scans), np.concatenate(landmarks)


def test_the_same_seed_reproduces_the_run_and_another_seed_does_not():
    first, again, other = trace(7), trace(7), trace(8)
    for a, b in zip(first, again, strict=True):
        np.testing.assert_array_equal(a, b)
    for a, c in zip(first, other, strict=True):
        assert not np.array_equal(a, c)


def test_teleport_refuses_poses_in_collision_and_reset_returns_to_the_start():
    sim = world(obstacles=((1.0,), (0.0,), (0.05,)), start=(-0.5, 0.2, 0.3))
    with pytest.raises(ValueError, match="overlaps obstacle 0"):
        sim.teleport(Transform2D(0.9, 0.1, 0.0))
    with pytest.raises(ValueError, match="not inside the arena"):
        sim.teleport(Transform2D(1.95, 0.0, 0.0))
    assert sim.T_world_body == Transform2D(-0.5, 0.2, 0.3)
    sim.teleport(Transform2D(0.0, -1.0, 2.0))
    assert sim.T_world_body == Transform2D(0.0, -1.0, 2.0)
    sim.command_wheels(3.0, 2.0)
    run(sim, 50)
    ticks = sim.encoder_ticks
    sim.reset()
    assert sim.T_world_body == Transform2D(-0.5, 0.2, 0.3)
    assert tuple(sim.motor_cmd) == (0, 0)
    np.testing.assert_array_equal(sim.encoder_ticks, ticks)


# --- validation -----------------------------------------------------------------------------------------


@pytest.mark.parametrize(
    ("build", "message"),
    [
        (lambda: ArenaConfig(arena_x_length=-1.0), "arena_x_length must be finite and > 0"),
        (lambda: ArenaConfig(arena_y_length=0.0), "arena_y_length must be finite and > 0"),
        (lambda: ArenaConfig(x0=math.nan), "x0 must be a finite number"),
        (lambda: Obstacles((1.0, 2.0), (0.0,), (0.1, 0.1)), "same length, got 2, 1 and 2"),
        (lambda: Obstacles((1.0,), (0.0,), (0.0,)), r"obstacles.r\[0\] must be finite and > 0"),
        (lambda: Obstacles((math.inf,), (0.0,), (0.1,)), r"obstacles.x\[0\] must be a finite number"),
        (lambda: Obstacles("abc", (0.0,), (0.1,)), "obstacles.x must be a list of numbers"),
        (lambda: NoiseConfig(input_noise=-0.1), "input_noise must be finite and >= 0"),
        (lambda: NoiseConfig(slip_fraction=1.0), r"slip_fraction must be in \[0.0, 1.0\)"),
        (lambda: NoiseConfig(basic_sensor_variance=-1e-4), "basic_sensor_variance must be finite and >= 0"),
        (lambda: NoiseConfig(max_range=0.0), "max_range must be finite and > 0"),
        (lambda: NoiseConfig(seed=-1), "seed must be >= 0"),
        (lambda: NoiseConfig(seed=1.5), "seed must be an integer"),
        (
            lambda: SimulationConfig(obstacles=Obstacles((0.05,), (0.0,), (0.038,))),
            r"start \(x0, y0\) = \(0.0, 0.0\) m with collision_radius 0.11 m overlaps obstacle 0",
        ),
        (
            lambda: SimulationConfig(arena=ArenaConfig(x0=2.45)),
            "is not inside the arena",
        ),
        (
            lambda: SimulationConfig(arena=ArenaConfig(arena_x_length=0.2)),
            "does not fit inside the 0.2 m x 5.0 m arena",
        ),
        (
            lambda: SimulationConfig(obstacles=Obstacles((2.48,), (0.0,), (0.038,))),
            "obstacle 0 at .* does not fit inside the 5.0 m x 5.0 m arena",
        ),
        (lambda: Walls((0.0, 1.0, 1.0), (0.0, 0.0)), "walls.x and walls.y must have the same length"),
        (lambda: Walls((0.0, 1.0, 0.0, 1.0), (0.0, 1.0, 1.0, 0.0)), "edges 0 and 2 cross"),
        (lambda: Walls((0.0, math.nan, 0.0), (0.0, 0.0, 1.0)), r"walls.x\[1\] must be a finite number"),
        (
            lambda: SimulationConfig(
                walls=NOTCHED_WALLS, arena=ArenaConfig(y0=1.2), obstacles=Obstacles((), (), ())
            ),
            r"start .* is not inside the arena \(outside its walls\)",
        ),
        (
            lambda: SimulationConfig(walls=NOTCHED_WALLS, obstacles=Obstacles((0.0,), (0.98,), (0.038,))),
            "obstacle 0 at .* does not fit inside the arena's 5-corner polygon of walls",
        ),
        (lambda: Robots(("tb3_0", "1b")), r"robots.names\[1\] must be a namespace token"),
        (lambda: Robots(("a/b",)), r"robots.names\[0\] must be a namespace token"),
        (lambda: Robots("tb3_0"), "robots.names must be a list of names"),
        (lambda: Robots(("a", "a"), (0.0, 1.0), (0.0, 0.0), (0.0, 0.0)), "robots.names must be distinct"),
        (lambda: Robots(("a", "b"), (0.0,), (0.0,), (0.0,)), "need one value per name \\(2\\), got 1"),
        (lambda: Robots(("a",), (0.0,), (0.0, 1.0), (0.0,)), "must have the same length, got 1, 2, 1"),
        (lambda: Robots(("a",), (math.nan,), (0.0,), (0.0,)), r"robots.x0\[0\] must be a finite number"),
        (
            lambda: SimulationConfig(robots=Robots(("a", "b"), (0.0, 0.2), (0.0, 0.0), (0.0, 0.0))),
            r"robot b's start \(0.2, 0.0\) m with collision_radius 0.11 m overlaps robot a's start",
        ),
        (
            lambda: SimulationConfig(robots=Robots(("a", "b"), (0.0, 1.4), (0.0, 0.3), (0.0, 0.0))),
            "robot b's start .* overlaps obstacle 0",
        ),
    ],
)
def test_invalid_configurations_raise_with_their_reason(build, message):
    with pytest.raises(ValueError, match=message):
        build()


def test_step_rejects_a_non_positive_time_step():
    with pytest.raises(ValueError, match="dt_s must be finite and > 0"):
        world().step(0.0)


# --- several robots -------------------------------------------------------------------------------------


def fleet(x0, y0, theta0, noise=QUIET, obstacles=((), (), ()), arena=(4.0, 3.0)) -> MultiRobotSimulation:
    names = tuple(f"tb3_{k}" for k in range(len(x0)))
    return MultiRobotSimulation(
        SimulationConfig(
            arena=ArenaConfig(0.0, 0.0, 0.0, *arena),
            obstacles=Obstacles(*obstacles),
            robot=RobotParams(),
            noise=noise,
            lidar=EXACT_LIDAR,
            robots=Robots(names, x0, y0, theta0),
        )
    )


def test_each_robot_s_lidar_sees_the_other_robot_as_a_disc_of_its_collision_radius():
    # tb3_0 at the origin facing +x, tb3_1 at (1, 0.5) facing -y; arena 4 m x 3 m, no cylinder
    robots = fleet((0.0, 1.0), (0.0, 0.5), (0.0, -math.pi / 2))
    ranges = robots.scan(0).range_m
    # tb3_0's sensor at (-0.032, 0): the beam towards (1, 0.5) (bearing atan2(0.5, 1.032) = 25.85 deg:
    # beam 26 at 26 deg) meets the disc of radius 0.11 m around it; the beam at 0 deg passes 0.5 m beside
    # it and hits the wall x = 2
    assert ranges[0] == pytest.approx(2.0 - LIDAR_X, abs=1e-12)
    # beam 26: from s = (-0.032, 0) along u = (cos 26, sin 26), |s + t u - c| = R: t = u.(c - s) - sqrt(...)
    u = np.array([math.cos(math.radians(26)), math.sin(math.radians(26))])
    m = np.array([1.0 + 0.032, 0.5])
    t = u @ m - math.sqrt((u @ m) ** 2 - m @ m + R_ROBOT**2)
    assert ranges[26] == pytest.approx(t, abs=1e-12)
    # tb3_1's sensor at (1, 0.532) facing -y: beam 0 towards -y hits the wall y = -1.5; beam 270 (+x)
    # the wall x = 2; the beam towards tb3_0 (bearing atan2(-0.532, -1) - (-pi/2) = -62 deg: beam 298)
    # meets tb3_0's disc, and the landmarks never include a robot
    ranges_1 = robots.scan(1).range_m
    assert ranges_1[0] == pytest.approx(1.5 + 0.532, abs=1e-12)
    assert ranges_1[90] == pytest.approx(1.0, abs=1e-12)
    bearing = -math.pi / 2 + math.radians(298 - 360)
    u = np.array([math.cos(bearing), math.sin(bearing)])
    m = np.array([0.0, 0.0]) - np.array([1.0, 0.5 + 0.032])
    t = u @ m - math.sqrt((u @ m) ** 2 - m @ m + R_ROBOT**2)
    assert ranges_1[298] == pytest.approx(t, abs=1e-12)
    assert robots.robots[1].sense_landmarks().ids.size == 0


def test_two_robots_driving_at_each_other_stop_at_contact_and_their_wheels_keep_turning():
    robots = fleet((-0.5, 0.5), (0.0, 0.0), (0.0, math.pi))
    for robot in robots.robots:
        robot.command_wheels(5.0, 5.0)
    for _ in range(300):
        robots.step(DT)
    p0, p1 = (robot.T_world_body.translation for robot in robots.robots)
    # touching: |p0 - p1| = 2 R (the first to move reached contact, the second found none left)
    assert np.hypot(*(p1 - p0)) == pytest.approx(2 * R_ROBOT, abs=1e-9)
    assert all(robot.encoder_ticks[0] > 4096 for robot in robots.robots), "the wheels kept turning"


@settings(max_examples=30, deadline=None)
@given(
    starts=st.lists(
        st.tuples(st.floats(-1.2, 1.2), st.floats(-1.0, 1.0), st.floats(-math.pi, math.pi)),
        min_size=2,
        max_size=3,
    ),
    commands=st.lists(
        st.lists(st.tuples(st.floats(-7.0, 7.0), st.floats(-7.0, 7.0)), min_size=3, max_size=3),
        min_size=1,
        max_size=5,
    ),
    seed=st.integers(0, 2**32),
)
def test_robots_never_overlap_or_pass_through_each_other(starts, commands, seed):
    """Each step's straight moves: at every step every pair of robots is at least 2 R apart, and no robot's
    chord crosses another's disc where that one stood when it moved."""
    xy = np.array([start[:2] for start in starts])
    gaps = np.hypot(*(xy[:, None] - xy[None]).transpose(2, 0, 1))
    if np.any(gaps[np.triu_indices(len(starts), 1)] < 2 * R_ROBOT):
        return
    x0, y0, theta0 = zip(*starts, strict=True)
    robots = fleet(x0, y0, theta0, noise=NoiseConfig(input_noise=0.5, slip_fraction=0.3, seed=seed))
    for wheels in commands:
        for robot, (left, right) in zip(robots.robots, wheels, strict=False):
            robot.command_wheels(left, right)
        for _ in range(15):
            before = [robot.T_world_body.translation for robot in robots.robots]
            robots.step(0.05)
            after = [robot.T_world_body.translation for robot in robots.robots]
            for k, (p, q) in enumerate(zip(before, after, strict=True)):
                # robot k moved after the robots before it: they stood at their new places
                others = [after[j] for j in range(k)] + [before[j] for j in range(k + 1, len(before))]
                d = q - p
                for c in others:
                    s = np.clip(((c - p) @ d) / max(d @ d, 1e-300), 0.0, 1.0)
                    assert np.hypot(*(p + s * d - c)) >= 2 * R_ROBOT - 1e-9


def test_one_named_robot_is_the_one_robot_and_each_robot_has_its_own_noise():
    noise = NoiseConfig(input_noise=0.2, slip_fraction=0.1, seed=3)
    one = Simulation(SimulationConfig(arena=ArenaConfig(0.3, -0.2, 1.0), noise=noise))
    named = MultiRobotSimulation(
        SimulationConfig(noise=noise, robots=Robots(("tb3_0",), (0.3,), (-0.2,), (1.0,)))
    ).robots[0]
    pair = fleet((-1.0, 1.0), (0.0, 0.0), (0.0, 0.0), noise=noise, arena=(5.0, 5.0)).robots
    for sim in (one, named, *pair):
        sim.command_wheels(3.0, 4.0)
        run(sim, 50)
    assert named.T_world_body == one.T_world_body
    np.testing.assert_array_equal(named.scan().range_m, one.scan().range_m)
    # the same commands, other noise: robot 1's streams are not robot 0's
    assert not np.array_equal(pair[0].wheel_speed_rad_s, pair[1].wheel_speed_rad_s)
    assert [s.spawn_key for s in robot_streams(3, 0)] == [s.spawn_key for s in seed_streams(3)[:4]]
    keys = {s.spawn_key for k in range(4) for s in robot_streams(3, k)} | {seed_streams(3)[4].spawn_key}
    assert len(keys) == 17, "every robot's four streams and the placement are distinct"


def test_teleport_refuses_a_pose_on_another_robot_and_reset_brings_every_robot_back():
    robots = fleet((-0.5, 0.5), (0.0, 0.0), (0.0, 0.0))
    with pytest.raises(ValueError, match=r"overlaps another robot at \(0.500, 0.000\) m"):
        robots.teleport(0, Transform2D(0.3, 0.0, 0.0))
    robots.teleport(0, Transform2D(-0.5, 1.0, 0.0))
    robots.robots[1].command_wheels(3.0, 3.0)
    run(robots.robots[1], 30)
    robots.reset()
    assert [r.T_world_body for r in robots.robots] == [
        Transform2D(-0.5, 0.0, 0.0),
        Transform2D(0.5, 0.0, 0.0),
    ]
