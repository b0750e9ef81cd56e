"""Benchmark: the CPU time of the smoother over a dataset run (``--smooth`` of the dataset command).

For each run (MRCLAM Dataset 7 robot 1 with known and with unknown association, Victoria Park), the filter
runs once; then the smoother (building its factors, solving, revising the associations for unknown
association, recovering the landmark covariance) runs ``--repeat`` times from the same filter result. The
CPU time (user + system of this process, ``time.process_time``) of each smoothing is reported, median and
range, beside the filter's and the figures the smoother gave (they are the same on every repetition).

Usage: .venv/bin/python -P bench/smoother_cpu.py --mrclam DIR --victoria DIR [--repeat 3] [--write]
(``--write`` replaces the "## Smoother" section of docs/benchmarks.md).
"""

from __future__ import annotations

import os

os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")  # before numpy loads OpenBLAS, as the dataset command

import argparse
import platform
import sys
import time
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))  # bench_docs, also under python -P

from bench_docs import write_section

ROOT = Path(__file__).resolve().parents[1]
HEADING = "## Smoother"
TARGETS_S = {"mrclam": 5.0, "victoria": 20.0}


def runs(mrclam: Path, victoria: Path):
    """``(name, target key, experiment, evaluate)`` of each benchmarked run."""
    from nuturtle_eval.datasets.evaluation import evaluate_mrclam, evaluate_victoria
    from nuturtle_eval.datasets.mrclam import load_mrclam
    from nuturtle_eval.datasets.setups import (
        VICTORIA_PARAMS,
        load_params,
        mrclam_experiment,
        mrclam_params,
        victoria_experiment,
    )
    from nuturtle_eval.datasets.victoria import load_victoria

    recording = load_mrclam(mrclam, 1)
    for association in ("known", "unknown"):
        experiment = mrclam_experiment(recording, load_params(mrclam_params(association), None), association)
        yield experiment.name, "mrclam", experiment, lambda e, r: evaluate_mrclam(e, r, recording)
    park = load_victoria(victoria)
    experiment = victoria_experiment(park, load_params(VICTORIA_PARAMS, None))
    yield experiment.name, "victoria", experiment, lambda e, r: evaluate_victoria(e, r, park)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--mrclam", type=Path, required=True, help="an MRCLAM_Dataset7 directory")
    parser.add_argument("--victoria", type=Path, required=True, help="the victoria_park directory")
    parser.add_argument("--repeat", type=int, default=3, help="smoothings per run")
    parser.add_argument("--write", action="store_true", help="replace the section in docs/benchmarks.md")
    args = parser.parse_args()

    from nuturtle_eval.datasets.experiment import run_experiment
    from nuturtle_eval.datasets.smoothing import smooth_run

    rows = []
    for name, key, experiment, evaluate in runs(args.mrclam, args.victoria):
        print(f"{name}: filter", file=sys.stderr, flush=True)
        result = run_experiment(experiment)
        cpu = []
        for k in range(args.repeat):
            print(f"{name}: smoothing {k + 1}/{args.repeat}", file=sys.stderr, flush=True)
            start = time.process_time()
            smoothed, _ = smooth_run(experiment, result, revise=experiment.scans.ids is None)
            cpu.append(time.process_time() - start)
        filtered, smoothed_metrics = (
            evaluate(experiment, result).metrics,
            evaluate(experiment, smoothed).metrics,
        )
        rows.append(
            f"| {name} | {len(result.t_ns)} | {result.cpu_seconds:.1f} | {np.median(cpu):.1f} "
            f"({min(cpu):.1f}-{max(cpu):.1f}) | {TARGETS_S[key]:g} | {filtered['ate_rmse_aligned_m']:.3f} | "
            f"{smoothed_metrics['ate_rmse_aligned_m']:.3f} |"
        )
    text = "\n".join(
        [
            HEADING,
            "",
            "`.venv/bin/python -P bench/smoother_cpu.py --mrclam DIR --victoria DIR "
            f"--repeat {args.repeat}` on "
            f"{platform.machine()}, Python {platform.python_version()}, one BLAS thread, "
            f"{time.strftime('%Y-%m-%d')}. CPU seconds (user + system) of the smoother after the filter: "
            "building the factors, solving, revising the associations (unknown association) and the "
            "landmark covariance. The machine is shared: repeated runs vary (load average "
            f"{os.getloadavg()[0]:.1f} on its {os.cpu_count()} cores when this run ended).",
            "",
            "| run | poses | filter CPU (s) | smoother CPU (s), median (range) | target (s) | ATE aligned, "
            "filter (m) | smoother (m) |",
            "|---|---|---|---|---|---|---|",
            *rows,
        ]
    )
    print(text)
    if args.write:
        write_section(HEADING, text, ROOT / "docs" / "benchmarks.md")


if __name__ == "__main__":
    main()
