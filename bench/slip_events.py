"""Benchmark: slip events and bumps in nusim's simulation, with and without the slip recovery.

Each run is one closed-loop scenario of `tests/slip_scenarios.py` (a TurtleBot3 in nusim's default world,
the LiDAR, the landmark detector and EKF SLAM on its timeline): 25 s of a 0.75 m circle, then the event (a
0.75 rad phantom turn: the wheels turn the robot in place on a floor without grip; a wheel slip: the left
wheel spins on a slick patch while the robot drives, until the wheels report 0.75 rad more turn than the
body made; or a bump: the robot drives into the nearest cylinder and pushes for 4 s, wheels spinning), then
20 s more of the circle. Per model (Burger, Waffle), event, mode (mapping, localization), recovery (on,
off) and seed: the position and heading error 20 s
after the event, the largest position error in those 20 s, landmarks mapped and spurious (no cylinder
within 0.15 m), scans held and relocalizations. Also runs without an event (120 s), where the recovery
must never act. Target: final error <= 5 cm, no spurious landmark, the cause in the status.

Usage: python bench/slip_events.py [--seeds 5] [--write]   (--write replaces the "## Slip and bumps"
section of docs/benchmarks.md)
"""

from __future__ import annotations

import os

os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")  # before numpy loads OpenBLAS

import argparse
import importlib.util
import sys
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))  # bench_docs, also under python -P

from bench_docs import write_section

from turtlelib.estimation.slip_recovery import SlipRecoveryConfig


def _scenarios():
    """tests/slip_scenarios.py, loaded from its file (tests/ on sys.path would shadow the packages)."""
    path = Path(__file__).resolve().parent.parent / "tests" / "slip_scenarios.py"
    spec = importlib.util.spec_from_file_location("slip_scenarios", path)
    module = importlib.util.module_from_spec(spec)
    sys.modules[spec.name] = module  # its dataclasses look themselves up there
    spec.loader.exec_module(module)
    return module


run_scenario = _scenarios().run_scenario

HEADER = (
    "model", "event", "mode", "recovery", "final position error (m), mean / worst",
    "final heading error (rad), worst", "largest error after the event (m), worst",
    "landmarks mapped / spurious, worst", "scans held / relocalizations / stall scans, mean", "target met",
)  # fmt: skip


def row(model: str, event: str, mode: str, recovery: bool, seeds: int) -> str:
    results = []
    for seed in range(seeds):
        config = SlipRecoveryConfig(slip_recovery=recovery)
        if event == "none":
            result = run_scenario(
                "none", mode, recovery=config, seed=seed, model=model, event_s=60.0, after_s=60.0
            )
        else:
            result = run_scenario(event, mode, recovery=config, seed=seed, model=model)
        results.append(result)
        print(
            f"  {model} {event} {mode} {recovery} seed {seed}: {result.final_error_m:.3f} m", file=sys.stderr
        )
    final = np.array([r.final_error_m for r in results])
    heading = max(r.final_heading_rad for r in results)
    after = max(max(e for t, e in r.errors if t >= r.event_end_s) for r in results)
    mapped = max(r.landmarks for r in results)
    spurious = max(r.spurious for r in results)
    held = np.mean([r.held for r in results])
    relocalized = np.mean([r.relocalized for r in results])
    stalls = np.mean([r.stalls for r in results])
    met = final.max() <= 0.05 and spurious == 0
    return (
        f"| {model} | {event} | {mode} | {'on' if recovery else 'off'} | "
        f"{final.mean():.3f} / {final.max():.3f} | {heading:.3f} | {after:.3f} | {mapped} / {spurious} | "
        f"{held:.1f} / {relocalized:.1f} / {stalls:.1f} | "
        f"{'yes' if met else 'no'} |"
    )


def section(seeds: int) -> str:
    lines = [
        "## Slip and bumps",
        "",
        f"`python bench/slip_events.py --seeds {seeds} --write` (seeds 0-{seeds - 1}; the scenarios are "
        "`tests/slip_scenarios.py`; nusim's default world, 5 Hz scans, 20 Hz joint states). ",
        "Errors 20 s after the event (`none`: after 120 s of driving); the recovery is "
        "`turtlelib.estimation.slip_recovery` ([reliability.md](reliability.md#slip-and-bumps-slam)).",
        "",
        "| " + " | ".join(HEADER) + " |",
        "|" + "---|" * len(HEADER),
    ]
    for model in ("burger", "waffle"):
        for event in ("none", "phantom_turn", "wheel_slip", "bump"):
            for mode in ("mapping", "localization"):
                for recovery in (True, False):
                    lines.append(row(model, event, mode, recovery, seeds))
    return "\n".join(lines)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--seeds", type=int, default=5)
    parser.add_argument("--write", action="store_true", help="write the section into docs/benchmarks.md")
    args = parser.parse_args()
    text = section(args.seeds)
    print(text)
    if args.write:
        write_section(
            "## Slip and bumps", text, Path(__file__).resolve().parent.parent / "docs" / "benchmarks.md"
        )


if __name__ == "__main__":
    main()
