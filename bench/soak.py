"""Soak: the simulation + SLAM demo for a long run (one hour of robot time by default), watched as it runs.

It runs the real demo (`nuturtle_demo.run.run_demo`: every node in this process, nusim at the demo's
default maximum real-time factor, the rosbag2 recording included) and, every ``--sample-period`` s of robot
time, reads from the in-process nodes (run_demo's ``on_progress`` hook):

* the slam node's full covariance ``P`` (N, N) over the pose and the confirmed landmarks
  (``EkfSlam.covariance``): its smallest eigenvalue (``numpy.linalg.eigvalsh`` of ``(P + P^T) / 2``;
  mixed units m^2 / rad^2 / m rad) and its asymmetry ``max |P - P^T|``;
* the landmarks mapped (confirmed) and tentative, and how many mapped ones pair with a true cylinder
  (``metrics.associate_landmarks``, the demo's 0.2 m gate);
* the SLAM position error (m) and heading error (rad) of the latest `slam/odom` pose the monitor holds,
  against nusim's ground truth interpolated at that pose's stamp;
* the process's resident set size, VmRSS of /proc/self/status (MiB), and its growth's suspects: the
  samples the monitor holds, the messages written to the bag, the Python objects the garbage collector
  tracks (``len(gc.get_objects())``).

Targets, each printed PASS / FAIL (the exit code is 1 when any fails):

* P symmetric positive definite: smallest eigenvalue > 0 and ``max |P - P^T| <= 1e-12`` at every sample;
* the map keeps its landmarks: once every true cylinder is mapped, every later sample maps exactly that
  many, each paired with a true cylinder, and so does the last;
* memory flat: VmRSS at the end within 10 % of VmRSS at 5 min of robot time (not judged for runs that
  end before 10 min: the reference would be too close to the end);
* SLAM error under 2 cm at every sample once the map is complete (every true cylinder mapped). The
  maximum after the first 20 s is reported too: during the first loop, before the map is complete, the
  error peaks near 2 cm (docs/soak.md).

Outputs in --out: ``soak.json`` (every sample, the summary, the targets and the demo's metrics),
``soak.png`` (RSS, smallest eigenvalue of P, landmarks, SLAM error over robot time) and the demo's own
outputs (metrics.json, the figures, the bag run/, config.yaml).

The run lives in its own DDS world (the demo's default ``--domain-id private``: a free domain with discovery
off, docs/demo.md), so no other ROS process on the machine or the network joins it.

Usage: python -P bench/soak.py [--duration 3600] [--out out/soak] [--association unknown|known] [--seed 0]
       [--sample-period 10] [--no-progress]
"""

from __future__ import annotations

import os

os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")  # before numpy loads OpenBLAS

import argparse
import gc
import json
import math
import platform
import sys
import time
from collections.abc import Sequence
from dataclasses import asdict, dataclass
from pathlib import Path
from typing import Any

import numpy as np

from nuturtle_demo.run import ASSOCIATIONS, DemoOptions, DemoSystem, run_demo
from nuturtle_eval.metrics import associate_landmarks, pose_errors
from nuturtle_eval.run_evaluation import LANDMARK_GATE_M, json_value

SAMPLE_PERIOD_S = 10.0
# Targets
MAX_ASYMMETRY = 1e-12  # max |P - P^T| (the units of P's entries)
RSS_REFERENCE_S = 300.0  # robot time of the reference RSS sample (s)
MAX_RSS_RATIO = 1.10  # VmRSS at the end / at RSS_REFERENCE_S
RSS_MIN_DURATION_S = 600.0  # shorter runs do not judge the RSS ratio
MAX_SLAM_ERROR_M = 0.02
WARM_UP_S = 20.0  # the SLAM error's maximum is also reported after this much robot time (s)
MIB = 1024.0 * 1024.0
# Newest samples of the monitor's 20 Hz streams read for the SLAM error (2 s)
RECENT_SAMPLES = 40


def rss_bytes() -> int:
    """This process's resident set size (bytes): VmRSS of /proc/self/status (Linux)."""
    with open("/proc/self/status", encoding="ascii") as status:
        for line in status:
            if line.startswith("VmRSS:"):
                return int(line.split()[1]) * 1024
    raise RuntimeError("/proc/self/status has no VmRSS line")


@dataclass(frozen=True)
class SoakSample:
    """What one sample read, at ``sim_time_s`` of robot time (s) and ``wall_time_s`` of wall time since the
    sampler was made (s).

    ``rss_mb`` VmRSS (MiB); ``p_size`` N of P (N, N); ``p_min_eigenvalue`` its smallest eigenvalue and
    ``p_asymmetry`` ``max |P - P^T|`` (P's units); ``landmarks_mapped``, ``landmarks_tentative``,
    ``landmarks_paired`` (counts); ``slam_error_m`` (m) and ``slam_heading_error_rad`` (rad) of the latest
    SLAM pose at its stamp ``slam_stamp_s`` (s) against the ground truth (NaN before the first);
    ``monitor_samples``, ``bag_messages``, ``python_objects`` (counts).
    """

    sim_time_s: float
    wall_time_s: float
    rss_mb: float
    p_size: int
    p_min_eigenvalue: float
    p_asymmetry: float
    landmarks_mapped: int
    landmarks_tentative: int
    landmarks_paired: int
    slam_stamp_s: float
    slam_error_m: float
    slam_heading_error_rad: float
    monitor_samples: int
    bag_messages: int
    python_objects: int


def covariance_health(P: np.ndarray) -> tuple[float, float]:
    """``(smallest eigenvalue of (P + P^T) / 2, max |P - P^T|)`` of a square matrix (P's units)."""
    P = np.asarray(P, dtype=np.float64)
    asymmetry = float(np.max(np.abs(P - P.T))) if P.size else 0.0
    smallest = float(np.linalg.eigvalsh(0.5 * (P + P.T))[0]) if P.size else math.nan
    return smallest, asymmetry


def latest_slam_error(system: DemoSystem) -> tuple[float, float, float]:
    """``(stamp (s), position error (m), heading error (rad))`` of the newest `slam/odom` pose the monitor
    holds that the ground truth covers, against the truth interpolated at its stamp; NaNs before there is
    one. Reads only the monitor's newest ``RECENT_SAMPLES`` of each stream."""
    truth = system.monitor.truth(last=RECENT_SAMPLES)
    slam = system.monitor.slam(last=RECENT_SAMPLES)
    if len(truth) == 0 or len(slam) == 0:
        return math.nan, math.nan, math.nan
    covered = slam.within(truth.t_s[0], truth.t_s[-1])
    if not np.any(covered):
        return math.nan, math.nan, math.nan
    e = pose_errors(slam, truth)[-1]
    return float(slam.t_s[covered][-1]), float(math.hypot(e[0], e[1])), float(abs(e[2]))


class SoakSampler:
    """run_demo's ``on_progress`` hook: one :class:`SoakSample` every ``period_s`` of robot time (s), the
    first at ``period_s``; the samples in ``samples``."""

    def __init__(self, period_s: float = SAMPLE_PERIOD_S) -> None:
        if not period_s > 0.0:
            raise ValueError(f"period_s must be > 0, got {period_s!r}")
        self.period_s = float(period_s)
        self.samples: list[SoakSample] = []
        self._next_s = self.period_s
        self._wall_start = time.monotonic()

    def __call__(self, system: DemoSystem, sim_time_s: float) -> None:
        if sim_time_s < self._next_s - 1e-9:
            return
        while self._next_s <= sim_time_s + 1e-9:
            self._next_s += self.period_s
        self.samples.append(self.sample(system, sim_time_s))

    def sample(self, system: DemoSystem, sim_time_s: float) -> SoakSample:
        ekf = system.slam.slam
        p_min, asymmetry = covariance_health(ekf.covariance)
        mapped_xy = np.asarray(ekf.landmarks).reshape(-1, 2)
        true_xy = system.nusim.simulation.circles[:, :2]
        stamp_s, error_m, heading_rad = latest_slam_error(system)
        return SoakSample(
            sim_time_s=float(sim_time_s),
            wall_time_s=time.monotonic() - self._wall_start,
            rss_mb=rss_bytes() / MIB,
            p_size=int(ekf.covariance.shape[0]),
            p_min_eigenvalue=p_min,
            p_asymmetry=asymmetry,
            landmarks_mapped=int(mapped_xy.shape[0]),
            landmarks_tentative=int(np.asarray(ekf.tentative_ids).size),
            landmarks_paired=int(associate_landmarks(mapped_xy, true_xy, LANDMARK_GATE_M).true_index.size),
            slam_stamp_s=stamp_s,
            slam_error_m=error_m,
            slam_heading_error_rad=heading_rad,
            monitor_samples=int(sum(system.monitor.counts.values())),
            bag_messages=int(system.recorder.writer.message_count),
            python_objects=len(gc.get_objects()),
        )


@dataclass(frozen=True)
class Target:
    """One soak target: ``name``, ``passed`` (None: not judged) and what was measured (``detail``)."""

    name: str
    passed: bool | None
    detail: str

    @property
    def verdict(self) -> str:
        return "n/a" if self.passed is None else ("PASS" if self.passed else "FAIL")


def _sample_at(samples: Sequence[SoakSample], sim_time_s: float) -> SoakSample | None:
    """The first sample at or after ``sim_time_s`` (s), or None."""
    return next((s for s in samples if s.sim_time_s >= sim_time_s - 1e-9), None)


def _largest_error(samples: Sequence[SoakSample]) -> SoakSample | None:
    """The sample with the largest finite SLAM position error, or None."""
    finite = [s for s in samples if math.isfinite(s.slam_error_m)]
    return max(finite, key=lambda s: s.slam_error_m) if finite else None


def summarize(samples: Sequence[SoakSample], landmarks_true: int) -> dict[str, Any]:
    """The soak's figures over the samples (units in the keys; None where there is no such sample).

    ``rss_5min_mb`` is the first sample at or after 5 min of robot time, ``rss_end_mb`` the last;
    ``landmarks_complete_s`` the first sample (robot time, s) that mapped every true cylinder, and
    ``landmarks_mapped_{min,max}_after_complete`` the counts from then on; ``slam_error_max_m`` the
    largest SLAM position error from then on (m) and ``slam_error_max_after_warm_up_m`` the largest after
    the first ``WARM_UP_S``, each with the robot time of its sample (``..._at_s``).
    """
    if not samples:
        raise ValueError("no samples: the run was shorter than one sample period")
    reference = _sample_at(samples, RSS_REFERENCE_S)
    last = samples[-1]
    complete = next((k for k, s in enumerate(samples) if s.landmarks_mapped >= landmarks_true), None)
    after = samples[complete:] if complete is not None else []
    worst = _largest_error(after)
    worst_after_warm_up = _largest_error([s for s in samples if s.sim_time_s > WARM_UP_S])
    return {
        "samples": len(samples),
        "sim_seconds": last.sim_time_s,
        "rss_5min_mb": reference.rss_mb if reference is not None else None,
        "rss_end_mb": last.rss_mb,
        "rss_ratio": last.rss_mb / reference.rss_mb if reference is not None else None,
        "rss_max_mb": max(s.rss_mb for s in samples),
        "p_min_eigenvalue": min(s.p_min_eigenvalue for s in samples),
        "p_max_asymmetry": max(s.p_asymmetry for s in samples),
        "p_size_max": max(s.p_size for s in samples),
        "landmarks_true": int(landmarks_true),
        "landmarks_complete_s": samples[complete].sim_time_s if complete is not None else None,
        "landmarks_mapped_min_after_complete": min(s.landmarks_mapped for s in after) if after else None,
        "landmarks_mapped_max_after_complete": max(s.landmarks_mapped for s in after) if after else None,
        "landmarks_paired_min_after_complete": min(s.landmarks_paired for s in after) if after else None,
        "landmarks_mapped_min": min(s.landmarks_mapped for s in samples),
        "landmarks_mapped_max": max(s.landmarks_mapped for s in samples),
        "landmarks_mapped_end": last.landmarks_mapped,
        "landmarks_tentative_max": max(s.landmarks_tentative for s in samples),
        "slam_error_max_m": worst.slam_error_m if worst else None,
        "slam_error_max_at_s": worst.sim_time_s if worst else None,
        "slam_error_max_after_warm_up_m": worst_after_warm_up.slam_error_m if worst_after_warm_up else None,
        "slam_error_max_after_warm_up_at_s": worst_after_warm_up.sim_time_s if worst_after_warm_up else None,
        "slam_error_final_m": last.slam_error_m,
        "monitor_samples_end": last.monitor_samples,
        "bag_messages_end": last.bag_messages,
        "python_objects_5min": reference.python_objects if reference is not None else None,
        "python_objects_end": last.python_objects,
    }


def judge(summary: dict[str, Any], samples: Sequence[SoakSample]) -> list[Target]:
    """The four targets (module docstring) from :func:`summarize`'s figures and the samples."""
    n_true = summary["landmarks_true"]
    complete = summary["landmarks_complete_s"] is not None
    kept = (
        complete
        and summary["landmarks_mapped_min_after_complete"] == n_true
        and summary["landmarks_mapped_max_after_complete"] == n_true
        and summary["landmarks_paired_min_after_complete"] == n_true
    )
    judged_rss = summary["sim_seconds"] >= RSS_MIN_DURATION_S and summary["rss_ratio"] is not None
    rss_5min = summary["rss_5min_mb"]
    rss_detail = (
        f"VmRSS {rss_5min:.1f} MiB at 5 min, {summary['rss_end_mb']:.1f} MiB at the end: ratio "
        f"{summary['rss_ratio']:.3f} (<= {MAX_RSS_RATIO})"
        if rss_5min is not None
        else f"VmRSS {summary['rss_end_mb']:.1f} MiB at the end"
    )
    if not judged_rss:
        rss_detail += f"; not judged: the run is shorter than {RSS_MIN_DURATION_S:g} s"
    slam_max = summary["slam_error_max_m"]
    return [
        Target(
            "P symmetric positive definite",
            summary["p_min_eigenvalue"] > 0.0 and summary["p_max_asymmetry"] <= MAX_ASYMMETRY,
            f"smallest eigenvalue {summary['p_min_eigenvalue']:.3e} (> 0), max |P - P^T| "
            f"{summary['p_max_asymmetry']:.1e} (<= {MAX_ASYMMETRY:g}) over {len(samples)} samples",
        ),
        Target(
            "map keeps its landmarks",
            kept and summary["landmarks_mapped_end"] == n_true,
            f"all {n_true} mapped at {summary['landmarks_complete_s']} s, then "
            f"{summary['landmarks_mapped_min_after_complete']}-{summary['landmarks_mapped_max_after_complete']}"
            f" mapped, {summary['landmarks_paired_min_after_complete']} paired at least; "
            f"{summary['landmarks_mapped_end']} at the end"
            if complete
            else f"never all {n_true} mapped (at most {summary['landmarks_mapped_max']})",
        ),
        Target("memory flat", (summary["rss_ratio"] <= MAX_RSS_RATIO) if judged_rss else None, rss_detail),
        Target(
            "SLAM error under 2 cm",
            slam_max is not None and slam_max < MAX_SLAM_ERROR_M,
            f"max {slam_max * 1e3:.1f} mm (at {summary['slam_error_max_at_s']:g} s) once the map is "
            f"complete, final {summary['slam_error_final_m'] * 1e3:.1f} mm (< {MAX_SLAM_ERROR_M * 1e3:g} "
            f"mm); max after {WARM_UP_S:g} s {summary['slam_error_max_after_warm_up_m'] * 1e3:.1f} mm (at "
            f"{summary['slam_error_max_after_warm_up_at_s']:g} s)"
            if slam_max is not None
            else "the map was never complete",
        ),
    ]


def plot_soak(path: str | Path, samples: Sequence[SoakSample], landmarks_true: int) -> None:
    """soak.png: over robot time (min), VmRSS (MiB), the smallest eigenvalue of P (log), the landmarks
    mapped and tentative, and the SLAM position error (mm) with the 2 cm target and the time the map was
    complete."""
    from nuturtle_eval.plots import new_figure

    t_min = np.array([s.sim_time_s for s in samples]) / 60.0
    figure = new_figure(8.0, 9.0)
    rss, eig, landmarks, error = figure.subplots(4, 1, sharex=True)
    rss.plot(t_min, [s.rss_mb for s in samples], color="tab:blue")
    if samples[-1].sim_time_s >= RSS_REFERENCE_S:
        rss.axvline(RSS_REFERENCE_S / 60.0, color="0.6", linestyle=":", label="5 min reference")
        rss.legend(loc="lower right")
    rss.set_ylabel("VmRSS (MiB)")
    eigenvalues = np.array([s.p_min_eigenvalue for s in samples])
    eig.semilogy(t_min, np.where(eigenvalues > 0.0, eigenvalues, np.nan), color="tab:purple")
    eig.set_ylabel("smallest eigenvalue of P")
    landmarks.step(t_min, [s.landmarks_mapped for s in samples], where="post", color="tab:green",
                   label="mapped")  # fmt: skip
    landmarks.step(t_min, [s.landmarks_tentative for s in samples], where="post", color="tab:orange",
                   linestyle="--", label="tentative")  # fmt: skip
    landmarks.axhline(landmarks_true, color="0.6", linestyle=":", label="true cylinders")
    landmarks.set_ylabel("landmarks")
    landmarks.legend(loc="lower right")
    error.plot(t_min, [s.slam_error_m * 1e3 for s in samples], color="tab:green")
    error.axhline(MAX_SLAM_ERROR_M * 1e3, color="tab:red", linestyle="--", label="2 cm target")
    complete_s = next((s.sim_time_s for s in samples if s.landmarks_mapped >= landmarks_true), None)
    if complete_s is not None:
        error.axvline(complete_s / 60.0, color="0.6", linestyle=":", label="map complete")
    error.set_ylabel("SLAM position error (mm)")
    error.set_xlabel("robot time (min)")
    error.set_ylim(bottom=0.0)
    error.legend(loc="upper right")
    figure.savefig(path)


@dataclass(frozen=True)
class SoakResult:
    """A soak run: its ``samples``, ``summary`` (:func:`summarize`), ``targets``, the demo's ``metrics``
    (metrics.json), ``wall_seconds`` of the whole run (s), and the written ``json_path`` and ``png_path``."""

    samples: list[SoakSample]
    summary: dict[str, Any]
    targets: list[Target]
    metrics: dict[str, Any]
    wall_seconds: float
    json_path: Path
    png_path: Path

    @property
    def passed(self) -> bool:
        return all(target.passed is not False for target in self.targets)


def run_soak(
    duration_s: float,
    out_dir: str | Path,
    association: str = "unknown",
    seed: int = 0,
    sample_period_s: float = SAMPLE_PERIOD_S,
    progress: bool = True,
) -> SoakResult:
    """Run the demo for ``duration_s`` of robot time (s) into ``out_dir``, sampling every
    ``sample_period_s`` (s) of it (module docstring); writes soak.json and soak.png there, the demo's
    outputs into ``out_dir/demo``."""
    out_dir = Path(out_dir)
    # the demo's own output folder, replaced as a whole by each run (docs/demo.md)
    options = DemoOptions(
        association=association, seed=seed, duration_s=duration_s, out_dir=out_dir / "demo", progress=progress
    )
    sampler = SoakSampler(sample_period_s)
    wall_start = time.monotonic()
    result = run_demo(options, on_progress=sampler)
    wall_seconds = time.monotonic() - wall_start
    metrics = result.metrics.as_dict()
    summary = summarize(sampler.samples, metrics["landmarks_true"])
    summary["wall_seconds"] = wall_seconds
    targets = judge(summary, sampler.samples)
    report = {
        "options": {
            "duration_s": duration_s, "association": association, "seed": seed,
            "sample_period_s": sample_period_s, "max_realtime_factor": options.max_realtime_factor,
        },
        "machine": {
            "cores": os.cpu_count(), "machine": platform.machine(), "python": platform.python_version(),
            "openblas_num_threads": os.environ.get("OPENBLAS_NUM_THREADS"),
        },
        "interrupted": result.interrupted,
        "summary": summary,
        "targets": [{**asdict(t), "verdict": t.verdict} for t in targets],
        "demo_metrics": metrics,
        "samples": [asdict(s) for s in sampler.samples],
    }  # fmt: skip
    out_dir.mkdir(parents=True, exist_ok=True)
    json_path, png_path = out_dir / "soak.json", out_dir / "soak.png"
    # strict JSON, as metrics.json: a NaN (no SLAM pose yet) is null
    json_path.write_text(json.dumps(json_value(report), indent=2, allow_nan=False) + "\n", encoding="utf-8")
    plot_soak(png_path, sampler.samples, metrics["landmarks_true"])
    return SoakResult(sampler.samples, summary, targets, metrics, wall_seconds, json_path, png_path)


def main(argv: Sequence[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--duration", type=float, default=3600.0, help="robot (simulation) seconds")
    parser.add_argument("--out", type=Path, default=Path("out/soak"), help="output folder")
    parser.add_argument("--association", choices=ASSOCIATIONS, default="unknown")
    parser.add_argument("--seed", type=int, default=0)
    parser.add_argument("--sample-period", type=float, default=SAMPLE_PERIOD_S, help="robot seconds")
    parser.add_argument("--no-progress", action="store_true", help="no progress bar on stderr")
    args = parser.parse_args(argv)
    print(
        f"soak: {args.duration:g} s of robot time, association {args.association}, seed {args.seed} "
        f"(OPENBLAS_NUM_THREADS={os.environ.get('OPENBLAS_NUM_THREADS')}; {platform.machine()}, "
        f"{os.cpu_count()} cores, Python {platform.python_version()})",
        flush=True,
    )
    result = run_soak(
        args.duration, args.out, args.association, args.seed, args.sample_period, not args.no_progress
    )
    for target in result.targets:
        print(f"{target.verdict:4}  {target.name}: {target.detail}")
    print(f"wall time {result.wall_seconds:.0f} s; {result.json_path} {result.png_path}")
    return 0 if result.passed else 1


if __name__ == "__main__":
    sys.exit(main())
