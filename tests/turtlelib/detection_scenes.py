"""Synthetic LDS-01 scenes and detection-quality scoring, shared by test_detection.py and
bench/bench_detection.py.

A scene is a square walled arena (side 4-6 m, centred at the origin), a sensor pose at least 0.5 m from
every wall, and 5-12 cylinders of radius 0.038-0.15 m whose centres lie 0.3-3 m from the sensor (uniform
in distance and bearing), with at least ``CLEARANCE_M`` between any two surfaces (cylinder-cylinder and
cylinder-wall). Scans come from :func:`turtlelib.simulate_scan` with the LDS-01 geometry, 1 cm Gaussian
range noise and 1 cm resolution.

Scoring: a detection is *correct* when its centre lies inside a not yet matched cylinder (distance to the
true centre at most the true radius); every other detection - a wall, a corner, an arena edge, a
duplicate, or a fit off by more than the radius - is a false positive. Recall counts the cylinders hit by
at least 4 beams (noise-free ray casting within the range window) that were matched.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np

from turtlelib import LandmarkDetector, LidarConfig, Transform2D, arena_walls, cast_beams, simulate_scan

LDS01_NOISY = LidarConfig(noise=0.01, resolution=0.01)
CLEARANCE_M = 0.15
MIN_BEAMS = 4


@dataclass(frozen=True)
class Scene:
    T_world_sensor: Transform2D
    circles: np.ndarray  # (M, 3) [x, y, r] in the world
    walls: np.ndarray  # (4, 4)


def random_scene(rng: np.random.Generator, n_cylinders: int | None = None) -> Scene:
    """A scene as described in the module docstring (``n_cylinders`` fixes the count, else 5-12)."""
    half = 0.5 * rng.uniform(4.0, 6.0)
    sensor_xy = rng.uniform(-half + 0.5, half - 0.5, 2)
    pose = Transform2D(sensor_xy[0], sensor_xy[1], rng.uniform(-math.pi, math.pi))
    wanted = int(rng.integers(5, 13)) if n_cylinders is None else n_cylinders
    circles: list[tuple[float, float, float]] = []
    for _ in range(10_000):
        if len(circles) == wanted:
            break
        radius, distance = rng.uniform(0.038, 0.15), rng.uniform(0.3, 3.0)
        bearing = rng.uniform(-math.pi, math.pi)
        x, y = sensor_xy[0] + distance * math.cos(bearing), sensor_xy[1] + distance * math.sin(bearing)
        if max(abs(x), abs(y)) > half - radius - CLEARANCE_M:
            continue
        if any(math.hypot(x - cx, y - cy) < radius + cr + CLEARANCE_M for cx, cy, cr in circles):
            continue
        circles.append((x, y, radius))
    return Scene(pose, np.array(circles).reshape(-1, 3), arena_walls(2.0 * half, 2.0 * half))


def beams_on_cylinders(scene: Scene, lidar: LidarConfig) -> np.ndarray:
    """How many beams hit each cylinder (noise-free, within the range window), shape (M,)."""
    range_m, hit = cast_beams(scene.T_world_sensor, lidar.angles(), scene.circles, scene.walls)
    in_window = (range_m >= lidar.range_min) & (range_m <= lidar.range_max)
    seen = (hit >= 0) & (hit < scene.circles.shape[0]) & in_window
    return np.bincount(hit[seen], minlength=scene.circles.shape[0])


@dataclass
class Quality:
    """Detection counts and errors accumulated over scenes (errors of correct detections only)."""

    correct: int = 0
    false_positives: int = 0
    eligible: int = 0
    eligible_found: int = 0
    centre_error_m: list[float] = field(default_factory=list)
    range_error_m: list[float] = field(default_factory=list)
    bearing_error_rad: list[float] = field(default_factory=list)

    @property
    def precision(self) -> float:
        return self.correct / max(self.correct + self.false_positives, 1)

    @property
    def recall(self) -> float:
        return self.eligible_found / max(self.eligible, 1)

    @property
    def median_centre_error_m(self) -> float:
        return float(np.median(self.centre_error_m))

    def add_scan(
        self, scene: Scene, lidar: LidarConfig, detector: LandmarkDetector, ranges: np.ndarray
    ) -> None:
        """Detect in one scan of ``scene`` and score the detections."""
        detections = detector.detect(lidar.range_scan(ranges))
        centres = np.empty((0, 2))
        if len(scene.circles):
            centres = scene.T_world_sensor.inverse() @ scene.circles[:, :2]
        matched = np.zeros(centres.shape[0], dtype=bool)
        for k in range(len(detections)):
            distance = np.hypot(*(centres - detections.p_sensor[k]).T) if centres.size else np.empty(0)
            distance[matched] = np.inf
            j = int(np.argmin(distance)) if distance.size else -1
            if j < 0 or distance[j] > scene.circles[j, 2]:
                self.false_positives += 1
                continue
            matched[j] = True
            self.correct += 1
            self.centre_error_m.append(float(distance[j]))
            self.range_error_m.append(float(detections.range_m[k] - math.hypot(*centres[j])))
            true_bearing = math.atan2(centres[j, 1], centres[j, 0])
            bearing_error = math.remainder(float(detections.bearing_rad[k]) - true_bearing, math.tau)
            self.bearing_error_rad.append(bearing_error)
        eligible = beams_on_cylinders(scene, lidar) >= MIN_BEAMS
        self.eligible += int(eligible.sum())
        self.eligible_found += int((eligible & matched).sum())


def score(detector: LandmarkDetector, n_scenes: int, seed: int, lidar: LidarConfig = LDS01_NOISY) -> Quality:
    """Score ``detector`` on ``n_scenes`` seeded random scenes."""
    rng = np.random.default_rng(seed)
    quality = Quality()
    for _ in range(n_scenes):
        scene = random_scene(rng)
        ranges = simulate_scan(scene.T_world_sensor, scene.circles, scene.walls, lidar, rng)
        quality.add_scan(scene, lidar, detector, ranges)
    return quality
