"""Benchmark: the real-building recordings (shared/datasets/radish_offices: ACES, FHW) replayed into
landmarks and slam the way a user would, scored against GMapping's corrected poses as docs/real_data.md
describes: ATE after a rigid alignment, relative pose error over 1-10 m of path, the grid's agreement with
the scans placed at the reference poses, for SLAM and for its own odometry.

Each folder is replayed by ``python -P -m nuturtle_tools.replay FOLDER --motion-source odom --truth-topic
/ground_truth --params P`` in its own process (docs/replay.md), P the parameters these recordings need (the
SICK at the base centre, a Pioneer's speeds, a building-sized grid), outputs in --out/<name>/ (metrics.json,
estimate.tum, odometry.tum, reference.tum for evo, map.yaml, grid.png, ...) and its printout in
--out/<name>.log. Prints one markdown table and writes it to --out/results.md.

Usage: python -P bench/radish_offices.py [FOLDER ...] [--max-range-m 3.5] [--out DIR] [--rate R]
       [--no-scan-registration] [--loop-closure] [--smooth]
"""

from __future__ import annotations

import argparse
import json
import subprocess
import sys
import time
from pathlib import Path

import yaml

DATASETS = Path(__file__).resolve().parents[2] / "shared" / "datasets" / "radish_offices"
DEFAULT_FOLDERS = (DATASETS / "aces", DATASETS / "fhw")
# the SICK sits at the base centre; the robot drives faster than a TurtleBot3; the buildings are ~100 m
PARAMS = {
    "slam": {
        "ros__parameters": {
            "lidar_x": 0.0,
            "max_linear_speed": 1.5,
            "max_angular_speed": 3.0,
            "grid": {"max_size_m": 300.0},
        }
    },
    "landmarks": {"ros__parameters": {"lidar_x": 0.0}},
}
HEADER = (
    "| recording | estimate | ATE aligned (m) | RPE 1-10 m (m) | RPE 1-10 m (deg) | grid found | "
    "grid unexplained | landmarks | NEES median | wall (s) | real-time factor |\n"
    "|---|---|---:|---:|---:|---:|---:|---:|---:|---:|---:|"
)


def _figure(value: float | None, fmt: str) -> str:
    return "n/a" if value is None else fmt.format(value)


def _estimate(name: str, label: str, m: dict) -> list[str]:
    """The accuracy cells of SLAM's estimate in the metrics ``m`` (the replay's, or its smoothed run's)."""
    grid = [_figure(m.get(k), "{:.1%}") for k in ("grid_found_fraction", "grid_unexplained_fraction")]
    return [
        name, label, _figure(m["ate_rmse_aligned_slam_m"], "{:.3f}"),
        _figure(m["rpe_translation_slam_m"], "{:.3f}"), _figure(m["rpe_rotation_slam_deg"], "{:.2f}"), *grid,
        str(m["landmarks_mapped"]),
    ]  # fmt: skip


def rows(name: str, m: dict, wall_s: float) -> list[str]:
    """SLAM's row (live, then smoothed with --smooth) and its odometry's of one replay's metrics.json
    (``m``), replayed in ``wall_s``."""
    if "rpe_translation_slam_m" not in m:
        return [f"| {name} | (no accuracy metrics: see {name}/metrics.json) |" + " |" * 9]
    pace = f"{m['bag_seconds'] / wall_s:.1f}x"
    table = [[*_estimate(name, "SLAM", m), _figure(m["nees_pose_median"], "{:.1f}"), f"{wall_s:.1f}", pace]]
    smoothed = m.get("smoothed", {})
    if "rpe_translation_slam_m" in smoothed:
        table.append([*_estimate(name, "SLAM, smoothed", smoothed), "", "", ""])
    table.append([
        name, "odometry", _figure(m["ate_rmse_aligned_odom_m"], "{:.3f}"),
        _figure(m["rpe_translation_odom_m"], "{:.3f}"), _figure(m["rpe_rotation_odom_deg"], "{:.2f}"),
        "", "", "", "", "", "",
    ])  # fmt: skip
    return ["| " + " | ".join(cells) + " |" for cells in table]


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("folders", type=Path, nargs="*", default=list(DEFAULT_FOLDERS), metavar="FOLDER")
    parser.add_argument("--out", type=Path, default=Path("out/radish_offices"))
    parser.add_argument(
        "--max-range-m",
        type=float,
        default=None,
        help="cut the scans to this range, as an LDS-01 (3.5) would see the buildings",
    )
    parser.add_argument("--rate", type=float, default=None, help="the replay's --rate (default: as fast)")
    parser.add_argument(
        "--no-scan-registration",
        dest="scan_registration",
        action="store_false",
        help="slam with scan_registration: false (the motion input alone between landmarks)",
    )
    parser.add_argument("--loop-closure", action="store_true", help="slam with loop_closure: true")
    parser.add_argument(
        "--smooth",
        action="store_true",
        help="the replay's --smooth: the whole run smoothed too, a row of its own",
    )
    args = parser.parse_args()  # fmt: skip
    args.out.mkdir(parents=True, exist_ok=True)
    params = args.out / "params.yaml"
    slam = {
        **PARAMS["slam"]["ros__parameters"],
        "scan_registration": args.scan_registration,
        "loop_closure": args.loop_closure,
    }
    chosen = {**PARAMS, "slam": {"ros__parameters": slam}}
    params.write_text(yaml.safe_dump(chosen, sort_keys=False), encoding="utf-8")
    table = [HEADER]
    for folder in args.folders:
        name = folder.name
        command = [
            sys.executable, "-P", "-m", "nuturtle_tools.replay", str(folder), "--motion-source", "odom",
            "--truth-topic", "/ground_truth", "--params", str(params), "--out", str(args.out / name),
            "--no-progress",
        ]  # fmt: skip
        if args.max_range_m is not None:
            command += ["--max-range-m", str(args.max_range_m)]
        if args.rate is not None:
            command += ["--rate", str(args.rate)]
        if args.smooth:
            command.append("--smooth")
        print(f"replaying {folder} ...", file=sys.stderr, flush=True)
        start = time.monotonic()
        # the replay's report and slam's warnings, kept beside the outputs
        with (args.out / f"{name}.log").open("w", encoding="utf-8") as log:
            subprocess.run(command, check=True, stdout=log, stderr=subprocess.STDOUT)
        wall_s = time.monotonic() - start
        metrics = json.loads((args.out / name / "metrics.json").read_text(encoding="utf-8"))
        table += rows(name, metrics, wall_s)
    text = "\n".join(table)
    (args.out / "results.md").write_text(text + "\n", encoding="utf-8")
    print(text)


if __name__ == "__main__":
    main()
