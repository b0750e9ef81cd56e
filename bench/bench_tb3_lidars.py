"""Benchmark: the landmark detector (default parameters) on every TurtleBot3 LiDAR layout.

1. Gazebo, recorded: every /scan of the shared third-party recording tb3_gazebo_burger (a Burger in
   Gazebo's turtlebot3_world: nine cylinders of radius 0.15 m; 360 beams over 0..6.28 rad, inf for no
   return), each detection put in the world by the recording's /odom (Gazebo's true pose, interpolated to
   the scan's stamp) and the Burger's LiDAR mount (x = -0.032 m). A detection is *correct* when its centre
   lies inside a cylinder, *spurious* otherwise.
2. nusim, each ``lidar_model`` (lds01, lds02, gazebo; ROS-free ``nusim.simulation``): the robot at rest at
   the origin among three of our cylinders (0.038 m, 0.85-0.92 m away) and three of turtlebot3_world's
   (0.15 m, 1.8-1.9 m away), SCANS scans each: how often each size is found, spurious detections, centre
   errors, and the detection time per scan (the LDS-02's layout changes every scan).

Usage: python bench/bench_tb3_lidars.py [--recording DIR] [--write]   (--write replaces the
"## TurtleBot3 LiDARs" section of docs/benchmarks.md). Run with OPENBLAS_NUM_THREADS=1.
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
sys.path[:0] = [str(ROOT / "bench")]

from bench_docs import write_section  # noqa: E402

from nusim.simulation import LIDAR_MODELS, ArenaConfig, Obstacles, Simulation, SimulationConfig  # noqa: E402
from turtlelib import DetectorConfig, LandmarkDetector, RangeScan, Transform2D, check_scan_layout  # noqa: E402

RECORDING = Path("/work/shared/datasets/tb3_gazebo_burger")
TB3_WORLD_CYLINDERS = np.array([(x, y) for x in (-1.1, 0.0, 1.1) for y in (-1.1, 0.0, 1.1)])
TB3_WORLD_RADIUS_M = 0.15
T_FOOTPRINT_SCAN = Transform2D(-0.032, 0.0, 0.0)
SIM_OBSTACLES = Obstacles(
    x=(0.8, -0.7, 0.2, 1.5, -1.6, -0.3), y=(0.3, 0.6, -0.9, 1.2, -1.0, 1.8), r=(0.038,) * 3 + (0.15,) * 3
)
SCANS = 200
HEADING = "## TurtleBot3 LiDARs"


def match(p_world: np.ndarray, centres: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Nearest cylinder of each detection and the distance to its centre (m)."""
    distance = np.hypot(*(p_world[:, None, :] - centres[None]).transpose(2, 0, 1)).reshape(len(p_world), -1)
    nearest = distance.argmin(axis=1) if len(p_world) else np.empty(0, dtype=int)
    return nearest, distance[np.arange(len(p_world)), nearest]


def recorded_gazebo(directory: Path) -> dict[str, object]:
    from rosbags.rosbag2 import Reader
    from rosbags.typesys import Stores, get_typestore

    typestore = get_typestore(Stores.ROS2_HUMBLE)
    poses, scans = [], []
    with Reader(directory) as reader:
        wanted = [c for c in reader.connections if c.topic in ("/scan", "/odom")]
        for connection, _, data in reader.messages(connections=wanted):
            msg = typestore.deserialize_cdr(data, connection.msgtype)
            t_ns = msg.header.stamp.sec * 1_000_000_000 + msg.header.stamp.nanosec
            if connection.topic == "/odom":
                q, p = msg.pose.pose.orientation, msg.pose.pose.position
                poses.append((t_ns, p.x, p.y, 2.0 * math.atan2(q.z, q.w)))
            else:
                scans.append((t_ns, msg))
    poses_array = np.array(poses)
    heading = np.unwrap(poses_array[:, 3])
    detector = LandmarkDetector(DetectorConfig())
    hits, spurious, errors, radii = np.zeros(9, dtype=int), 0, [], []
    for t_ns, msg in scans:
        check_scan_layout(len(msg.ranges), msg.angle_min, msg.angle_max, msg.angle_increment)
        found = detector.detect(
            RangeScan(msg.ranges, msg.angle_min, msg.angle_increment, msg.range_min, msg.range_max)
        )
        # T_world_footprint interpolated to the scan's stamp
        columns = (poses_array[:, 1], poses_array[:, 2], heading)
        xyt = [np.interp(t_ns, poses_array[:, 0], column) for column in columns]
        T_world_scan = Transform2D(*xyt) @ T_FOOTPRINT_SCAN
        nearest, distance = match(T_world_scan @ found.p_sensor.reshape(-1, 2), TB3_WORLD_CYLINDERS)
        correct = distance < TB3_WORLD_RADIUS_M
        np.add.at(hits, nearest[correct], 1)
        spurious += int(np.count_nonzero(~correct))
        errors.extend(distance[correct])
        radii.extend(found.radius[correct])
    return {
        "scans": len(scans),
        "hits": hits,
        "spurious": spurious,
        "errors_m": np.array(errors),
        "radii_m": np.array(radii),
    }


def simulated(lidar_model: str) -> dict[str, object]:
    model = LIDAR_MODELS[lidar_model]
    arena = ArenaConfig(arena_x_length=12.0, arena_y_length=12.0)
    simulation = Simulation(SimulationConfig(arena=arena, obstacles=SIM_OBSTACLES, lidar=model.sensor))
    T_world_scan = simulation.T_world_body @ simulation.config.robot.T_body_scan
    circles = simulation.circles
    detector = LandmarkDetector(DetectorConfig())
    hits, spurious, errors, times, beams = np.zeros(len(circles), dtype=int), 0, [], [], set()
    for _ in range(SCANS):
        scan = simulation.scan()
        layout = scan.layout
        range_min, range_max = model.reported_range_m or (layout.range_min, layout.range_max)
        start = time.perf_counter()
        found = detector.detect(
            RangeScan(scan.range_m, layout.angle_min, layout.angle_increment, range_min, range_max)
        )
        times.append(time.perf_counter() - start)
        beams.add(layout.samples)
        nearest, distance = match(T_world_scan @ found.p_sensor.reshape(-1, 2), circles[:, :2])
        correct = distance < circles[nearest, 2]
        np.add.at(hits, nearest[correct], 1)
        spurious += int(np.count_nonzero(~correct))
        errors.extend(distance[correct])
    small = circles[:, 2] < 0.1
    return {
        "beams": f"{min(beams)}-{max(beams)}" if len(beams) > 1 else str(beams.pop()),
        "small": hits[small].sum() / (SCANS * small.sum()),
        "large": hits[~small].sum() / (SCANS * (~small).sum()),
        "spurious": spurious,
        "errors_m": np.array(errors),
        "time_ms": 1e3 * np.median(times),
    }


def report(recording: Path) -> str:
    lines = [
        HEADING,
        "",
        f"`bench/bench_tb3_lidars.py`; {platform.python_implementation()} {platform.python_version()}, "
        f"{platform.machine()}, {os.cpu_count()} cores. Default `DetectorConfig`.",
        "",
    ]
    if recording.is_dir():
        gazebo = recorded_gazebo(recording)
        errors = gazebo["errors_m"]
        lines += [
            f"Gazebo, recorded (`tb3_gazebo_burger`, {gazebo['scans']} scans, none refused): correct "
            f"detections per cylinder {gazebo['hits'].tolist()} (all nine cylinders), {gazebo['spurious']} "
            f"spurious; centre error against `/odom` median {1e3 * np.median(errors):.1f} mm, 95th "
            f"percentile {1e3 * np.percentile(errors, 95):.1f} mm; radius median "
            f"{1e3 * np.median(gazebo['radii_m']):.0f} mm (true 150 mm).",
            "",
        ]
    lines += [
        f"nusim, robot at rest, {SCANS} scans per LiDAR; three 0.038 m cylinders 0.85-0.92 m away, three "
        "0.15 m ones 1.8-1.9 m away (a detection is spurious when its centre lies outside every cylinder):",
        "",
        "| `lidar_model` | beams per scan | 0.038 m found | 0.15 m found | spurious | centre error median "
        "| detection median |",
        "|---|---|---|---|---|---|---|",
    ]
    for name in LIDAR_MODELS:
        r = simulated(name)
        lines.append(
            f"| `{name}` | {r['beams']} | {100 * r['small']:.0f} % | {100 * r['large']:.0f} % "
            f"| {r['spurious']} | {1e3 * np.median(r['errors_m']):.1f} mm | {r['time_ms']:.2f} ms |"
        )
    return "\n".join(lines)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--recording", type=Path, default=RECORDING)
    parser.add_argument("--write", action="store_true", help="update docs/benchmarks.md")
    args = parser.parse_args()
    text = report(args.recording)
    print(text)
    if args.write:
        write_section(HEADING, text, ROOT / "docs" / "benchmarks.md")


if __name__ == "__main__":
    main()
