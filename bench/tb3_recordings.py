"""Benchmark: TurtleBot3 recordings of ROBOTIS' Gazebo `turtlebot3_world` replayed into landmarks and slam,
against the issue's target: every cylinder that comes in range (and in sight) mapped once, none spurious,
ATE <= 2 cm against the recording's truth.

Each BAG (a rosbag2 directory, a single .mcap / .db3, or a ROS 1 .bag) is replayed with
``python -m nuturtle_tools.replay`` (docs/replay.md), one after the other in this process, with its
``/odom`` as the truth (Gazebo's diff-drive plugin reports the model's true pose there), the true cylinders
of nusim's turtlebot3_world (``--world``), outputs in --out/<k>-<bag name>/. Options the replay takes that
are not this script's (e.g. ``--motion-source odom``, the robot model) are passed on to every replay.
Prints one markdown row per recording.

Usage: python -P bench/tb3_recordings.py BAG [BAG ...] [--truth-topic /odom] [--world FILE] [--out DIR]
       [replay options]
"""

from __future__ import annotations

import os

os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")  # before numpy loads OpenBLAS

import argparse
import contextlib
import io
import json
from pathlib import Path

from nuturtle_tools.replay import main as replay

WORLD = Path(__file__).resolve().parents[1] / "nusim" / "config" / "turtlebot3_world.yaml"
ATE_TARGET_M = 0.02
HEADER = (
    "| recording | scans played / refused | cylinders true / in range / mapped | unmapped / duplicate / "
    "spurious | ATE RMSE (m) | final error (m) | target | replay wall (s) / bag (s) |"
)


def row(name: str, m: dict) -> str:
    """One markdown row of a replay's metrics.json."""
    met = (
        m["landmarks_in_range_unmapped"] == m["landmarks_duplicate"] == m["landmarks_spurious"] == 0
        and m["ate_rmse_slam_m"] <= ATE_TARGET_M
    )
    return (
        f"| {name} | {m['scans_played']} / {m.get('scans_refused_by_landmarks', 0)} | "
        f"{m['landmarks_true']} / {m['landmarks_in_range']} / {m['landmarks_mapped']} | "
        f"{m['landmarks_in_range_unmapped']} / {m['landmarks_duplicate']} / {m['landmarks_spurious']} | "
        f"{m['ate_rmse_slam_m']:.4f} | {m['final_position_error_slam_m']:.4f} | "
        f"{'met' if met else 'missed'} | {m['replay_wall_seconds']:.1f} / {m['bag_seconds']:.1f} |"
    )


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("bags", type=Path, nargs="+", metavar="BAG")
    parser.add_argument("--truth-topic", default="/odom", help="the recording's ground truth")
    parser.add_argument("--world", type=Path, default=WORLD, help="nusim world file of the true cylinders")
    parser.add_argument("--out", type=Path, default=Path("out/tb3_recordings"))
    args, replay_options = parser.parse_known_args()
    rows = []
    for k, bag in enumerate(args.bags):
        out = args.out / f"{k}-{bag.name}"
        options = [
            str(bag),
            "--out",
            str(out),
            "--truth-topic",
            args.truth_topic,
            "--params",
            str(args.world),
        ]
        with contextlib.redirect_stdout(io.StringIO()) as summary:
            code = replay([*options, "--no-progress", *replay_options])
        if code != 0:
            rows.append(f"| {bag.name} | replay failed (exit code {code}) |")
            continue
        metrics = json.loads((out / "metrics.json").read_text(encoding="utf-8"))
        if "ate_rmse_slam_m" not in metrics:
            print(summary.getvalue())
            rows.append(f"| {bag.name} | no accuracy metrics (no truth on {args.truth_topic}?) |")
            continue
        rows.append(row(bag.name, metrics))
    print(HEADER)
    print("|---|---:|---:|---:|---:|---:|---|---:|")
    print("\n".join(rows))


if __name__ == "__main__":
    main()
