"""turtlelib.sensing.detection: clustering with the seam merge, the landmark detector, and its quality on
synthetic LDS-01 scans (see detection_scenes.py for the scenes and the scoring rules).
"""

import dataclasses
import math
import warnings

import numpy as np
import pytest
from detection_scenes import LDS01_NOISY, Scene, beams_on_cylinders, random_scene, score

from turtlelib import (
    Clusters,
    Detections,
    DetectorConfig,
    LandmarkDetector,
    LidarConfig,
    RangeScan,
    Transform2D,
    arena_walls,
    cast_beams,
    cluster_scan,
    simulate_scan,
)

PI = math.pi
DEG = math.radians(1.0)
NO_SEGMENTS = np.empty((0, 4))
CONFIG = DetectorConfig()


def scan(ranges, angle_min=0.0, angle_increment=DEG, range_min=0.0, range_max=10.0) -> RangeScan:
    """A scan of beams ``angle_min + b angle_increment`` (rad), returns in ``[range_min, range_max]``."""
    return RangeScan(np.asarray(ranges, dtype=np.float64), angle_min, angle_increment, range_min, range_max)


def full_turn(ranges) -> RangeScan:
    """A scan of one full turn of len(ranges) beams from 0 rad."""
    return scan(ranges, angle_increment=2.0 * PI / len(ranges))


# --- DetectorConfig ----------------------------------------------------------------------------------


def test_detector_config_is_frozen_with_sane_defaults():
    assert CONFIG.min_points >= 3 and 0.0 <= CONFIG.min_radius < 0.03 and CONFIG.max_radius > 0.2
    assert CONFIG.min_inscribed_angle < PI / 2.0 < CONFIG.max_inscribed_angle <= PI
    with pytest.raises(dataclasses.FrozenInstanceError):
        CONFIG.min_points = 5


def test_detector_config_accepts_ints_for_floats():
    assert DetectorConfig(max_radius=1).max_radius == 1.0


@pytest.mark.parametrize(
    "changes",
    [
        {"cluster_threshold": 0.0},
        {"cluster_threshold": -0.1},
        {"min_points": 2},
        {"min_points": 4.0},
        {"min_points": True},
        {"min_radius": -0.01},
        {"min_radius": 0.3},
        {"max_radius": 0.01},
        {"max_residual": 0.0},
        {"min_inscribed_angle": -0.1},
        {"max_inscribed_angle": 1.0},
        {"max_inscribed_angle": 3.2},
        {"max_inscribed_angle_std": 0.0},
        {"min_silhouette_edges": -1},
        {"min_silhouette_edges": 3},
        {"silhouette_tolerance": -0.01},
        {"beam_range_std": 0.0},
        {"min_cos_incidence": 0.0},
        {"min_cos_incidence": 1.1},
        {"range_std": 0.0},
        {"bearing_std": -1.0},
        {"range_std": math.nan},
        {"bearing_std": math.inf},
        {"max_radius": "0.2"},
    ],
)
def test_detector_config_rejects_invalid_values(changes):
    with pytest.raises(ValueError):
        DetectorConfig(**changes)


# --- cluster_scan ------------------------------------------------------------------------------------


def test_cluster_scan_hand_case_drops_invalid_beams_and_splits_on_gaps():
    angles = np.arange(12) * DEG
    ranges = np.array([1.0, 1.0, 1.0, 0.0, 2.0, 2.0, 2.0, math.nan, 1.0, 1.0, math.inf, -1.0])
    clusters = cluster_scan(scan(ranges), CONFIG)
    np.testing.assert_array_equal(clusters.offsets, [0, 3, 6, 8])
    np.testing.assert_array_equal(clusters.beam_index, [0, 1, 2, 4, 5, 6, 8, 9])
    directions = np.column_stack((np.cos(angles), np.sin(angles)))
    expected = ranges[clusters.beam_index, None] * directions[clusters.beam_index]
    np.testing.assert_allclose(clusters.p_sensor, expected, rtol=0.0, atol=1e-15)


def test_cluster_scan_applies_the_range_window():
    ranges = np.array([0.1, 0.5, 0.5, 0.5, 3.0, 3.0, 4.0, 4.0])
    clusters = cluster_scan(scan(ranges, range_min=0.12, range_max=3.5), CONFIG)
    np.testing.assert_array_equal(clusters.beam_index, [1, 2, 3, 4, 5])
    np.testing.assert_array_equal(clusters.offsets, [0, 3, 5])


def test_cluster_scan_threshold_is_strict():
    # two points 1 deg apart at 1 m are 2 sin(0.5 deg) = 0.01745 m apart
    gap = 2.0 * math.sin(DEG / 2.0)
    two_beams = scan([1.0, 1.0])
    assert len(cluster_scan(two_beams, DetectorConfig(cluster_threshold=gap * 1.001))) == 1
    assert len(cluster_scan(two_beams, DetectorConfig(cluster_threshold=gap * 0.999))) == 2


def test_cluster_scan_merges_across_the_seam_of_a_full_turn():
    ranges = np.zeros(360)
    ranges[[357, 358, 359, 0, 1, 2]] = 1.0
    ranges[180:186] = 2.0
    clusters = cluster_scan(full_turn(ranges), CONFIG)
    assert len(clusters) == 2
    np.testing.assert_array_equal(clusters.points(0), clusters.p_sensor[:6])
    np.testing.assert_array_equal(clusters.beam_index[:6], [357, 358, 359, 0, 1, 2])
    np.testing.assert_array_equal(clusters.beam_index[6:], np.arange(180, 186))
    # the merged cluster runs contiguously in space
    steps = np.hypot(*np.diff(clusters.points(0), axis=0).T)
    assert steps.max() < 0.02


def test_cluster_scan_merges_across_the_seam_of_a_reversed_full_turn():
    # beams 0, 1 look at 359 and 358 deg, beams 358, 359 at 1 and 0 deg: one object across the seam
    ranges = np.zeros(360)
    ranges[[0, 1, 358, 359]] = 1.0
    ranges[180:186] = 2.0
    clusters = cluster_scan(scan(ranges, angle_min=359 * DEG, angle_increment=-DEG), CONFIG)
    assert len(clusters) == 2
    np.testing.assert_array_equal(clusters.beam_index, [358, 359, 0, 1, 180, 181, 182, 183, 184, 185])


def test_cluster_scan_does_not_merge_a_partial_scan_or_a_wide_seam():
    # 350 deg: the first and last points are 5.7 cm apart but the scan does not close
    ranges = np.zeros(350)
    ranges[[0, 1, 348, 349]] = 0.3
    ranges[170:176] = 2.0
    assert len(cluster_scan(scan(ranges), CONFIG)) == 3
    # a full turn whose seam gap (1 m) is above the threshold
    ranges = np.zeros(360)
    ranges[[358, 359]] = 1.0
    ranges[[0, 1]] = 2.0
    ranges[180:186] = 2.0
    assert len(cluster_scan(full_turn(ranges), CONFIG)) == 3


def test_cluster_scan_of_a_closed_ring_is_one_cluster():
    # the sensor in the middle of a round wall: every gap, the seam included, is small
    clusters = cluster_scan(full_turn(np.full(360, 1.0)), CONFIG)
    assert len(clusters) == 1 and clusters.sizes[0] == 360
    np.testing.assert_array_equal(clusters.beam_index, np.arange(360))


def test_cluster_scan_without_returns_has_no_clusters():
    clusters = cluster_scan(full_turn(np.zeros(360)), CONFIG)
    assert len(clusters) == 0 and clusters.p_sensor.shape == (0, 2) and clusters.labels.shape == (0,)


def test_clusters_accessors():
    clusters = cluster_scan(scan([1.0, 1.0, 2.0, 2.0, 2.0]), CONFIG)
    assert len(clusters) == 2
    np.testing.assert_array_equal(clusters.sizes, [2, 3])
    np.testing.assert_array_equal(clusters.labels, [0, 0, 1, 1, 1])
    assert clusters.points(1).shape == (3, 2)
    for bad in (-1, 2):
        with pytest.raises(IndexError):
            clusters.points(bad)


# --- LandmarkDetector: hand-built scenes -------------------------------------------------------------


LDS01 = LidarConfig()


def detect(ranges, lidar=LDS01, config=CONFIG):
    return LandmarkDetector(config).detect(
        scan(ranges, lidar.angle_min, lidar.angle_increment, lidar.range_min, lidar.range_max)
    )


# noise-free scans: tell the refinement the ranges are (nearly) exact
EXACT = dataclasses.replace(CONFIG, beam_range_std=1e-5)


def test_detects_a_single_cylinder_noise_free():
    lidar = LidarConfig()
    cylinder = np.array([[1.0, 0.3, 0.1]])
    ranges = simulate_scan(Transform2D(), cylinder, NO_SEGMENTS, lidar)
    detections = detect(ranges, lidar, EXACT)
    assert len(detections) == 1
    np.testing.assert_allclose(detections.p_sensor[0], [1.0, 0.3], rtol=0.0, atol=1e-6)
    assert detections.radius[0] == pytest.approx(0.1, abs=1e-6)
    assert detections.n_points[0] == np.count_nonzero(ranges)
    assert detections.residual[0] < 1e-6
    assert detections.range_m[0] == pytest.approx(math.hypot(*detections.p_sensor[0]), abs=1e-15)
    x, y = detections.p_sensor[0]
    assert detections.bearing_rad[0] == pytest.approx(math.atan2(y, x), abs=1e-15)
    covariance = np.diag([CONFIG.range_std**2, CONFIG.bearing_std**2])
    np.testing.assert_array_equal(detections.covariance[0], covariance)
    measurement = [detections.range_m[0], detections.bearing_rad[0]]
    np.testing.assert_array_equal(detections.measurements(), [measurement])


@pytest.mark.parametrize("bearing_deg", [0.0, 0.5, 17.3, 90.25])
def test_default_config_on_a_noise_free_scan_errs_by_under_half_a_beam(bearing_deg):
    # with the default 1 cm range noise assumed, the silhouette rays (each known to half a beam) weigh in:
    # the centre stays within half a beam width (range * increment / 2) of the truth
    lidar = LidarConfig()
    bearing = math.radians(bearing_deg)
    centre = 1.5 * np.array([math.cos(bearing), math.sin(bearing)])
    detections = detect(simulate_scan(Transform2D(), [[*centre, 0.1]], NO_SEGMENTS, lidar), lidar)
    assert len(detections) == 1
    assert math.hypot(*(detections.p_sensor[0] - centre)) < 0.5 * 1.5 * lidar.angle_increment


def test_detects_a_cylinder_across_the_seam_once():
    lidar = LidarConfig()
    cylinder = np.array([[1.5, 0.0, 0.1]])
    ranges = simulate_scan(Transform2D(), cylinder, arena_walls(6.0, 6.0), lidar)
    assert ranges[0] > 0.0 and ranges[-1] > 0.0  # the cylinder straddles beam 0
    detections = detect(ranges, lidar, EXACT)
    assert len(detections) == 1
    np.testing.assert_allclose(detections.p_sensor[0], [1.5, 0.0], rtol=0.0, atol=1e-6)


def test_beams_beyond_one_turn_are_dropped():
    # Gazebo's layout (360 beams of 6.28 / 359 rad from 0, as the shared recording carries it): beam 359 lies
    # 0.0032 rad short of a turn and repeats beam 0. A cylinder straddles the seam; whatever beam 359 reads
    # (here a phantom 0.3 m return that would split the cylinder's cluster), the detections are those of the
    # first 359 beams.
    angle_increment = 0.01749303564429283
    angles = angle_increment * np.arange(360)
    ranges, _ = cast_beams(Transform2D(), angles, [[1.5, 0.0, 0.1]], arena_walls(6.0, 6.0))
    phantom = ranges.copy()
    phantom[-1] = 0.3
    detector = LandmarkDetector(EXACT)
    expected = detector.detect(scan(ranges[:359], 0.0, angle_increment, 0.12, 3.5))
    for beams in (ranges, phantom):
        detections = detector.detect(scan(beams, 0.0, angle_increment, 0.12, 3.5))
        assert len(detections) == 1
        np.testing.assert_array_equal(detections.p_sensor, expected.p_sensor)
        np.testing.assert_allclose(detections.p_sensor[0], [1.5, 0.0], rtol=0.0, atol=1e-6)


def test_a_reversed_scan_gives_the_same_detections():
    lidar = LidarConfig(noise=0.01, resolution=0.01)
    rng = np.random.default_rng(4)
    scene = random_scene(rng, n_cylinders=8)
    ranges = simulate_scan(scene.T_world_sensor, scene.circles, scene.walls, lidar, rng)
    forward = detect(ranges, lidar)
    detector = LandmarkDetector(CONFIG)
    last_angle = lidar.angle_min + (lidar.samples - 1) * lidar.angle_increment
    limits = (lidar.range_min, lidar.range_max)
    backward = detector.detect(scan(ranges[::-1], last_angle, -lidar.angle_increment, *limits))
    assert len(forward) == len(backward) > 0
    order_f, order_b = np.argsort(forward.bearing_rad), np.argsort(backward.bearing_rad)
    np.testing.assert_allclose(backward.p_sensor[order_b], forward.p_sensor[order_f], rtol=0.0, atol=1e-9)


def test_walls_corners_and_arena_edges_are_never_cylinders():
    # empty arenas seen from 300 poses: walls, corners, walls cut by the range limit, grazing walls
    rng = np.random.default_rng(9)
    detector = LandmarkDetector(CONFIG)
    lidar = LDS01_NOISY
    found = 0
    for _ in range(300):
        half = 0.5 * rng.uniform(1.5, 7.0, 2)
        pose = Transform2D(*rng.uniform(-half + 0.2, half - 0.2), rng.uniform(-PI, PI))
        ranges = simulate_scan(pose, np.empty((0, 3)), arena_walls(*(2.0 * half)), lidar, rng)
        found += len(detector.detect(scan(ranges, lidar.angle_min, lidar.angle_increment, 0.12, 3.5)))
    assert found == 0


def test_a_cylinder_seen_only_between_two_occluders_needs_a_silhouette_edge():
    # a cylinder 2 m ahead, visible only through the gap between two nearer ones: both beams next to its
    # cluster hit an occluder, so it shows no outline of its own
    circles = np.array([[2.0, 0.0, 0.15], [1.0, 0.09, 0.045], [1.0, -0.09, 0.045]])
    lidar = LidarConfig(angle_min=-PI)
    ranges = simulate_scan(Transform2D(), circles, NO_SEGMENTS, lidar)
    assert beams_on_cylinders(Scene(Transform2D(), circles, NO_SEGMENTS), lidar)[0] == 5
    strict = detect(ranges, lidar, EXACT)
    relaxed = detect(ranges, lidar, dataclasses.replace(EXACT, min_silhouette_edges=0))
    assert np.count_nonzero(strict.range_m > 1.5) == 0
    assert np.count_nonzero(relaxed.range_m > 1.5) == 1


def test_invalid_beams_inside_a_scan_are_ignored_without_warnings():
    lidar = LidarConfig()
    ranges = simulate_scan(Transform2D(), [[1.0, 0.3, 0.1], [-1.0, 0.5, 0.1]], arena_walls(5.0, 5.0), lidar)
    ranges[100:110] = math.nan
    ranges[200:210] = math.inf
    ranges[250:260] = -math.inf
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        detections = detect(ranges, lidar)
    assert len(detections) == 2


def test_detect_with_clusters_returns_the_detections_and_every_cluster():
    lidar = LDS01_NOISY
    rng = np.random.default_rng(1)
    scene = random_scene(rng)
    ranges = simulate_scan(scene.T_world_sensor, scene.circles, scene.walls, lidar, rng)
    detector = LandmarkDetector(CONFIG)
    lidar_scan = scan(ranges, 0.0, lidar.angle_increment, 0.12, 3.5)
    detections, clusters = detector.detect_with_clusters(lidar_scan)
    again = detector.detect(lidar_scan)
    np.testing.assert_array_equal(detections.p_sensor, again.p_sensor)
    expected = cluster_scan(lidar_scan, CONFIG)
    assert isinstance(clusters, Clusters)
    np.testing.assert_array_equal(clusters.offsets, expected.offsets)
    np.testing.assert_array_equal(clusters.beam_index, expected.beam_index)


def test_each_detection_names_the_cluster_it_was_fitted_to():
    rng = np.random.default_rng(4)
    lidar = LDS01_NOISY
    for _ in range(5):
        scene = random_scene(rng)
        ranges = simulate_scan(scene.T_world_sensor, scene.circles, scene.walls, lidar, rng)
        detections, clusters = LandmarkDetector(CONFIG).detect_with_clusters(
            scan(ranges, 0.0, lidar.angle_increment, 0.12, 3.5)
        )
        assert len(detections) > 0
        assert len(set(detections.cluster_index.tolist())) == len(detections)
        for centre, radius, n, k in zip(
            detections.p_sensor, detections.radius, detections.n_points, detections.cluster_index, strict=True
        ):
            points = clusters.points(int(k))
            assert len(points) == n
            # the cluster's points lie on the fitted circle (1 cm noise, 1 cm resolution)
            np.testing.assert_allclose(np.linalg.norm(points - centre, axis=1), radius, atol=0.04)


def test_detections_built_without_cluster_indices_mark_them_unknown():
    one = np.ones(1)
    detections = Detections(
        np.zeros((1, 2)), one, np.ones(1, dtype=np.intp), one, one, one, np.zeros((1, 2, 2))
    )
    np.testing.assert_array_equal(detections.cluster_index, [-1])


def test_a_scan_without_candidates_gives_empty_detections():
    detections = detect(np.zeros(360))
    assert len(detections) == 0
    assert detections.p_sensor.shape == (0, 2) and detections.covariance.shape == (0, 2, 2)


def test_detections_validate_their_shapes():
    one, count, covariance = np.zeros(1), np.zeros(1, dtype=np.intp), np.zeros((1, 2, 2))
    Detections(np.zeros((1, 2)), one, count, one, one, one, covariance)
    with pytest.raises(ValueError):
        Detections(np.zeros((1, 2)), one, count, one, one, np.empty(0), covariance)
    with pytest.raises(ValueError):
        Detections(np.zeros((1, 3)), one, count, one, one, one, covariance)
    with pytest.raises(ValueError):
        Detections(np.zeros((1, 2)), one, count, one, one, one, np.zeros((1, 3, 3)))


# --- quality on synthetic LDS-01 scans ---------------------------------------------------------------


def test_detection_quality_on_synthetic_lds01_scans():
    """The issue's acceptance figures on 1000 seeded scenes (about 6500 eligible cylinders)."""
    quality = score(LandmarkDetector(CONFIG), n_scenes=1000, seed=2024)
    assert quality.eligible > 5000
    assert quality.precision >= 0.99
    assert quality.recall >= 0.95
    assert quality.median_centre_error_m <= 0.01
    # the configured measurement covariance bounds the errors actually made, bias included (Monte Carlo
    # over the scenes): E[e^2] <= sigma^2 for range and bearing
    assert math.sqrt(np.mean(np.square(quality.range_error_m))) <= CONFIG.range_std
    assert math.sqrt(np.mean(np.square(quality.bearing_error_rad))) <= CONFIG.bearing_std


# --- what is not a post: dropout fragments, door frames, wall ends ----------------------------------------

# the LDS-02 as nusim simulates it (nusim.simulation.LIDAR_MODELS["lds02"]): 0.94 deg beams, a layout per
# turn, NaN for no return, 1 cm noise and 1 mm resolution, reach 0.16-8 m
LDS02 = LidarConfig(
    range_min=0.16,
    range_max=8.0,
    angle_increment=2.0 * PI * 6.0 / 2300.0,
    samples=383,
    noise=0.01,
    resolution=0.001,
    no_return=math.nan,
    spin_spread=0.02,
)


def phantoms(detections: Detections, scene: Scene, margin_m: float = 0.03) -> int:
    """Detections whose centre is not within a cylinder grown by ``margin_m`` (m)."""
    p_world = scene.T_world_sensor @ detections.p_sensor
    gap = np.linalg.norm(p_world[:, None, :] - scene.circles[None, :, :2], axis=2) - scene.circles[:, 2]
    return int(np.count_nonzero((gap > margin_m).all(axis=1))) if len(scene.circles) else len(p_world)


def test_lds02_dropouts_of_every_third_beam_make_no_phantom_posts():
    # every third beam without a return (a dark floor-level surface for the LDS-02): walls cut into
    # fragments of two returns and a gap, which looked like posts where a missing beam counted as a
    # silhouette edge. Bridging the missing beams and reading past them leaves none; with no beam taken
    # as a dropout (max_dropout_beams = 0) the same scans give phantoms, so this scene can tell.
    rng = np.random.default_rng(11)
    detector = LandmarkDetector(CONFIG)
    naive = LandmarkDetector(dataclasses.replace(CONFIG, max_dropout_beams=0))
    found = naive_phantoms = 0
    for _ in range(150):
        scene = random_scene(rng)
        lidar = LDS02.scan_layout(rng)
        ranges = simulate_scan(scene.T_world_sensor, scene.circles, scene.walls, lidar, rng)
        ranges[int(rng.integers(3)) :: 3] = math.nan
        detections = detector.detect(lidar.range_scan(ranges))
        assert phantoms(detections, scene) == 0
        found += len(detections)
        naive_phantoms += phantoms(naive.detect(lidar.range_scan(ranges)), scene)
    assert naive_phantoms >= 1
    assert found >= 4 * 150  # the posts are still found (about 5.5 per scene)


def test_lds02_dropouts_keep_a_post_whole():
    # a 0.15 m post 2.5 m ahead, every third beam missing: its returns form one cluster with the dropouts
    # bridged (not three fragments) and one detection at its place
    lidar = dataclasses.replace(LDS02, spin_spread=0.0, noise=0.0, resolution=0.0)
    ranges = simulate_scan(Transform2D(), [[2.5, 0.0, 0.15]], arena_walls(8.0, 8.0), lidar)
    ranges[::3] = math.nan
    detections = LandmarkDetector(EXACT).detect(lidar.range_scan(ranges))
    assert len(detections) == 1
    np.testing.assert_allclose(detections.p_sensor[0], [2.5, 0.0], rtol=0.0, atol=0.01)


def test_too_few_real_returns_are_no_post():
    # the post above with two beams of three missing: 5 returns over 13 beams, under min_return_fraction
    lidar = dataclasses.replace(LDS02, spin_spread=0.0, noise=0.0, resolution=0.0)
    ranges = simulate_scan(Transform2D(), [[1.2, 0.0, 0.15]], arena_walls(8.0, 8.0), lidar)
    ranges[(np.arange(len(ranges)) % 3) != 0] = math.nan
    relaxed = dataclasses.replace(EXACT, min_return_fraction=0.0, max_dropout_beams=2)
    assert len(LandmarkDetector(relaxed).detect(lidar.range_scan(ranges))) == 1
    assert len(LandmarkDetector(EXACT).detect(lidar.range_scan(ranges))) == 0
