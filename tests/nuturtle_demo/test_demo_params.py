"""nuturtle_tools.params: parameter files in and out, and SLAM's wheel noise and the registration's point
noise matched to nusim's slip and LiDAR by Monte Carlo on the simulator's own models."""

import math

import numpy as np
import pytest
import rclpy
from rclpy.context import Context
from rclpy.node import Node

from nusim.simulation import NoiseConfig, Simulation, SimulationConfig
from nuturtle_demo.matched_noise import matched_point_std, matched_wheel_noise
from nuturtle_demo.run import default_world
from nuturtle_description.robot_params import burger_params
from nuturtle_ros_common.ros_files import load_ros_parameters
from nuturtle_tools.params import params_file, to_parameters
from turtlelib import Transform2D
from turtlelib.sensing.scan_model import LidarConfig, arena_walls, cast_beams, simulate_scan


def test_demo_world_loads_flat():
    world = load_ros_parameters(default_world())
    assert world["obstacles.x"][0] == 1.4 and len(world["obstacles.r"]) == 8
    assert world["lidar.samples"] == 360 and world["slip_fraction"] > 0.0


def test_to_parameters_makes_number_lists_uniform():
    values = {p.name: p.value for p in to_parameters({"a": [1, 0.5], "b": [1, 2], "c": "x", "d": 0.1})}
    assert values == {"a": [1.0, 0.5], "b": [1, 2], "c": "x", "d": 0.1}
    assert all(isinstance(v, float) for v in values["a"])


def test_params_file_is_a_valid_ros_params_file(tmp_path):
    """Dump a node's parameters, then start a node from the file with --params-file: same values."""
    context = Context()
    rclpy.init(context=context)
    try:
        node = Node("nusim", context=context, parameter_overrides=to_parameters(
            {"obstacles.x": [1.0, -2.5], "rate": 100.0, "seed": 3, "lidar.samples": 360, "wheel_left": "w"}
        ), automatically_declare_parameters_from_overrides=True)  # fmt: skip
        path = tmp_path / "config.yaml"
        path.write_text(params_file([node]))
        node.destroy_node()
    finally:
        rclpy.try_shutdown(context=context)
    context = Context()
    rclpy.init(context=context, args=["--ros-args", "--params-file", str(path)])
    try:
        node = Node("nusim", context=context, automatically_declare_parameters_from_overrides=True)
        assert list(node.get_parameter("obstacles.x").value) == [1.0, -2.5]
        assert node.get_parameter("seed").value == 3 and node.get_parameter("lidar.samples").value == 360
        assert node.get_parameter("wheel_left").value == "w" and node.get_parameter("rate").value == 100.0
        node.destroy_node()
    finally:
        rclpy.try_shutdown(context=context)


def test_matched_wheel_noise_hand_computed():
    # 0.3 sqrt(4.5 / 100 / 3)
    assert matched_wheel_noise(0.3, 4.5, 100.0) == pytest.approx(0.3 * math.sqrt(0.015), rel=1e-12)
    assert matched_wheel_noise(0.0, 4.5, 100.0) == 0.0
    with pytest.raises(ValueError):
        matched_wheel_noise(0.3, 4.5, 0.0)


def test_matched_point_std_hand_computed_and_monte_carlo_on_the_lidar_model():
    # sqrt(0.01^2 + 0.01^2 / 12)
    assert matched_point_std(0.01, 0.01) == pytest.approx(math.sqrt(1.0e-4 + 1.0e-4 / 12.0), rel=1e-12)
    assert matched_point_std(0.0, 0.01) == pytest.approx(0.01 / math.sqrt(12.0), rel=1e-12)
    with pytest.raises(ValueError):
        matched_point_std(0.0, 0.0)
    # nusim's range model: a wall 1.2345 m ahead of every beam of a 360-beam scan, 200 scans
    config = LidarConfig(noise=0.01, resolution=0.01, range_max=3.5)
    walls = arena_walls(2.469, 2.469)
    rng = np.random.default_rng(7)
    errors = []
    for _ in range(200):
        range_m = simulate_scan(Transform2D(), np.empty((0, 3)), walls, config, rng)
        true_m, _ = cast_beams(Transform2D(), config.angles(), np.empty((0, 3)), walls)
        errors.append(range_m - true_m)
    # 72,000 samples: the std's relative standard error is about 1 / sqrt(2 n) = 0.3 %
    assert np.std(np.concatenate(errors)) == pytest.approx(matched_point_std(0.01, 0.01), rel=0.02)


def test_matched_wheel_noise_monte_carlo_on_nusim():
    """Straight driving: the heading nusim's slip adds over a wheel travel |dphi| has variance
    (r / d)^2 2 wheel_noise^2 |dphi| (the two wheels slip independently)."""
    robot = burger_params()
    w_rad_s, rate_hz, steps, runs, slip = 4.0, 100.0, 100, 400, 0.3
    errors = []
    for seed in range(runs):
        simulation = Simulation(
            SimulationConfig(noise=NoiseConfig(input_noise=0.0, slip_fraction=slip, seed=seed))
        )
        simulation.command_wheels(w_rad_s, w_rad_s)
        for _ in range(steps):
            simulation.step(1.0 / rate_hz)
        phi_left, phi_right = simulation.wheel_angles_rad
        theta_odom = robot.wheel_radius / robot.track_width * (phi_right - phi_left)
        errors.append(simulation.T_world_body.theta - theta_odom)
    dphi = abs(simulation.commanded_speed_rad_s[0]) * steps / rate_hz
    wheel_noise = matched_wheel_noise(slip, abs(simulation.commanded_speed_rad_s[0]), rate_hz)
    predicted = (robot.wheel_radius / robot.track_width) ** 2 * 2 * wheel_noise**2 * dphi
    # the sample variance of 400 draws is within 4 standard errors, sqrt(2 / 400) relative
    assert np.var(errors) == pytest.approx(predicted, rel=4 * math.sqrt(2 / runs))
