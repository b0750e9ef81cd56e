"""Benchmark: CPU instructions per EKF SLAM step, counted by valgrind (callgrind), which the load of a shared
machine does not move (wall times of one version move by +-30 % from run to run here).

The step is bench_ekf.py's (a prediction from wheel increments and an update with 10 observations of mapped
landmarks; known association, or unknown with nearest neighbour or JCBB). Each count runs the same seeded
scenario twice under callgrind, with 0 and with --steps steps after the set-up, and divides the difference:
instructions per step, set-up and interpreter start excluded. --tree compares versions of turtlelib (their
folder first on PYTHONPATH; each must have today's EkfSlam API), e.g. a `git worktree` of an older commit.

Usage: python bench/ekf_instructions.py [--tree DIR ...] [--sizes 10 20] [--steps 100]
(needs valgrind; about a minute per count).
"""

from __future__ import annotations

import argparse
import math
import os
import re
import shutil
import subprocess
import sys
from pathlib import Path

BENCH = Path(__file__).resolve().parent
MODES = ("known", "nn", "jcbb")


def run_steps(n: int, mode: str, steps: int) -> None:
    """The child: a filter that mapped n landmarks, then ``steps`` steps of bench_ekf.py's loop."""
    sys.path.insert(0, str(BENCH))
    import numpy as np
    from bench_ekf import BURGER, SCAN_PERIOD_NS, WHEEL_STEP_RAD, grid_world, mapped_filter, observations

    from turtlelib import Transform2D

    rng = np.random.default_rng(1)
    world = grid_world(n, rng)
    slam = mapped_filter(world, mode, rng)
    truth, scan, inputs = Transform2D(), math.ceil(n / 10), []
    for _ in range(steps):
        truth = BURGER.step(truth, WHEEL_STEP_RAD, WHEEL_STEP_RAD)
        ids = rng.choice(n, size=min(10, n), replace=False)
        inputs.append((ids, observations(truth, world, ids, rng)))
    for ids, z in inputs:
        slam.predict((WHEEL_STEP_RAD, WHEEL_STEP_RAD))
        if mode == "known":
            slam.update_known(ids, z)
        else:
            slam.update_unknown(z, stamp_ns=scan * SCAN_PERIOD_NS)
        scan += 1


def instructions(tree: Path | None, n: int, mode: str, steps: int) -> int:
    """Instructions of one child run under callgrind (the interpreter's re-exec followed)."""
    env = dict(os.environ, OPENBLAS_NUM_THREADS="1")
    if tree is not None:
        env["PYTHONPATH"] = str(tree / "turtlelib")
    command = [
        "valgrind", "--tool=callgrind", "--trace-children=yes", "--callgrind-out-file=/dev/null",
        sys.executable, "-P", __file__, "--child", str(n), mode, str(steps),
    ]  # fmt: skip
    result = subprocess.run(command, env=env, capture_output=True, text=True, check=True)
    return int(re.findall(r"Collected : (\d+)", result.stderr)[-1])


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--tree", type=Path, action="append", help="a checkout whose turtlelib to count")
    parser.add_argument("--sizes", type=int, nargs="+", default=[10, 20])
    parser.add_argument("--steps", type=int, default=100)
    parser.add_argument("--child", nargs=3, help=argparse.SUPPRESS)
    args = parser.parse_args()
    if args.child:
        run_steps(int(args.child[0]), args.child[1], int(args.child[2]))
        return
    if shutil.which("valgrind") is None:
        parser.error("valgrind is not installed")
    trees = args.tree or [None]
    names = ["this checkout" if tree is None else str(tree) for tree in trees]
    print("| n | association | " + " | ".join(f"{name} (instructions per step)" for name in names) + " |")
    print("|---:|---|" + "---:|" * len(trees))
    for n in args.sizes:
        for mode in MODES:
            counts = []
            for tree in trees:
                setup = instructions(tree, n, mode, 0)
                counts.append((instructions(tree, n, mode, args.steps) - setup) // args.steps)
            print(f"| {n} | {mode} | " + " | ".join(f"{count:,}" for count in counts) + " |", flush=True)


if __name__ == "__main__":
    main()
