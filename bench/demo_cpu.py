"""Benchmark: the CPU time of the whole demo per second of robot time.

Each run is the command a user types, ``python -P -m nuturtle_demo --duration D --seed S --out DIR
--no-progress`` (default world, unknown association unless told), in a child process; its CPU time is the
child's user + system time from ``os.wait4`` (its own rusage) (every thread of it: the executor,
DDS, the bag's compression), start-up, evaluation and figures included, divided by the robot seconds it ran
(``sim_seconds`` of its metrics.json). Also reported: the wall time of the process and its peak resident
memory (``ru_maxrss``).

``--tree DIR`` (repeatable) runs the demo of another checkout (its nine package folders first on
PYTHONPATH, the same .venv), e.g. ``git archive main | tar -x -C /tmp/main``; with several trees the runs
are interleaved (tree A, tree B, A, B, ... for each seed), so a change in the machine's load falls on both.
Prints one markdown row per run and the median per tree.

Usage: python bench/demo_cpu.py [--tree DIR ...] [--seeds 0 1 2] [--duration 60] [--association unknown]
       [--out out/demo_cpu]
"""

from __future__ import annotations

import argparse
import json
import os
import statistics
import subprocess
import sys
import time
from dataclasses import dataclass
from pathlib import Path

# the nine ament_python packages (pyproject.toml: tool.setuptools.packages.find)
PACKAGES = (
    "turtlelib", "nuturtle_eval", "nuturtle_ros_common", "nuturtle_description", "nusim", "nuturtle_control",
    "nuslam", "nuturtle_tools", "nuturtle_demo",
)  # fmt: skip


@dataclass(frozen=True)
class DemoCost:
    """One run: ``cpu_s`` user + system CPU time (s), ``wall_s`` (s), ``sim_s`` robot seconds run,
    ``max_rss_mb`` peak resident memory (MB)."""

    cpu_s: float
    wall_s: float
    sim_s: float
    max_rss_mb: float

    @property
    def cpu_per_robot_s(self) -> float:
        return self.cpu_s / self.sim_s


def run_once(tree: Path | None, seed: int, duration_s: float, association: str, out_dir: Path) -> DemoCost:
    """One demo in a child process (module docstring); RuntimeError when it fails."""
    env = dict(os.environ)
    env.setdefault("OPENBLAS_NUM_THREADS", "1")
    if tree is not None:
        paths = [str(tree / package) for package in PACKAGES]
        env["PYTHONPATH"] = os.pathsep.join(paths + [env.get("PYTHONPATH", "")]).rstrip(os.pathsep)
    command = [
        sys.executable, "-P", "-m", "nuturtle_demo", "--duration", f"{duration_s:g}", "--seed", str(seed),
        "--association", association, "--out", str(out_dir), "--no-progress",
    ]  # fmt: skip
    log = out_dir.with_name(out_dir.name + ".stderr")
    log.parent.mkdir(parents=True, exist_ok=True)
    start = time.monotonic()
    with log.open("w", encoding="utf-8") as stderr:
        child = subprocess.Popen(command, env=env, stdout=subprocess.DEVNULL, stderr=stderr)
        # this child's own rusage (every thread of it), not that of all children so far
        _, status, usage = os.wait4(child.pid, 0)
    wall_s = time.monotonic() - start
    child.returncode = os.waitstatus_to_exitcode(status)
    if child.returncode != 0:
        tail = log.read_text(encoding="utf-8")[-2000:]
        raise RuntimeError(f"{' '.join(command)} exited {child.returncode}:\n{tail}")
    metrics = json.loads((out_dir / "metrics.json").read_text(encoding="utf-8"))
    cpu_s = usage.ru_utime + usage.ru_stime
    # ru_maxrss: kB on Linux
    return DemoCost(cpu_s, wall_s, float(metrics["sim_seconds"]), usage.ru_maxrss / 1024.0)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--tree", type=Path, action="append", help="a checkout whose demo to run")
    parser.add_argument("--seeds", type=int, nargs="+", default=[0, 1, 2])
    parser.add_argument("--duration", type=float, default=60.0, help="robot seconds per run")
    parser.add_argument("--association", choices=("known", "unknown"), default="unknown")
    parser.add_argument("--out", type=Path, default=Path("out/demo_cpu"))
    args = parser.parse_args()
    trees: list[Path | None] = [tree.resolve() for tree in args.tree] if args.tree else [None]
    names = ["this checkout" if tree is None else str(tree) for tree in trees]
    costs: dict[str, list[DemoCost]] = {name: [] for name in names}
    print(f"{args.duration:g} s demos, {args.association} association")
    print()
    print("| tree | seed | CPU-s | CPU-s per robot s | wall (s) | peak memory (MB) |")
    print("|---|---:|---:|---:|---:|---:|")
    for seed in args.seeds:
        for index, (tree, name) in enumerate(zip(trees, names, strict=True)):
            out_dir = args.out / f"tree{index}-seed{seed}"
            cost = run_once(tree, seed, args.duration, args.association, out_dir)
            costs[name].append(cost)
            print(
                f"| {name} | {seed} | {cost.cpu_s:.1f} | {cost.cpu_per_robot_s:.3f} | {cost.wall_s:.1f} "
                f"| {cost.max_rss_mb:.0f} |",
                flush=True,
            )
    for name, runs in costs.items():
        cpu = statistics.median(c.cpu_per_robot_s for c in runs)
        wall = statistics.median(c.wall_s for c in runs)
        print(f"| **{name}, median** | | | {cpu:.3f} | {wall:.1f} | |")


if __name__ == "__main__":
    main()
