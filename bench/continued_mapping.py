"""Benchmark: mapping over two sessions against one run of the same route (docs/maps.md, "Continuing over
sessions").

Per world: session 1 maps the first part of the figure eight and saves the map (landmarks and grid);
session 2 starts where the route stopped (`route_start_s`, the robot placed on the route there), continues
the saved map and saves it again; one single run drives the same whole route. Seed 0, unknown association;
outputs in --out/<world>/{session1,session2,single}/. Prints, per world, one markdown row per run: the
landmarks (mapped, spurious, RMSE), the SLAM pose at the end and along the run (session 2's run only) and
the grid (the run's final grid scored against the walls its whole route saw: both sessions' for session 2,
nuturtle_eval.grid_score), then whether session 1's landmarks were kept (ids, how far they moved) and the
closest pair of landmarks in the final map (a duplicate would be within a post's width).

Usage: python bench/continued_mapping.py [--first 60] [--second 63] [--world demo ...] [--out DIR]
"""

from __future__ import annotations

import os

os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")  # before numpy loads OpenBLAS

import argparse
from pathlib import Path

import numpy as np

from nuturtle_demo.driver import RouteConfig
from nuturtle_demo.run import DemoOptions, default_world, run_demo, seen_walls, world_outline
from nuturtle_eval.grid_score import score_grid
from nuturtle_eval.run_evaluation import REFERENCE_TUM
from nuturtle_eval.tum import read_tum
from turtlelib.mapping.grid_map_file import load_grid_map
from turtlelib.mapping.landmark_map import load_map

WORLDS = {
    "demo": default_world(),
    "turtlebot3_world": Path("nusim/config/turtlebot3_world.yaml"),
    "rooms_world": Path("nusim/config/rooms_world.yaml"),
}
KEYS = (
    ("landmarks_mapped", "{:d}"),
    ("landmarks_spurious", "{:d}"),
    ("landmark_rmse_m", "{:.4f}"),
    ("final_position_error_slam_m", "{:.4f}"),
    ("ate_rmse_slam_m", "{:.4f}"),
    ("nees_pose_within_95_fraction", "{:.3f}"),
)


def run(options: DemoOptions):
    """The run's result and its system (kept for the walls its true poses saw)."""
    held = {}

    def keep(system, _sim_time_s):
        held["system"] = system

    return run_demo(options, keep), held["system"]


def grid_row(out_dirs: list[Path], systems) -> tuple[float, float]:
    """(walls found, false occupied) of the last run's final grid against the walls all the runs saw."""
    seen = np.vstack(
        [
            seen_walls(system, read_tum(out / REFERENCE_TUM))
            for out, system in zip(out_dirs, systems, strict=True)
        ]
    )
    score = score_grid(load_grid_map(out_dirs[-1] / "map.yaml"), world_outline(systems[-1]), seen)
    return score.walls_found, score.false_occupied


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--first", type=float, default=60.0, help="session 1's duration (s)")
    parser.add_argument("--second", type=float, default=60.0 + RouteConfig().start_delay,
                        help="session 2's duration (s; it first stands still for the driver's start_delay)",
                        )  # fmt: skip
    parser.add_argument("--world", choices=tuple(WORLDS), nargs="+", default=list(WORLDS))
    parser.add_argument("--out", type=Path, default=Path("out/continued_mapping"))
    args = parser.parse_args()
    single_s = args.first + args.second - RouteConfig().start_delay
    for name in args.world:
        out = args.out / name
        map_file = out / "sessions" / "map.json"
        map_file.parent.mkdir(parents=True, exist_ok=True)
        for stale in map_file.parent.glob("map.*"):
            stale.unlink()
        common = {"world": WORLDS[name], "progress": False}
        first, system1 = run(
            DemoOptions(
                duration_s=args.first, out_dir=out / "session1", map_file=map_file, save_map=True, **common
            )
        )
        map1 = load_map(map_file)
        second, system2 = run(
            DemoOptions(
                duration_s=args.second, out_dir=out / "session2", map_file=map_file, save_map=True,
                route_start_s=first.route_time_s, **common,
            )
        )  # fmt: skip
        map2 = load_map(map_file)
        single, system3 = run(DemoOptions(duration_s=single_s, out_dir=out / "single", **common))
        print(f"\n{name}: session 1 {args.first:.0f} s (route to {first.route_time_s:.1f} s), session 2 "
              f"{args.second:.0f} s (to {second.route_time_s:.1f} s), single {single_s:.0f} s "
              f"(to {single.route_time_s:.1f} s)")  # fmt: skip
        print("| run | " + " | ".join(key for key, _ in KEYS) + " | grid walls found | grid false occupied |")
        print("|---" * (len(KEYS) + 3) + "|")
        rows = (
            ("session 1", first, [out / "session1"], [system1]),
            ("session 2 (continued)", second, [out / "session1", out / "session2"], [system1, system2]),
            ("single", single, [out / "single"], [system3]),
        )
        for label, result, dirs, systems in rows:
            metrics = result.metrics.as_dict()
            walls, false = grid_row(dirs, systems)
            cells = [form.format(metrics[key]) for key, form in KEYS] + [f"{walls:.4f}", f"{false:.4f}"]
            print(f"| {label} | " + " | ".join(cells) + " |")
        kept = np.isin(map1.ids, map2.ids)
        index = {int(i): k for k, i in enumerate(map2.ids)}
        moved = [
            np.linalg.norm(map2.xy[index[int(i)]] - xy)
            for i, xy in zip(map1.ids, map1.xy, strict=True)
            if int(i) in index
        ]
        gaps = np.linalg.norm(map2.xy[:, None] - map2.xy[None], axis=-1) + np.diag(
            np.full(len(map2.ids), np.inf)
        )
        print(f"session 1's {len(map1.ids)} landmarks kept: {int(kept.sum())} (ids {map1.ids.tolist()} -> "
              f"{map2.ids.tolist()}), moved at most {max(moved, default=0.0) * 1000:.1f} mm; closest pair "
              f"in the final map {gaps.min(initial=np.inf):.3f} m", flush=True)  # fmt: skip


if __name__ == "__main__":
    main()
