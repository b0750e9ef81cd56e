"""Occupancy grid of the shared Gazebo recording at its recorded poses, with a figure.

/work/shared/datasets/tb3_gazebo_burger (see its README): a Burger in Gazebo's turtlebot3_world for 27.7 s.
Its /odom is Gazebo's true pose in the world frame, so each /scan is inserted at /odom's pose at the scan's
stamp (turtlelib.geometry.pose_buffer interpolates between odometry messages) composed with the Burger's LiDAR
mount: the grid mapping alone, against the world's known cylinders (nine of radius 0.15 m at x, y in
{-1.1, 0, 1.1}).

Per cylinder: the occupied cells (>= 65) within one cell of its outline, and whether it was in range;
occupied cells far from every cylinder are the walls' (drawn in the figure).

At SLAM poses (``--replay DIR``): the grid slam made in a replay of the recording (``python -P -m
nuturtle_tools.replay BAG --truth-topic /odom --params nusim/config/turtlebot3_world.yaml --out DIR``:
each scan at slam's pose at its stamp, re-rendered from its keyframes), read from ``DIR/map.yaml``, counted
the same way.

Usage: python bench/grid_gazebo.py [BAG] [--replay DIR] [--write]   (--write replaces the "## Occupancy
grid: Gazebo recording" section of docs/benchmarks.md, draws docs/figures/grid_gazebo_burger.png and, with
--replay, copies DIR/grid.png to docs/figures/grid_gazebo_slam.png).
"""

from __future__ import annotations

import argparse
import math
import shutil
import sys
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parent.parent
sys.path.insert(0, str(ROOT / "bench"))  # bench_docs

from bench_docs import write_section  # noqa: E402

from turtlelib import GridConfig, GridMap, OccupancyGrid, RangeScan, Transform2D  # noqa: E402
from turtlelib.geometry.pose_buffer import PoseBuffer  # noqa: E402

HEADING = "## Occupancy grid: Gazebo recording"
BAG = Path("/work/shared/datasets/tb3_gazebo_burger")
CYLINDERS = np.array([[x, y] for x in (-1.1, 0.0, 1.1) for y in (-1.1, 0.0, 1.1)])
RADIUS_M = 0.15
FIGURE = ROOT / "docs" / "figures" / "grid_gazebo_burger.png"
SLAM_FIGURE = ROOT / "docs" / "figures" / "grid_gazebo_slam.png"


def stamp_ns(header) -> int:
    return header.stamp.sec * 10**9 + header.stamp.nanosec


def read(bag: Path) -> tuple[PoseBuffer, list[tuple[int, RangeScan]]]:
    """The /odom poses (world frame) and the /scans with their stamps."""
    from rosbags.typesys import Stores, get_typestore

    from nuturtle_tools.bag_source import BagSource

    typestore = get_typestore(Stores.ROS2_JAZZY)
    poses = PoseBuffer(100_000)
    scans = []
    with BagSource(bag) as source:
        for message in source.messages(["/odom", "/scan"]):
            msg = typestore.deserialize_cdr(message.data, message.type_name)
            if message.topic == "/odom":
                q = msg.pose.pose.orientation
                yaw = math.atan2(2.0 * (q.w * q.z + q.x * q.y), 1.0 - 2.0 * (q.y * q.y + q.z * q.z))
                p = msg.pose.pose.position
                poses.add(stamp_ns(msg.header), Transform2D(p.x, p.y, yaw))
            else:
                scan = RangeScan(msg.ranges, msg.angle_min, msg.angle_increment, msg.range_min, msg.range_max)
                scans.append((stamp_ns(msg.header), scan))
    return poses, scans


def measure(bag: Path) -> dict:
    from nuturtle_description.robot_params import burger_params

    T_body_scan = burger_params().T_body_scan
    poses, scans = read(bag)
    grid = OccupancyGrid(GridConfig())
    used, path, update_ns = 0, [], []
    for stamp, scan in scans:
        T_world_body = poses.at(stamp)
        if T_world_body is None:
            continue
        start = time.process_time_ns()
        grid.insert_scan(scan, T_world_body @ T_body_scan)
        update_ns.append(time.process_time_ns() - start)
        used += 1
        path.append([T_world_body.x, T_world_body.y])
    path = np.array(path)
    nearest_path = np.linalg.norm(path[:, None, :] - CYLINDERS[None], axis=2).min(axis=0)
    return {
        "scans": len(scans),
        "used": used,
        "median_ms": 1e-6 * float(np.median(update_ns)),
        "nearest_path_m": nearest_path,
        **outline_counts(grid.grid_map()),
        "grid": grid,
        "path": path,
    }


def outline_counts(grid_map: GridMap) -> dict:
    """Occupied cells (>= 65) of ``grid_map``: in all, within one cell of a cylinder's outline (in all and
    per cylinder), inside a cylinder."""
    res = grid_map.resolution_m
    rows, cols = np.nonzero(grid_map.occupancy >= 65)
    x0, y0 = grid_map.origin.x, grid_map.origin.y
    occupied = np.column_stack([x0 + (cols + 0.5) * res, y0 + (rows + 0.5) * res])
    distance = np.linalg.norm(occupied[:, None, :] - CYLINDERS[None], axis=2)
    # a cell centre is within one cell of a circle when | |c - m| - r | <= res (half a diagonal + slack)
    on_outline = np.abs(distance - RADIUS_M) <= res
    return {
        "cells_per_cylinder": on_outline.sum(axis=0),
        "occupied": len(occupied),
        "near_cylinders": int(on_outline.any(axis=1).sum()),
        "inside_cylinders": int((distance < RADIUS_M - res).any(axis=1).sum()),
    }


def section(result: dict, slam: dict | None) -> str:
    slam_counts = slam["cells_per_cylinder"] if slam is not None else [None] * len(CYLINDERS)
    rows = [
        f"| ({x:+.1f}, {y:+.1f}) | {d:.2f} | {n} |" + (f" {m} |" if slam is not None else "")
        for (x, y), d, n, m in zip(
            CYLINDERS, result["nearest_path_m"], result["cells_per_cylinder"], slam_counts, strict=True
        )
    ]
    slam_text = []
    if slam is not None:
        slam_text = [
            "At SLAM poses (`--replay DIR`: the grid slam saved in",
            "`.venv/bin/python -P -m nuturtle_tools.replay tb3_gazebo_burger/ --truth-topic /odom --params",
            "nusim/config/turtlebot3_world.yaml --out DIR`, its",
            f"keyframes at slam's poses): {slam['occupied']} occupied cells, {slam['near_cylinders']} within",
            f"one cell of a cylinder's outline, {slam['inside_cylinders']} inside a cylinder (last column",
            "above; the figure below).",
            "",
            "![occupancy grid of the Gazebo recording at SLAM poses](figures/grid_gazebo_slam.png)",
            "",
        ]
    return "\n".join(
        [
            HEADING,
            "",
            "`.venv/bin/python -P bench/grid_gazebo.py --replay DIR --write`: `turtlelib.OccupancyGrid`",
            "(0.05 m, default `GridConfig`)",
            "on the shared Gazebo recording (`/work/shared/datasets/tb3_gazebo_burger`, 27.7 s in",
            "turtlebot3_world), each `/scan` at `/odom`'s pose at its stamp (Gazebo's true pose) composed",
            f"with the Burger's LiDAR mount ({result['used']} of {result['scans']} scans within the",
            f"odometry's span), {1e3 * result['median_ms']:.0f} us of CPU per update (median).",
            "",
            f"{result['occupied']} occupied cells: {result['near_cylinders']} within one cell of a",
            f"cylinder's outline, {result['inside_cylinders']} inside a cylinder (more than a cell within",
            "its outline), the rest on the walls. Per cylinder (radius 0.15 m), the occupied cells on",
            "its outline:",
            "",
            "| cylinder (m) | closest approach of the path (m) | occupied cells on the outline |"
            + (" at SLAM poses |" if slam is not None else ""),
            "|---|---:|---:|" + ("---:|" if slam is not None else ""),
            *rows,
            "",
            "![occupancy grid of the Gazebo recording](figures/grid_gazebo_burger.png)",
            "",
            *slam_text,
        ]
    )


def figure(result: dict, path: Path) -> None:
    from matplotlib.patches import Circle

    from nuturtle_eval.plots import draw_grid, new_figure

    fig = new_figure(6.0, 6.0)
    ax = fig.add_subplot()
    draw_grid(ax, result["grid"].grid_map())
    ax.plot(result["path"][:, 0], result["path"][:, 1], color="tab:blue", lw=1.2, label="path (/odom)")
    for k, (x, y) in enumerate(CYLINDERS):
        circle = Circle((x, y), RADIUS_M, fill=False, color="tab:red", lw=1.0)
        ax.add_patch(circle)
        if k == 0:
            circle.set_label("true cylinders")
    ax.set_xlim(-2.8, 2.8)
    ax.set_ylim(-2.8, 2.8)
    ax.set_aspect("equal")
    ax.set_xlabel("x (m, world)")
    ax.set_ylabel("y (m, world)")
    ax.set_title("occupancy grid, 0.05 m, turtlebot3_world recording at /odom poses", fontsize=10)
    ax.legend(loc="upper right", fontsize=8)
    fig.savefig(path, dpi=110)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("bag", nargs="?", type=Path, default=BAG)
    parser.add_argument("--replay", type=Path, help="a replay's output folder (its map.yaml, grid.png)")
    parser.add_argument("--write", action="store_true", help="update docs/benchmarks.md and the figure")
    arguments = parser.parse_args()
    result = measure(arguments.bag)
    slam = None
    if arguments.replay is not None:
        from turtlelib.mapping.grid_map_file import load_grid_map

        slam = outline_counts(load_grid_map(arguments.replay / "map.yaml"))
    text = section(result, slam)
    print(text)
    if arguments.write:
        write_section(HEADING, text, ROOT / "docs" / "benchmarks.md")
        figure(result, FIGURE)
        if arguments.replay is not None:
            shutil.copyfile(arguments.replay / "grid.png", SLAM_FIGURE)


if __name__ == "__main__":
    main()
