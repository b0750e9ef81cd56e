"""Benchmark: occupancy grid update time per scan and the grid's accuracy against the true geometry.

The demo's world (nuturtle_demo/config/demo_world.yaml: the 5 m square arena, eight cylinders of radius
0.038 m) scanned by a simulated LDS-01 (360 beams of 1 deg, 0.12-3.5 m, 1 cm noise, 1 cm resolution,
0.0 for no return) at 5 Hz for 120 s along the demo's figure eight (two loops of radius 0.75 m at
0.14 m/s touching at the origin), the LiDAR 0.032 m behind the Burger's axle. The scans are inserted at
their TRUE poses: this measures the grid mapping alone (the SLAM poses come with the node).

Timing: CPU time (``time.process_time_ns``) of ``OccupancyGrid.insert_scan`` per scan (median, p99),
of ``OccupancyGrid.grid_map`` (the int8 grid a node publishes) and of re-rendering the kept keyframes
(``ScanKeyframes.render``, what a save after a loop closure costs).

Accuracy (the issue's targets): the true boundary cells (cells a wall or a cylinder's outline passes
through, sampled every 1 mm) with an occupied cell (>= 65) within one cell (the 3 x 3 block); the true
free cells (inside the arena, centre more than 1.5 cells from every boundary) marked occupied, and those
known to be free (<= 19).

At the bound: a corridor 3 m wide and 300 m long driven straight along its middle at 1 m/s (1500 scans
of the same LiDAR), into a grid that starts at the default bound (``max_size_m`` = 100 m: 2000 x 2000
cells), so that it moves toward the robot every ``grow_margin_m`` or so: ``insert_scan`` per scan
(median, p99, largest: a move copies the cells it keeps), the moves, the scans past the bound, the
grid's bytes, and ``grid_map`` of the full grid.

At SLAM poses (``--slam-seeds``): the demo itself (``python -P -m nuturtle_demo --duration 120 --seed S``,
its default world and unknown association, in a child process: bench/demo_cpu.py's ``run_once``) maps
with slam's grid; its ``map.yaml`` + ``map.pgm`` (the keyframes re-rendered at slam's poses, in
map_server's trinary values) are measured the same way.

Usage: python bench/grid_update.py [--write] [--figure] [--slam-seeds 0 1 2]   (--write replaces the
"## Occupancy grid" section of docs/benchmarks.md; --figure draws docs/figures/grid_demo_world.png and,
with --slam-seeds, copies the first seed's grid.png to docs/figures/grid_demo_slam.png). Run with
OPENBLAS_NUM_THREADS=1.
"""

from __future__ import annotations

import argparse
import json
import math
import os
import platform
import shutil
import sys
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parent.parent
sys.path.insert(0, str(ROOT / "bench"))  # bench_docs

from bench_docs import write_section  # noqa: E402
from demo_cpu import run_once  # noqa: E402

from turtlelib import (  # noqa: E402
    GridConfig,
    GridMap,
    KeyframeConfig,
    LidarConfig,
    OccupancyGrid,
    RangeScan,
    ScanKeyframes,
    Transform2D,
    Twist2D,
    arena_walls,
    integrate_twist,
    simulate_scan,
)

HEADING = "## Occupancy grid"
CYLINDERS = np.array(
    [
        [1.4, 0.3],
        [-1.4, -0.3],
        [1.3, -1.2],
        [-1.3, 1.2],
        [0.0, 0.75],
        [0.0, -0.75],
        [1.2, 1.4],
        [-1.2, -1.4],
    ]
)
RADIUS_M = 0.038
ARENA_M = 5.0
LIDAR = LidarConfig(noise=0.01, resolution=0.01)
T_BODY_SCAN = Transform2D(-0.032, 0.0, 0.0)
SCAN_RATE_HZ, DURATION_S, SPEED_MPS, LOOP_RADIUS_M = 5.0, 120.0, 0.14, 0.75
CORRIDOR_LENGTH_M, CORRIDOR_WIDTH_M, CORRIDOR_SPEED_MPS = 300.0, 3.0, 1.0


def route() -> list[Transform2D]:
    """True body poses at the scan times: the figure eight, each loop's turn the other way."""
    omega = SPEED_MPS / LOOP_RADIUS_M
    period_s = 2.0 * math.pi / omega
    poses = []
    for k in range(int(DURATION_S * SCAN_RATE_HZ)):
        tau = k / SCAN_RATE_HZ
        loop = math.floor(tau / period_s)
        twist = Twist2D((-1) ** loop * omega, SPEED_MPS, 0.0) * (tau - loop * period_s)
        poses.append(integrate_twist(twist))
    return poses


def scans(poses: list[Transform2D]) -> list[RangeScan]:
    rng = np.random.default_rng(0)
    circles = np.column_stack([CYLINDERS, np.full(len(CYLINDERS), RADIUS_M)])
    walls = arena_walls(ARENA_M, ARENA_M)
    return [
        RangeScan(
            simulate_scan(T @ T_BODY_SCAN, circles, walls, LIDAR, rng),
            LIDAR.angle_min,
            LIDAR.angle_increment,
            LIDAR.range_min,
            LIDAR.range_max,
        )
        for T in poses
    ]


def boundary_points() -> np.ndarray:
    """Points every 1 mm on the walls and the cylinders' outlines (m), (N, 2)."""
    h = 0.5 * ARENA_M
    s = np.arange(-h, h, 0.001)
    walls = [np.column_stack([s, np.full_like(s, y)]) for y in (-h, h)]
    walls += [np.column_stack([np.full_like(s, x), s]) for x in (-h, h)]
    phi = np.arange(0.0, 2.0 * math.pi, 0.001 / RADIUS_M)
    rims = [c + RADIUS_M * np.column_stack([np.cos(phi), np.sin(phi)]) for c in CYLINDERS]
    return np.concatenate(walls + rims)


def accuracy(grid_map: GridMap) -> dict[str, float]:
    """The issue's measures of a grid (a GridMap: an OccupancyGrid's or one loaded from map_server's files)
    against the demo world's true geometry (module docstring)."""
    from scipy.ndimage import maximum_filter

    occupancy = grid_map.occupancy
    res = grid_map.resolution_m
    x0, y0 = grid_map.origin.x, grid_map.origin.y
    occupied_near = maximum_filter((occupancy >= 65).astype(np.uint8), size=3).astype(bool)
    # (row, col) of each boundary point as the grid numbers cells (floor(p / res) less the origin's cell);
    # a grid that does not reach a point has not found it
    points = boundary_points()
    origin_cell = np.rint(np.array([y0, x0]) / res).astype(np.int64)
    cells = np.unique(np.floor(points[:, ::-1] / res).astype(np.int64) - origin_cell, axis=0)
    inside = (cells >= 0).all(axis=1) & (cells < occupancy.shape).all(axis=1)
    found = np.zeros(len(cells), dtype=bool)
    found[inside] = occupied_near[cells[inside, 0], cells[inside, 1]]
    rows, cols = np.indices(occupancy.shape)
    centres = np.column_stack([(x0 + (cols.ravel() + 0.5) * res), (y0 + (rows.ravel() + 0.5) * res)])
    h = 0.5 * ARENA_M
    wall_distance = h - np.abs(centres).max(axis=1)
    cylinder_distance = np.linalg.norm(centres[:, None, :] - CYLINDERS[None], axis=2).min(axis=1) - RADIUS_M
    free = (wall_distance > 1.5 * res) & (np.abs(cylinder_distance) > 1.5 * res)
    values = occupancy.ravel()[free]
    return {
        "boundary_found": float(found.mean()),
        "boundary_cells": int(len(cells)),
        "free_marked_occupied": float(np.mean(values >= 65)),
        "free_known_free": float(np.mean((values >= 0) & (values <= 19))),
        "free_cells": int(free.sum()),
    }


def measure(resolution_m: float) -> dict[str, float]:
    poses = route()
    scan_list = scans(poses)
    grid = OccupancyGrid(GridConfig(resolution_m=resolution_m))
    keyframes = ScanKeyframes(KeyframeConfig())
    update_ns = []
    for T, scan in zip(poses, scan_list, strict=True):
        start = time.process_time_ns()
        grid.insert_scan(scan, T @ T_BODY_SCAN)
        update_ns.append(time.process_time_ns() - start)
        keyframes.offer(len(update_ns), T, scan)
    publish_ns = []
    for _ in range(20):
        start = time.process_time_ns()
        grid.grid_map()
        publish_ns.append(time.process_time_ns() - start)
    start = time.process_time_ns()
    rendered = keyframes.render(lambda k: poses[k - 1], T_BODY_SCAN, GridConfig(resolution_m=resolution_m))
    render_ms = 1e-6 * (time.process_time_ns() - start)
    return {
        "resolution_m": resolution_m,
        "scans": len(update_ns),
        "median_ms": 1e-6 * float(np.median(update_ns)),
        "p99_ms": 1e-6 * float(np.percentile(update_ns, 99)),
        "publish_ms": 1e-6 * float(np.median(publish_ns)),
        "cells": grid.log_odds.size,
        "shape": grid.log_odds.shape,
        "keyframes": len(keyframes),
        "render_ms": render_ms,
        **accuracy(grid.grid_map()),
        "rendered": accuracy(rendered.grid_map()),
        "grid": grid,
        "poses": poses,
    }


def measure_bound() -> dict[str, float]:
    """The grid at its bound along the corridor (module docstring)."""
    grid = OccupancyGrid(GridConfig(initial_size_m=GridConfig().max_size_m))
    h = 0.5 * CORRIDOR_WIDTH_M
    walls = np.array([[-5.0, -h, CORRIDOR_LENGTH_M + 5.0, -h], [-5.0, h, CORRIDOR_LENGTH_M + 5.0, h]])
    rng = np.random.default_rng(0)
    update_ns, moves, past_bound = [], 0, 0
    for k in range(round(CORRIDOR_LENGTH_M / CORRIDOR_SPEED_MPS * SCAN_RATE_HZ)):
        T_map_scan = Transform2D(k * CORRIDOR_SPEED_MPS / SCAN_RATE_HZ, 0.0, 0.0) @ T_BODY_SCAN
        ranges = simulate_scan(T_map_scan, np.zeros((0, 3)), walls, LIDAR, rng)
        scan = RangeScan(ranges, LIDAR.angle_min, LIDAR.angle_increment, LIDAR.range_min, LIDAR.range_max)
        col0 = grid.col0
        start = time.process_time_ns()
        past_bound += grid.insert_scan(scan, T_map_scan)
        update_ns.append(time.process_time_ns() - start)
        moves += grid.col0 != col0
    publish_ns = []
    for _ in range(5):
        start = time.process_time_ns()
        grid.grid_map()
        publish_ns.append(time.process_time_ns() - start)
    return {
        "scans": len(update_ns),
        "median_ms": 1e-6 * float(np.median(update_ns)),
        "p99_ms": 1e-6 * float(np.percentile(update_ns, 99)),
        "max_ms": 1e-6 * float(np.max(update_ns)),
        "moves": moves,
        "past_bound": past_bound,
        "shape": grid.log_odds.shape,
        "megabytes": grid.nbytes / 1e6,
        "publish_ms": 1e-6 * float(np.median(publish_ns)),
    }


def bound_section(result: dict) -> list[str]:
    return [
        "At the bound: a corridor 3 m wide and 300 m long driven straight at 1 m/s (1500 scans of the same",
        "LiDAR) into a grid that starts at the default bound (`max_size_m` = 100 m), so that it moves toward",
        "the robot (forgetting its far side) every `grow_margin_m` or so; `insert_scan` per scan (a move",
        "copies the cells it keeps), the moves, the scans past the bound, the grid's state and `grid_map`",
        "of the full grid (what slam publishes once per `grid.publish_period_s`).",
        "",
        "| grid (cells) | state (MB) | insert_scan median / p99 / largest (ms) | moves "
        "| scans past the bound | grid_map (ms) |",
        "|---:|---:|---:|---:|---:|---:|",
        f"| {result['shape'][1]} x {result['shape'][0]} | {result['megabytes']:.1f} "
        f"| {result['median_ms']:.3f} / {result['p99_ms']:.2f} / {result['max_ms']:.2f} | {result['moves']} "
        f"| {result['past_bound']} of {result['scans']} | {result['publish_ms']:.0f} |",
        "",
    ]


def measure_slam(seed: int, out_dir: Path) -> dict:
    """The demo's grid at SLAM poses after its two minutes (module docstring), with its SLAM errors."""
    from turtlelib.mapping.grid_map_file import load_grid_map

    run_dir = out_dir / f"seed{seed}"
    run_once(None, seed, DURATION_S, "unknown", run_dir)
    metrics = json.loads((run_dir / "metrics.json").read_text(encoding="utf-8"))
    grid_map = load_grid_map(run_dir / "map.yaml")
    return {
        "seed": seed,
        "ate_m": metrics["ate_rmse_slam_m"],
        "final_m": metrics["final_position_error_slam_m"],
        "shape": grid_map.occupancy.shape,
        "figure": run_dir / "grid.png",
        **accuracy(grid_map),
    }


def slam_section(results: list[dict]) -> list[str]:
    rows = [
        f"| {r['seed']} | {r['ate_m']:.4f} / {r['final_m']:.4f} | {r['shape'][1]} x {r['shape'][0]} "
        f"| {100 * r['boundary_found']:.1f} % of {r['boundary_cells']} "
        f"| {100 * r['free_marked_occupied']:.2f} % "
        f"| {100 * r['free_known_free']:.1f} % of {r['free_cells']} |"
        for r in results
    ]
    return [
        "At SLAM poses (`--slam-seeds`): the demo's own run",
        "(`.venv/bin/python -P -m nuturtle_demo --duration 120 --seed S`, unknown association), its",
        "`map.yaml` + `map.pgm` (slam's keyframes re-rendered at its poses at save, map_server's trinary",
        "values) against the same true geometry.",
        "",
        "| seed | SLAM ATE / final error (m) | grid (cells) | boundary found | free marked occupied "
        "| free known free |",
        "|---:|---:|---:|---:|---:|---:|",
        *rows,
        "",
    ]


def section(results: list[dict], bound: dict, slam_results: list[dict]) -> str:
    threads = os.environ.get("OPENBLAS_NUM_THREADS", "unset")
    versions = f"Python {platform.python_version()}, numpy {np.__version__}"
    machine = f"{platform.machine()}, {os.cpu_count()} cores, {versions}"
    rows = [
        f"| {r['resolution_m']} | {r['shape'][1]} x {r['shape'][0]} | {r['median_ms']:.3f} "
        f"| {r['p99_ms']:.3f} | {r['publish_ms']:.3f} | {r['keyframes']} / {r['render_ms']:.0f} |"
        for r in results
    ]
    quality = [
        f"| {r['resolution_m']} | {100 * r['boundary_found']:.1f} % of {r['boundary_cells']} "
        f"| {100 * r['free_marked_occupied']:.2f} % "
        f"| {100 * r['free_known_free']:.1f} % of {r['free_cells']} "
        f"| {100 * r['rendered']['boundary_found']:.1f} % "
        f"/ {100 * r['rendered']['free_marked_occupied']:.2f} % |"
        for r in results
    ]
    return "\n".join(
        [
            HEADING,
            "",
            "`.venv/bin/python -P bench/grid_update.py --write --figure --slam-seeds 0 1 2`",
            f"(OPENBLAS_NUM_THREADS={threads}; {machine}).",
            "",
            "`turtlelib.OccupancyGrid` (docs/maps.md) on the demo's world scanned by a simulated",
            "LDS-01 (360 beams, 1 cm noise and resolution) at 5 Hz for 120 s along the demo's figure",
            "eight, each scan at its TRUE pose (the grid alone; default `GridConfig`: 4 m to start,",
            "growing by 2 m).",
            "CPU time (`time.process_time_ns`) per call: `insert_scan` per 360-beam scan (target <= 2 ms),",
            "`grid_map` (the int8 grid a node publishes), and re-rendering the kept keyframes (one per",
            "0.1 m or 0.2 rad) into a fresh grid, which a save after a loop closure costs.",
            "",
            "| resolution (m) | grid (cells) | insert_scan median (ms) | p99 (ms) | grid_map (ms) "
            "| keyframes / render (ms) |",
            "|---:|---:|---:|---:|---:|---:|",
            *rows,
            "",
            "Accuracy against the true geometry: true boundary cells (walls and cylinder outlines) with an",
            "occupied cell (>= 65) within one cell (target >= 95 %); true free cells (centre > 1.5 cells",
            "from every boundary) marked occupied (target <= 1 %) and known free (<= 19); the same two",
            "for the grid re-rendered from the keyframes.",
            "",
            "| resolution (m) | boundary found | free marked occupied | free known free "
            "| re-rendered: boundary / free occupied |",
            "|---:|---:|---:|---:|---:|",
            *quality,
            "",
            *bound_section(bound),
            *(slam_section(slam_results) if slam_results else []),
        ]
    )


def figure(result: dict, path: Path) -> None:
    from nuturtle_eval.plots import draw_grid, new_figure

    fig = new_figure(6.0, 6.0)
    ax = fig.add_subplot()
    grid_map = result["grid"].grid_map()
    draw_grid(ax, grid_map)
    res = grid_map.resolution_m
    path_xy = np.array([[T.x, T.y] for T in result["poses"]])
    ax.plot(path_xy[:, 0], path_xy[:, 1], color="tab:blue", lw=0.8, label="path (true)")
    ax.scatter(CYLINDERS[:, 0], CYLINDERS[:, 1], s=60, facecolors="none", edgecolors="tab:red",
               label="true cylinders")  # fmt: skip
    ax.set_xlim(-2.8, 2.8)
    ax.set_ylim(-2.8, 2.8)
    ax.set_xlabel("x (m)")
    ax.set_ylabel("y (m)")
    ax.set_title(f"occupancy grid, {res} m cells, demo world, 120 s at true poses")
    ax.legend(loc="upper right", fontsize=8)
    fig.savefig(path, dpi=110)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--write", action="store_true", help="update docs/benchmarks.md")
    parser.add_argument("--figure", action="store_true", help="draw docs/figures/grid_demo_world.png")
    parser.add_argument("--slam-seeds", type=int, nargs="*", default=[], help="demo seeds at SLAM poses")
    parser.add_argument("--out", type=Path, default=Path("out/grid_slam"), help="the demo runs' folder")
    arguments = parser.parse_args()
    results = [measure(0.05), measure(0.025)]
    bound = measure_bound()
    slam_results = [measure_slam(seed, arguments.out) for seed in arguments.slam_seeds]
    text = section(results, bound, slam_results)
    print(text)
    if arguments.write:
        write_section(HEADING, text, ROOT / "docs" / "benchmarks.md")
    if arguments.figure:
        figure(results[0], ROOT / "docs" / "figures" / "grid_demo_world.png")
        if slam_results:
            shutil.copyfile(slam_results[0]["figure"], ROOT / "docs" / "figures" / "grid_demo_slam.png")


if __name__ == "__main__":
    main()
