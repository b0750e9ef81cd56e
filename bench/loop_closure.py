"""Benchmark: LiDAR odometry with and without loop closure on the real-building recordings
(shared/datasets/radish_offices: ACES, FHW), offline, scored against GMapping's corrected poses
(``/ground_truth``) as docs/real_data.md describes: relative pose error over 1-10 m of path and ATE after a
rigid alignment (nuturtle_eval.metrics).

Each scan is registered by :class:`turtlelib.LidarOdometry` (the recorded ``/odom`` as its prior) and fed to
:class:`turtlelib.smoothing.loop_closure.LoopClosure`. "odometry" is LiDAR odometry's own poses; "closed"
is every scan placed by the final graph, at its keyframe's correction (``map_from_odom(k) T_odom_body``,
``k`` the newest keyframe at or before the scan); "online" is each scan at the correction known when it was
taken (what a live system publishes). Prints one markdown row per recording and range: RPE and ATE of
each, loops accepted and refused (by reason), CPU time per scan (odometry, loop closure), and the
agreement of the grid of every scan at its "closed" pose with the scans at the reference's poses
(nuturtle_eval.grid_agreement; the closed poses rigidly aligned to the reference first, as this run starts
in the odometry's frame, not the reference's): the map the graph gives, in seconds rather than a replay's
minutes.

Usage: python -P bench/loop_closure.py [FOLDER ...] [--max-range-m 3.5]
"""

from __future__ import annotations

import argparse
import math
import time
from collections import Counter
from pathlib import Path

import numpy as np
from rosbags.highlevel import AnyReader

from nuturtle_eval.grid_agreement import grid_agreement, occupied_cells, reference_cells, scan_endpoints
from nuturtle_eval.metrics import PoseSeries, align_se2, ate_rmse_aligned
from nuturtle_eval.relative_error import relative_pose_error
from turtlelib import LidarOdometry, LidarOdometryConfig, RangeScan, Transform2D, TwistNoise
from turtlelib.estimation.lidar_odometry import scan_points
from turtlelib.geometry.pose_buffer import PoseBuffer
from turtlelib.mapping.occupancy_grid import GridConfig, OccupancyGrid
from turtlelib.smoothing.loop_closure import LoopClosure, Verdict

DATASETS = Path(__file__).resolve().parents[2] / "shared" / "datasets" / "radish_offices"
DEFAULT_FOLDERS = (DATASETS / "aces", DATASETS / "fhw")
# the recorded odometry's noise as LiDAR odometry's prior (a Pioneer's wheels)
NOISE = TwistNoise(
    forward_m2_per_m=0.01**2,
    lateral_m2_per_m=0.005**2,
    heading_rad2_per_m=0.01**2,
    heading_rad2_per_rad=0.02**2,
)


def _yaw(q) -> float:
    return math.atan2(2.0 * (q.w * q.z + q.x * q.y), 1.0 - 2.0 * (q.y * q.y + q.z * q.z))


def read(folder: Path, max_range_m: float | None):
    """``(odom, reference, scans)``: stamped poses (ns, Transform2D) and stamped ``RangeScan``s."""
    odom, reference, scans = [], [], []
    with AnyReader([folder]) as reader:
        for connection, _, raw in reader.messages():
            m = reader.deserialize(raw, connection.msgtype)
            t_ns = m.header.stamp.sec * 10**9 + m.header.stamp.nanosec
            if connection.topic in ("/odom", "/ground_truth"):
                p, q = m.pose.pose.position, m.pose.pose.orientation
                (odom if connection.topic == "/odom" else reference).append(
                    (t_ns, Transform2D(p.x, p.y, _yaw(q)))
                )
            elif connection.topic == "/scan":
                range_max = m.range_max if max_range_m is None else min(m.range_max, max_range_m)
                ranges = np.array(m.ranges, dtype=float)
                scans.append(
                    (t_ns, RangeScan(ranges, m.angle_min, m.angle_increment, m.range_min, range_max))
                )
    return odom, reference, scans


def series(stamps: list[int], poses: list[Transform2D]) -> PoseSeries:
    return PoseSeries(np.array(stamps) / 1e9, np.array([T.as_array() for T in poses]))


def map_agreement(
    stamps: list[int], poses: list[Transform2D], scans: list[RangeScan], truth: PoseSeries
) -> tuple[float, float]:
    """``(found, unexplained)``: the grid of ``scans`` at ``poses`` (aligned to ``truth`` first) against the
    scans at ``truth``'s poses."""
    estimate = series(stamps, poses)
    T_ref_est = align_se2(estimate.poses[:, :2], truth.interpolate(estimate.t_s)[:, :2])
    grid = OccupancyGrid(GridConfig(max_size_m=300.0))
    for T, scan in zip(poses, scans, strict=True):
        grid.insert_scan(scan, T_ref_est @ T)
    reference = reference_cells(scan_endpoints(zip(estimate.t_s, scans, strict=True), truth, Transform2D()))
    result = grid_agreement(reference, occupied_cells(grid.grid_map()))
    return result.found_fraction, result.unexplained_fraction


def run(folder: Path, max_range_m: float | None) -> str:
    odom, reference, scans = read(folder, max_range_m)
    buffer = PoseBuffer(10**7)
    for t_ns, T in odom:
        buffer.add(t_ns, T)
    lidar_odometry = LidarOdometry(LidarOdometryConfig(), NOISE)
    loops = LoopClosure()
    stamps, T_odom, online, keyframe_of, used = [], [], [], [], []
    cpu_odometry = cpu_loops = 0.0
    for t_ns, scan in scans:
        T_input = buffer.at(t_ns)
        if T_input is None:
            continue
        start = time.process_time()
        step = lidar_odometry.step(t_ns, T_input, scan, Transform2D())
        middle = time.process_time()
        loops.add_step(step, scan_points(scan, Transform2D()))
        cpu_odometry += middle - start
        cpu_loops += time.process_time() - middle
        stamps.append(t_ns)
        T_odom.append(step.T_odom_body)
        online.append(loops.map_from_odom() @ step.T_odom_body)
        keyframe_of.append(len(loops.keyframes) - 1)
        used.append(scan)
    closed = [loops.map_from_odom(k) @ T for k, T in zip(keyframe_of, T_odom, strict=True)]
    truth = series([t for t, _ in reference], [T for _, T in reference])
    verdicts = Counter(c.verdict for c in loops.candidates)
    refused = {v.value: n for v, n in verdicts.items() if v not in (Verdict.ACCEPTED, Verdict.HELD)}
    cells = []
    for poses in (T_odom, online, closed):
        estimate = series(stamps, poses)
        rpe = relative_pose_error(estimate, truth)
        cells.append(
            f"{rpe.translation_m:.3f} / {rpe.rotation_deg:.2f} | {ate_rmse_aligned(estimate, truth):.2f}"
        )
    found, unexplained = map_agreement(stamps, closed, used, truth)
    n = len(stamps)
    range_text = "full" if max_range_m is None else f"{max_range_m:g} m"
    return (
        f"| {folder.name} | {range_text} | {n} | {len(loops.keyframes)} | {' | '.join(cells)} | "
        f"{verdicts[Verdict.ACCEPTED]} | {sum(refused.values())} {dict(sorted(refused.items()))} | "
        f"{1000 * cpu_odometry / n:.0f} | {1000 * cpu_loops / n:.0f} | {found:.1%} | {unexplained:.1%} |"
    )


HEADER = (
    "| recording | range | scans | keyframes | odometry RPE (m / deg) | odometry ATE (m) | online RPE | "
    "online ATE | closed RPE | closed ATE | loops accepted | refused (by reason) | CPU odometry (ms/scan) | "
    "CPU loops (ms/scan) | closed grid found | closed grid unexplained |\n"
    "|---|---|---:|---:|---:|---:|---:|---:|---:|---:|---:|---|---:|---:|---:|---:|"
)


def main() -> None:
    parser = argparse.ArgumentParser(
        description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter
    )
    parser.add_argument("folders", nargs="*", type=Path, default=list(DEFAULT_FOLDERS))
    parser.add_argument("--max-range-m", type=float, default=None, help="cut the ranges (e.g. 3.5)")
    args = parser.parse_args()
    print(HEADER, flush=True)
    for folder in args.folders:
        print(run(folder, args.max_range_m), flush=True)


if __name__ == "__main__":
    main()
