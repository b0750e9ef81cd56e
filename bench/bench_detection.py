"""Benchmark: landmark detection time per scan and detection quality on synthetic LDS-01 scans.

Timing: median and p99 wall time of ``LandmarkDetector.detect`` on one full-turn scan of a walled room
with 10 cylinders (scenes as in tests/turtlelib/detection_scenes.py: 4-6 m square arena, cylinders of
radius 0.038-0.15 m 0.3-3 m away, 1 cm range noise, 1 cm resolution), for 100, 360 and 1000 beams.
Quality: precision, recall and errors on 2000 seeded scenes generated and scored like the quality test.

Usage: python bench/bench_detection.py [--write]   (--write replaces the "## Landmark detection" section
of docs/benchmarks.md, creating the file if needed). Run with OPENBLAS_NUM_THREADS=1.
"""

from __future__ import annotations

import argparse
import math
import os
import platform
import sys
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path[:0] = [str(ROOT / "bench"), str(ROOT / "tests" / "turtlelib")]  # bench_docs, detection_scenes

from bench_docs import write_section  # noqa: E402
from detection_scenes import random_scene, score  # noqa: E402

from turtlelib import DetectorConfig, LandmarkDetector, LidarConfig, simulate_scan  # noqa: E402

BEAM_COUNTS = (100, 360, 1000)
SCENES = 50
REPEATS = 40
QUALITY_SCENES = 2000
HEADING = "## Landmark detection"


def time_detection(samples: int, seed: int = 1) -> dict[str, float]:
    """Per-scan detection times (s) over SCENES scenes x REPEATS calls, and detections per scan."""
    increment = 2.0 * math.pi / samples
    lidar = LidarConfig(samples=samples, angle_increment=increment, noise=0.01, resolution=0.01)
    rng = np.random.default_rng(seed)
    scans = []
    for _ in range(SCENES):
        scene = random_scene(rng, n_cylinders=10)
        scans.append(simulate_scan(scene.T_world_sensor, scene.circles, scene.walls, lidar, rng))
    detector = LandmarkDetector(DetectorConfig())
    found = [len(detector.detect(lidar.range_scan(ranges))) for ranges in scans]  # also warms up
    times = []
    for _ in range(REPEATS):
        for ranges in scans:
            start = time.perf_counter()
            detector.detect(lidar.range_scan(ranges))
            times.append(time.perf_counter() - start)
    return {
        "median": float(np.median(times)),
        "p99": float(np.percentile(times, 99)),
        "found": float(np.mean(found)),
    }


def timing_rows() -> list[str]:
    rows = []
    for samples in BEAM_COUNTS:
        result = time_detection(samples)
        median_ms, p99_ms = 1e3 * result["median"], 1e3 * result["p99"]
        rows.append(f"| {samples} | {median_ms:.3f} | {p99_ms:.3f} | {result['found']:.1f} |")
    return rows


def quality_row(config: DetectorConfig) -> str:
    quality = score(LandmarkDetector(config), QUALITY_SCENES, seed=7)
    reported = quality.correct + quality.false_positives
    range_mean_mm = 1e3 * np.mean(quality.range_error_m)
    range_rms_mm = 1e3 * math.sqrt(np.mean(np.square(quality.range_error_m)))
    bearing_rms_mrad = 1e3 * math.sqrt(np.mean(np.square(quality.bearing_error_rad)))
    return (
        f"| {quality.precision:.4f} ({quality.false_positives} false of {reported}) "
        f"| {quality.recall:.4f} ({quality.eligible_found} of {quality.eligible}) "
        f"| {1e3 * quality.median_centre_error_m:.1f} mm "
        f"| {range_mean_mm:.1f} / {range_rms_mm:.1f} mm | {bearing_rms_mrad:.1f} mrad |"
    )


def section() -> str:
    config = DetectorConfig()
    threads = os.environ.get("OPENBLAS_NUM_THREADS", "unset")
    versions = f"Python {platform.python_version()}, numpy {np.__version__}"
    machine = f"{platform.machine()}, {os.cpu_count()} cores, {versions}"
    return "\n".join(
        [
            HEADING,
            "",
            f"`python bench/bench_detection.py --write` (OPENBLAS_NUM_THREADS={threads}; {machine}).",
            "",
            "Time of `LandmarkDetector.detect` per full-turn scan of a walled room with 10 cylinders",
            f"({SCENES} seeded scenes x {REPEATS} calls; 1 cm range noise, 1 cm resolution): clustering,",
            "batched hyper fit, one Gauss-Newton step with the silhouette rays, classification.",
            "",
            "| beams | median (ms) | p99 (ms) | cylinders found per scan |",
            "|---:|---:|---:|---:|",
            *timing_rows(),
            "",
            f"Quality on {QUALITY_SCENES} seeded LDS-01 scenes (360 beams of 1 deg, 0.12-3.5 m,",
            "sigma = 1 cm, 1 cm resolution; 5-12 cylinders of radius 0.038-0.15 m, 0.3-3 m away,",
            "in a 4-6 m walled square; scored as in tests/turtlelib/detection_scenes.py;",
            "default `DetectorConfig`):",
            "",
            "| precision | recall (cylinders hit by >= 4 beams) | median centre error "
            "| range error mean / RMS | bearing error RMS |",
            "|---:|---:|---:|---:|---:|",
            quality_row(config),
            "",
            f"The default measurement covariance is diag({config.range_std} m, {config.bearing_std} rad)^2.",
            "",
        ]
    )


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--write", action="store_true", help="update docs/benchmarks.md")
    arguments = parser.parse_args()
    text = section()
    print(text)
    if arguments.write:
        write_section(HEADING, text, ROOT / "docs" / "benchmarks.md")


if __name__ == "__main__":
    main()
