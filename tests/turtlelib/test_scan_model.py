"""turtlelib.sensing.scan_model: LidarConfig and its per-scan layouts, ray casting against circles and
segments, simulated scans of the TurtleBot3 LiDARs (LDS-01, LDS-02, Gazebo).

References: hand-computed ranges, the geometric definition of a hit (the hit point lies on the object and
nothing is hit earlier, checked by sampling the ray), and invariance under moving sensor and world
together. Noise and quantisation are checked by Monte Carlo with seeded generators.
"""

import dataclasses
import math

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from turtlelib import LidarConfig, Transform2D, arena_walls, cast_beams, polygon_walls, simulate_scan

PI = math.pi
NO_SEGMENTS = np.empty((0, 4))
NO_CIRCLES = np.empty((0, 3))
NON_FINITE = [math.nan, math.inf, -math.inf]

coords_m = st.floats(-5.0, 5.0, allow_nan=False)
headings_rad = st.floats(-PI, PI, allow_nan=False)
poses = st.builds(Transform2D, coords_m, coords_m, headings_rad)


# --- LidarConfig --------------------------------------------------------------------------------------


def test_lidar_config_defaults_are_the_lds01():
    config = LidarConfig()
    assert (config.range_min, config.range_max, config.samples) == (0.12, 3.5, 360)
    assert config.angle_min == 0.0
    assert config.angle_increment == pytest.approx(math.radians(1.0), abs=1e-15)
    assert (config.noise, config.resolution) == (0.0, 0.0)
    with pytest.raises(dataclasses.FrozenInstanceError):
        config.samples = 10


def test_lidar_config_angles():
    config = LidarConfig(angle_min=-0.5, angle_increment=0.25, samples=5)
    np.testing.assert_allclose(config.angles(), [-0.5, -0.25, 0.0, 0.25, 0.5], rtol=0.0, atol=1e-15)
    assert LidarConfig().angles().shape == (360,)


def test_lidar_config_accepts_gazebos_layout_whose_last_beam_repeats_the_first():
    gazebo = LidarConfig(angle_increment=6.28 / 359, samples=360, no_return=math.inf)
    assert gazebo.angles()[-1] == pytest.approx(6.28, abs=1e-12)
    assert math.isinf(gazebo.no_return)
    assert math.isnan(LidarConfig(no_return=math.nan).no_return)


def test_lidar_config_accepts_ints_for_floats():
    config = LidarConfig(range_min=0, range_max=4)
    assert isinstance(config.range_max, float) and config.range_max == 4.0


@pytest.mark.parametrize(
    "changes",
    [
        {"range_min": -0.1},
        {"range_min": 3.5},
        {"range_min": 4.0},
        {"angle_increment": 0.0},
        {"angle_increment": -0.01},
        {"samples": 0},
        {"samples": 3.0},
        {"samples": True},
        {"samples": 362},  # 361 beams of 1 deg is a turn with the first beam repeated
        {"spin_spread": 0.02, "angle_increment": 2.0, "samples": 1},  # too few points to spin
        {"no_return": -1.0},
        {"no_return": 3.0},
        {"no_return": -math.inf},
        {"no_return": "nan"},
        {"no_return": True},
        {"spin_spread": -0.01},
        {"spin_spread": 0.5},
        {"spin_spread": math.nan},
        {"noise": -0.01},
        {"resolution": -0.01},
        {"range_max": "3.5"},
        *(
            {field: bad}
            for field in ("range_min", "range_max", "angle_min", "angle_increment")
            for bad in NON_FINITE
        ),
        {"noise": math.nan},
        {"resolution": math.inf},
    ],
)
def test_lidar_config_rejects_invalid_values(changes):
    with pytest.raises(ValueError):
        LidarConfig(**changes)


# --- cast_beams: hand cases --------------------------------------------------------------------------


def test_cast_beams_circle_hand_cases():
    # circle centre (2, 0), r = 0.5 seen from the origin
    angles = [0.0, math.asin(0.3 / 2.0), PI / 2.0, PI]
    range_m, hit = cast_beams(Transform2D(), angles, [[2.0, 0.0, 0.5]], NO_SEGMENTS)
    assert range_m[0] == pytest.approx(1.5, abs=1e-14)
    # a beam whose line passes 0.3 m from the centre: t = 2 cos(a) - sqrt(0.5^2 - 0.3^2)
    assert range_m[1] == pytest.approx(2.0 * math.cos(angles[1]) - 0.4, abs=1e-14)
    assert np.isinf(range_m[2:]).all()
    np.testing.assert_array_equal(hit, [0, 0, -1, -1])


def test_cast_beams_segment_hand_cases():
    # wall x = 1 for y in [-1, 1]
    angles = [0.0, PI / 4.0, PI / 3.0, -PI / 6.0, PI]
    range_m, hit = cast_beams(Transform2D(), angles, NO_CIRCLES, [[1.0, -1.0, 1.0, 1.0]])
    assert range_m[0] == pytest.approx(1.0, abs=1e-15)
    assert range_m[1] == pytest.approx(math.sqrt(2.0), abs=1e-12)  # through the end point (1, 1)
    assert math.isinf(range_m[2])  # passes above the end point
    assert range_m[3] == pytest.approx(1.0 / math.cos(PI / 6.0), abs=1e-14)
    assert math.isinf(range_m[4])  # the wall is behind
    np.testing.assert_array_equal(hit, [0, 0, -1, 0, -1])


def test_cast_beams_takes_the_nearest_object_and_indexes_segments_after_circles():
    circles = [[3.0, 0.0, 0.5], [1.5, 0.0, 0.25]]
    segments = [[4.0, -1.0, 4.0, 1.0], [-2.0, -1.0, -2.0, 1.0]]
    range_m, hit = cast_beams(Transform2D(), [0.0, PI, 0.2], circles, segments)
    np.testing.assert_allclose(range_m, [1.25, 2.0, 4.0 / math.cos(0.2)], rtol=0.0, atol=1e-13)
    np.testing.assert_array_equal(hit, [1, 3, 2])


def test_cast_beams_from_inside_a_circle_sees_its_far_side():
    range_m, hit = cast_beams(Transform2D(0.5, 0.0, 0.0), [0.0, PI], [[0.0, 0.0, 2.0]], NO_SEGMENTS)
    np.testing.assert_allclose(range_m, [1.5, 2.5], rtol=0.0, atol=1e-14)
    np.testing.assert_array_equal(hit, [0, 0])


def test_cast_beams_uses_the_sensor_pose():
    # sensor at (1, 1) facing +y: a circle at world (1, 3) is straight ahead, one at world (3, 1) to its right
    T_world_sensor = Transform2D(1.0, 1.0, PI / 2.0)
    circles = [[1.0, 3.0, 0.5], [3.0, 1.0, 0.25]]
    range_m, hit = cast_beams(T_world_sensor, [0.0, -PI / 2.0], circles, NO_SEGMENTS)
    np.testing.assert_allclose(range_m, [1.5, 1.75], rtol=0.0, atol=1e-14)
    np.testing.assert_array_equal(hit, [0, 1])


def test_cast_beams_without_objects_hits_nothing():
    range_m, hit = cast_beams(Transform2D(), LidarConfig().angles(), [], [])
    assert np.isinf(range_m).all() and (hit == -1).all()


@pytest.mark.parametrize(
    ("circles", "segments", "angles"),
    [
        ([1.0, 0.0, 0.5], NO_SEGMENTS, [0.0]),
        ([[1.0, 0.0]], NO_SEGMENTS, [0.0]),
        ([[1.0, 0.0, 0.0]], NO_SEGMENTS, [0.0]),
        ([[1.0, 0.0, -0.5]], NO_SEGMENTS, [0.0]),
        ([[1.0, math.nan, 0.5]], NO_SEGMENTS, [0.0]),
        (NO_CIRCLES, [[0.0, 0.0, 1.0]], [0.0]),
        (NO_CIRCLES, [[0.0, 0.0, 1.0, math.inf]], [0.0]),
        (NO_CIRCLES, NO_SEGMENTS, [[0.0]]),
        (NO_CIRCLES, NO_SEGMENTS, [math.nan]),
    ],
)
def test_cast_beams_rejects_invalid_input(circles, segments, angles):
    with pytest.raises(ValueError):
        cast_beams(Transform2D(), angles, circles, segments)


# --- cast_beams: properties --------------------------------------------------------------------------


def _ray_point(T_world_sensor: Transform2D, angle: float, t: float) -> np.ndarray:
    return T_world_sensor @ np.array([t * math.cos(angle), t * math.sin(angle)])


def _inside_any_circle(point: np.ndarray, circles: np.ndarray) -> bool:
    return bool(np.any(np.hypot(*(circles[:, :2] - point).T) < circles[:, 2]))


@settings(max_examples=60, deadline=None)
@given(pose=poses, seed=st.integers(0, 2**32 - 1))
def test_cast_beams_hits_are_on_the_object_and_first_along_the_ray(pose, seed):
    rng = np.random.default_rng(seed)
    circles = np.column_stack((rng.uniform(-4.0, 4.0, (6, 2)), rng.uniform(0.05, 0.6, 6)))
    # the sensor must be outside every circle for "nothing before the hit" to mean "outside all circles"
    circles = circles[np.hypot(*(circles[:, :2] - pose.translation).T) > circles[:, 2] + 1e-3]
    angles = rng.uniform(-PI, PI, 40)
    range_m, hit = cast_beams(pose, angles, circles, NO_SEGMENTS)
    for angle, t, j in zip(angles, range_m, hit, strict=True):
        if j < 0:
            # a miss: the ray's closest approach to every circle in front is wider than its radius
            u = np.array([math.cos(angle + pose.theta), math.sin(angle + pose.theta)])
            to_centre = circles[:, :2] - pose.translation
            along = to_centre @ u
            lateral = np.abs(to_centre[:, 0] * u[1] - to_centre[:, 1] * u[0])
            assert np.all((along <= 0.0) | (lateral >= circles[:, 2] - 1e-12))
            continue
        p = _ray_point(pose, angle, t)
        assert math.hypot(*(p - circles[j, :2])) == pytest.approx(circles[j, 2], abs=1e-9)
        for fraction in np.linspace(0.0, 1.0, 50, endpoint=False):
            assert not _inside_any_circle(_ray_point(pose, angle, fraction * t), circles)


@settings(max_examples=60, deadline=None)
@given(pose=poses, motion=poses, seed=st.integers(0, 2**32 - 1))
def test_cast_beams_is_invariant_under_moving_sensor_and_world_together(pose, motion, seed):
    rng = np.random.default_rng(seed)
    circles = np.column_stack((rng.uniform(-4.0, 4.0, (5, 2)), rng.uniform(0.05, 0.6, 5)))
    segments = rng.uniform(-5.0, 5.0, (4, 4))
    moved_circles = np.column_stack((motion @ circles[:, :2], circles[:, 2]))
    moved_segments = np.column_stack((motion @ segments[:, :2], motion @ segments[:, 2:]))
    angles = LidarConfig().angles()
    range_m, hit = cast_beams(pose, angles, circles, segments)
    moved_range_m, moved_hit = cast_beams(motion @ pose, angles, moved_circles, moved_segments)
    finite = np.isfinite(range_m)
    np.testing.assert_array_equal(finite, np.isfinite(moved_range_m))
    np.testing.assert_allclose(moved_range_m[finite], range_m[finite], rtol=1e-9, atol=1e-9)
    # grazing beams may flip between two objects at equal range; everything else hits the same object
    assert np.mean(hit == moved_hit) > 0.95


# --- simulate_scan -----------------------------------------------------------------------------------


def test_simulate_scan_applies_the_range_window():
    config = LidarConfig(range_min=0.5, range_max=2.0, angle_increment=PI / 2.0, samples=4)
    circles = [[1.0, 0.0, 0.1], [0.0, 0.3, 0.1], [-3.0, 0.0, 0.2]]
    ranges = simulate_scan(Transform2D(), circles, NO_SEGMENTS, config)
    # beam 0 hits at 0.9; beam 1 hits at 0.2 < range_min; beam 2 hits at 2.8 > range_max; beam 3 nothing
    np.testing.assert_allclose(ranges, [0.9, 0.0, 0.0, 0.0], rtol=0.0, atol=1e-14)


def test_simulate_scan_in_an_arena():
    walls = arena_walls(4.0, 2.0)
    config = LidarConfig(angle_increment=PI / 2.0, samples=4, range_max=5.0)
    ranges = simulate_scan(Transform2D(0.5, 0.0, 0.0), NO_CIRCLES, walls, config)
    np.testing.assert_allclose(ranges, [1.5, 1.0, 2.5, 1.0], rtol=0.0, atol=1e-14)


def test_simulate_scan_without_noise_matches_cast_beams():
    config = LidarConfig()
    pose = Transform2D(0.3, -0.2, 1.0)
    circles = [[1.0, 0.5, 0.1], [-0.5, 1.0, 0.05]]
    walls = arena_walls(5.0, 5.0)
    true_range_m, _ = cast_beams(pose, config.angles(), circles, walls)
    ranges = simulate_scan(pose, circles, walls, config)
    in_window = (true_range_m >= config.range_min) & (true_range_m <= config.range_max)
    np.testing.assert_array_equal(ranges[in_window], true_range_m[in_window])
    assert np.all(ranges[~in_window] == 0.0)


def test_simulate_scan_noise_is_gaussian_with_the_configured_sigma():
    # Monte Carlo: 2000 scans of a wall 1 m ahead; the errors have mean 0 and std 0.01 (to sampling error)
    config = LidarConfig(angle_min=-0.2, angle_increment=0.1, samples=5, noise=0.01)
    wall = [[1.0, -1.0, 1.0, 1.0]]
    rng = np.random.default_rng(7)
    true_range_m, _ = cast_beams(Transform2D(), config.angles(), NO_CIRCLES, wall)
    scans = np.array([simulate_scan(Transform2D(), NO_CIRCLES, wall, config, rng) for _ in range(2000)])
    errors = scans - true_range_m
    n = errors.size
    assert abs(errors.mean()) < 4.0 * 0.01 / math.sqrt(n)
    # std of the sample std is about sigma / sqrt(2 n)
    assert abs(errors.std() - 0.01) < 4.0 * 0.01 / math.sqrt(2.0 * n)


def test_simulate_scan_quantises_to_the_resolution():
    config = LidarConfig(resolution=0.01)
    pose = Transform2D(0.1, 0.2, 0.3)
    walls = arena_walls(5.0, 4.0)
    ranges = simulate_scan(pose, [[1.0, 0.0, 0.1]], walls, config)
    true_range_m, _ = cast_beams(pose, config.angles(), [[1.0, 0.0, 0.1]], walls)
    returned = ranges > 0.0
    steps = ranges[returned] / 0.01
    np.testing.assert_allclose(steps, np.round(steps), rtol=0.0, atol=1e-9)
    assert np.max(np.abs(ranges[returned] - true_range_m[returned])) <= 0.005 + 1e-12


def test_simulate_scan_is_reproducible_with_a_seed_and_noisy_without_one():
    config = LidarConfig(noise=0.01, resolution=0.001)
    walls = arena_walls(4.0, 4.0)
    first = simulate_scan(Transform2D(), NO_CIRCLES, walls, config, np.random.default_rng(3))
    second = simulate_scan(Transform2D(), NO_CIRCLES, walls, config, np.random.default_rng(3))
    np.testing.assert_array_equal(first, second)
    unseeded = simulate_scan(Transform2D(), NO_CIRCLES, walls, config)
    assert unseeded.shape == (360,) and np.all(unseeded > 0.0)


def test_simulate_scan_reads_zero_where_nothing_is_hit():
    assert np.all(simulate_scan(Transform2D(), NO_CIRCLES, NO_SEGMENTS, LidarConfig()) == 0.0)


@pytest.mark.parametrize("no_return", [0.0, math.nan, math.inf])
def test_simulate_scan_reads_no_return_where_nothing_is_measured(no_return):
    # as test_simulate_scan_applies_the_range_window: beams 1 (too near), 2 (too far) and 3 (nothing)
    config = LidarConfig(
        range_min=0.5, range_max=2.0, angle_increment=PI / 2.0, samples=4, no_return=no_return
    )
    circles = [[1.0, 0.0, 0.1], [0.0, 0.3, 0.1], [-3.0, 0.0, 0.2]]
    ranges = simulate_scan(Transform2D(), circles, NO_SEGMENTS, config)
    np.testing.assert_allclose(ranges, [0.9, no_return, no_return, no_return], rtol=0.0, atol=1e-14)


# --- LidarConfig.scan_layout -------------------------------------------------------------------------


def test_a_fixed_layout_is_every_scans_and_draws_nothing():
    config = LidarConfig(noise=0.01)
    rng = np.random.default_rng(5)
    state = rng.bit_generator.state
    assert config.scan_layout(rng) is config
    assert rng.bit_generator.state == state


@settings(max_examples=100, deadline=None)
@given(
    angle_increment=st.floats(1e-3, PI / 2.0),
    spread=st.floats(0.001, 0.499),
    angle_min=st.floats(-PI, PI),
    seed=st.integers(0, 2**32 - 1),
)
def test_a_spinning_lidars_layouts_hold_one_turn_but_its_last_point(angle_increment, spread, angle_min, seed):
    # the spacing scales by (1 + u), |u| <= spread; the turn starts within one spacing of angle_min, and the
    # scan's end (one spacing past its last beam, the turn's last point) lies within the turn, with no room
    # for another point before the turn closes
    config = LidarConfig(angle_min=angle_min, angle_increment=angle_increment, samples=1, spin_spread=spread)
    layout = config.scan_layout(np.random.default_rng(seed))
    d = layout.angle_increment
    assert 1.0 - spread <= d / angle_increment <= 1.0 + spread
    assert layout.spin_spread == 0.0 and layout.samples >= 1
    assert angle_min <= layout.angle_min <= angle_min + d
    end = layout.angle_min + layout.samples * d
    assert end < angle_min + 2.0 * PI
    assert end + d >= angle_min + 2.0 * PI - 1e-9


def test_an_lds02_like_spin_varies_the_beam_count_from_scan_to_scan():
    # 2300 points per second at 6 Hz +- 2 %: 383.3 points per turn nominally, 375.8 to 391.2; the turn
    # starts up to one spacing in, so it holds 375 to 392 points and the scans 374 to 391 beams
    config = LidarConfig(angle_increment=2.0 * PI * 6.0 / 2300.0, samples=383, spin_spread=0.02)
    rng = np.random.default_rng(11)
    counts = np.array([config.scan_layout(rng).samples for _ in range(2000)])
    assert counts.min() >= 374 and counts.max() <= 391
    assert len(np.unique(counts)) >= 14


# --- arena_walls, polygon_walls ----------------------------------------------------------------------


def test_arena_walls_are_the_four_inner_faces():
    walls = arena_walls(4.0, 2.0)
    np.testing.assert_array_equal(
        walls,
        [[-2.0, -1.0, 2.0, -1.0], [2.0, -1.0, 2.0, 1.0], [2.0, 1.0, -2.0, 1.0], [-2.0, 1.0, -2.0, -1.0]],
    )


@pytest.mark.parametrize(
    ("x_length", "y_length"), [(0.0, 1.0), (1.0, -1.0), (math.nan, 1.0), (1.0, math.inf)]
)
def test_arena_walls_rejects_invalid_sizes(x_length, y_length):
    with pytest.raises(ValueError):
        arena_walls(x_length, y_length)


def test_polygon_walls_close_the_polygon_and_a_beam_hits_a_slanted_wall():
    # a triangle; its edges from each corner to the next, the last back to the first
    walls = polygon_walls([[0.0, 0.0], [2.0, 0.0], [0.0, 2.0]])
    np.testing.assert_array_equal(walls, [[0.0, 0.0, 2.0, 0.0], [2.0, 0.0, 0.0, 2.0], [0.0, 2.0, 0.0, 0.0]])
    # from (0.5, 0.5) along +x the hypotenuse x + y = 2 is at x = 1.5; along 45 deg at (1, 1), sqrt(2) * 0.5
    ranges, _ = cast_beams(Transform2D(0.5, 0.5, 0.0), [0.0, math.pi / 4], np.empty((0, 3)), walls)
    np.testing.assert_allclose(ranges, [1.0, math.sqrt(2.0) * 0.5], atol=1e-12)


@pytest.mark.parametrize(
    "corners",
    [
        [[0.0, 0.0], [1.0, 0.0]],  # too few
        [[0.0, 0.0], [1.0, 0.0], [1.0, 0.0], [0.0, 1.0]],  # a zero-length edge
        [[0.0, 0.0], [1.0, 1.0], [1.0, 0.0], [0.0, 1.0]],  # a bow tie: edges 0 and 2 cross
        [[0.0, 0.0], [1.0, 0.0], [2.0, 0.0]],  # no area (edges 0 and 1 overlap edge 2)
        [[0.0, 0.0], [1.0, 0.0], [math.nan, 1.0]],
    ],
)
def test_polygon_walls_refuse_a_polygon_that_is_not_simple(corners):
    with pytest.raises(ValueError):
        polygon_walls(corners)
