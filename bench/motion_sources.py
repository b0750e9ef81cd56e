"""Benchmark: slam's two motion sources on the same simulated runs, joint_states (wheel angles) against odom
(the odometry node's poses, `motion_source: odom`, twist noise matched to the same wheel slip).

Each seed runs the demo twice, once per motion source (default world and route, two minutes of robot time
unless --duration says otherwise), one after the other in this process, each in its own DDS world
(docs/demo.md); outputs stay in --out/<source>-seed<S>/. Prints one markdown row per seed and the means,
with the ratio odom / joint_states of the SLAM accuracy figures (the issue's target: within 20 %).

Usage: python bench/motion_sources.py [--seeds 5] [--association unknown] [--duration 120] [--out DIR]
"""

from __future__ import annotations

import os

os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")  # before numpy loads OpenBLAS

import argparse
from pathlib import Path

import numpy as np

from nuturtle_demo.run import ASSOCIATIONS, DemoOptions, run_demo

SOURCES = ("joint_states", "odom")
KEYS = (
    ("final_position_error_slam_m", "final pos (m)"),
    ("ate_rmse_slam_m", "ATE (m)"),
    ("landmark_rmse_m", "landmark RMSE (m)"),
    ("nees_pose_within_95_fraction", "NEES in band"),
)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--seeds", type=int, default=5)
    parser.add_argument("--association", choices=ASSOCIATIONS, default="unknown")
    parser.add_argument("--duration", type=float, default=120.0)
    parser.add_argument("--out", type=Path, default=Path("out/motion_sources"))
    args = parser.parse_args()
    results: dict[str, list[dict]] = {source: [] for source in SOURCES}
    header = ["seed"] + [f"{label} {source}" for _, label in KEYS for source in SOURCES]
    print("| " + " | ".join(header) + " |")
    print("|" + "---|" * len(header))
    for seed in range(args.seeds):
        for source in SOURCES:
            options = DemoOptions(
                association=args.association, seed=seed, duration_s=args.duration, motion_source=source,
                out_dir=args.out / f"{source}-seed{seed}", progress=False,
            )  # fmt: skip
            results[source].append(run_demo(options).metrics.as_dict())
        cells = [f"{results[source][-1][key]:.4f}" for key, _ in KEYS for source in SOURCES]
        print(f"| {seed} | " + " | ".join(cells) + " |", flush=True)
    means = {
        source: {key: float(np.mean([m[key] for m in results[source]])) for key, _ in KEYS}
        for source in SOURCES
    }
    cells = [f"{means[source][key]:.4f}" for key, _ in KEYS for source in SOURCES]
    print("| mean | " + " | ".join(cells) + " |")
    for key, label in KEYS[:3]:
        print(f"{label}: odom / joint_states = {means['odom'][key] / means['joint_states'][key]:.3f}")


if __name__ == "__main__":
    main()
