"""Benchmark: CPU instructions per EKF SLAM step, counted by valgrind (callgrind), which the load of a shared
machine does not move (wall times of one version move by +-30 % from run to run here).

The step is bench_ekf.py's (a prediction from wheel increments and an update with 10 observations of mapped
landmarks; known association, or unknown with nearest neighbour or JCBB). Each count runs the seeded
scenario once: the interpreter, the imports, the map and the inputs run uninstrumented; the child then turns
callgrind's instrumentation on (``callgrind_control -i on``), takes one step to warm up, and runs the
``--steps`` others inside ``functools.reduce``, the only code counted (``--toggle-collect``): instructions per
step of the filter alone, neither set-up nor input generation. --tree compares versions of turtlelib (their
folder first on PYTHONPATH; each must have today's EkfSlam API), e.g. a `git worktree` of an older commit.

Usage: python bench/ekf_instructions.py [--tree DIR ...] [--sizes 10 20] [--steps 50]
(needs valgrind; about 25 s per count).
"""

from __future__ import annotations

import argparse
import functools
import math
import os
import re
import shutil
import subprocess
import sys
from pathlib import Path

BENCH = Path(__file__).resolve().parent
MODES = ("known", "nn", "jcbb")
COUNTED = "functools_reduce"  # the C function whose calls callgrind counts: the child's step loop


def run_steps(n: int, mode: str, steps: int) -> None:
    """The child: a filter that mapped n landmarks, then one warm-up step and ``steps`` counted steps of
    bench_ekf.py's loop (inputs drawn before)."""
    sys.path.insert(0, str(BENCH))
    import numpy as np
    from bench_ekf import BURGER, SCAN_PERIOD_NS, WHEEL_STEP_RAD, grid_world, mapped_filter, observations

    from turtlelib import Transform2D

    rng = np.random.default_rng(1)
    world = grid_world(n, rng)
    slam = mapped_filter(world, mode, rng)
    truth, first_scan, inputs = Transform2D(), math.ceil(n / 10), []
    for k in range(steps + 1):
        truth = BURGER.step(truth, WHEEL_STEP_RAD, WHEEL_STEP_RAD)
        ids = rng.choice(n, size=min(10, n), replace=False)
        inputs.append((ids, observations(truth, world, ids, rng), (first_scan + k) * SCAN_PERIOD_NS))

    def step(_: None, scan: tuple) -> None:
        ids, z, stamp_ns = scan
        slam.predict((WHEEL_STEP_RAD, WHEEL_STEP_RAD))
        if mode == "known":
            slam.update_known(ids, z)
        else:
            slam.update_unknown(z, stamp_ns=stamp_ns)

    step(None, inputs[0])
    command = ["callgrind_control", "-i", "on", str(os.getpid())]
    subprocess.run(command, check=True, capture_output=True)
    functools.reduce(step, inputs[1:], None)


def instructions(tree: Path | None, n: int, mode: str, steps: int) -> int:
    """Instructions per step of one child run under callgrind (the interpreter's re-exec followed)."""
    env = dict(os.environ, OPENBLAS_NUM_THREADS="1")
    if tree is not None:
        env["PYTHONPATH"] = str(tree / "turtlelib")
    command = [
        "valgrind", "--tool=callgrind", "--trace-children=yes", "--instr-atstart=no", "--collect-atstart=no",
        f"--toggle-collect={COUNTED}", "--callgrind-out-file=/dev/null",
        sys.executable, "-P", __file__, "--child", str(n), mode, str(steps),
    ]  # fmt: skip
    result = subprocess.run(command, env=env, capture_output=True, text=True, check=True, cwd=BENCH)
    return int(re.findall(r"Collected : (\d+)", result.stderr)[-1]) // steps


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--tree", type=Path, action="append", help="a checkout whose turtlelib to count")
    parser.add_argument("--sizes", type=int, nargs="+", default=[10, 20])
    parser.add_argument("--steps", type=int, default=50)
    parser.add_argument("--child", nargs=3, help=argparse.SUPPRESS)
    args = parser.parse_args()
    if args.child:
        run_steps(int(args.child[0]), args.child[1], int(args.child[2]))
        return
    if shutil.which("valgrind") is None or shutil.which("callgrind_control") is None:
        parser.error("valgrind (with callgrind_control) is not installed")
    trees = args.tree or [None]
    names = ["this checkout" if tree is None else str(tree) for tree in trees]
    print("| n | association | " + " | ".join(f"{name} (instructions per step)" for name in names) + " |")
    print("|---:|---|" + "---:|" * len(trees))
    for n in args.sizes:
        for mode in MODES:
            counts = [instructions(tree, n, mode, args.steps) for tree in trees]
            print(f"| {n} | {mode} | " + " | ".join(f"{count:,}" for count in counts) + " |", flush=True)


if __name__ == "__main__":
    main()
