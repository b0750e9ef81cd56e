"""Benchmark: the simulation + SLAM demo over several seeds, in both data-association modes.

Each run is `python -m nuturtle_demo --seed S --association A` (the default world and route, two minutes of
robot time unless --duration says otherwise), run one after the other in this process; every run's
outputs stay in --out/<association>-seed<S>/. Prints one markdown row per run and a summary row per mode
(mean and worst) with the demo's targets: SLAM final position error <= 2 cm and heading <= 0.02 rad,
odometry final position error >= 20 cm, every cylinder that came in range mapped exactly once, pose NEES
inside its 95% band >= 90% of the time, wall time <= half the simulated time.

Usage: python bench/seeds.py [--seeds 5] [--duration 120] [--out out/seeds]
"""

from __future__ import annotations

import os

os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")  # before numpy loads OpenBLAS

import argparse
import platform
from pathlib import Path

import numpy as np

from nuturtle_demo.run import ASSOCIATIONS, DemoOptions, run_demo

HEADER = (
    "run", "SLAM pos (m)", "SLAM heading (rad)", "odom pos (m)", "ATE SLAM / odom (m)",
    "landmarks in range / mapped / paired", "landmark RMSE (m)", "NEES in 95% band", "wall / sim (s)",
    "targets met",
)  # fmt: skip


def meets_targets(m: dict) -> bool:
    return (
        m["final_position_error_slam_m"] <= 0.02
        and m["final_heading_error_slam_rad"] <= 0.02
        and m["final_position_error_odom_m"] >= 0.2
        and m["landmarks_in_range_unmapped"] == 0
        and m["landmarks_duplicate"] == 0
        and m["nees_pose_within_95_fraction"] >= 0.9
        and m["wall_seconds"] <= 0.5 * m["sim_seconds"]
    )


def row(label: str, m: dict, met: str) -> str:
    cells = (
        label,
        f"{m['final_position_error_slam_m']:.4f}",
        f"{m['final_heading_error_slam_rad']:.4f}",
        f"{m['final_position_error_odom_m']:.3f}",
        f"{m['ate_rmse_slam_m']:.4f} / {m['ate_rmse_odom_m']:.3f}",
        f"{m['landmarks_in_range']:g} / {m['landmarks_mapped']:g} / {m['landmarks_paired']:g}",
        f"{m['landmark_rmse_m']:.4f}",
        f"{m['nees_pose_within_95_fraction']:.3f}",
        f"{m['wall_seconds']:.1f} / {m['sim_seconds']:.1f}",
        met,
    )
    return "| " + " | ".join(cells) + " |"


def summary(runs: list[dict], worst: str) -> dict:
    """Per key, the mean (worst = 'mean') or the worst value over the runs."""
    higher_is_better = {"final_position_error_odom_m", "nees_pose_within_95_fraction", "landmarks_paired"}
    result = {}
    for key in runs[0]:
        values = np.array([r[key] for r in runs], dtype=float) if not isinstance(runs[0][key], list) else None
        if values is None:
            continue
        if worst == "mean":
            result[key] = float(np.mean(values))
        else:
            result[key] = float(np.min(values) if key in higher_is_better else np.max(values))
    return result


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--seeds", type=int, default=5)
    parser.add_argument("--duration", type=float, default=120.0)
    parser.add_argument("--out", type=Path, default=Path("out/seeds"))
    args = parser.parse_args()
    print(
        f"{args.seeds} seeds x {len(ASSOCIATIONS)} association modes, {args.duration:g} s of robot time each "
        f"(OPENBLAS_NUM_THREADS=1; {platform.machine()}, {os.cpu_count()} cores, "
        f"Python {platform.python_version()})\n"
    )
    print("| " + " | ".join(HEADER) + " |")
    print("|" + "---|" * len(HEADER))
    for association in ASSOCIATIONS:
        runs = []
        for seed in range(args.seeds):
            options = DemoOptions(
                association=association, seed=seed, duration_s=args.duration,
                out_dir=args.out / f"{association}-seed{seed}", progress=False,
            )  # fmt: skip
            metrics = run_demo(options).metrics.as_dict()
            runs.append(metrics)
            print(
                row(f"{association}, seed {seed}", metrics, "yes" if meets_targets(metrics) else "no"),
                flush=True,
            )
        met = sum(meets_targets(m) for m in runs)
        print(row(f"**{association}, mean**", summary(runs, "mean"), f"{met}/{len(runs)}"))
        print(row(f"**{association}, worst**", summary(runs, "worst"), ""))


if __name__ == "__main__":
    main()
