"""``python -m nuturtle_eval.datasets``: EKF SLAM on real datasets, and noise calibration from ground truth.

::

    python -m nuturtle_eval.datasets mrclam --data DIR --robot K [--association known|unknown] [--smooth]
        [--out DIR]
    python -m nuturtle_eval.datasets victoria --data DIR [--protocol aligned|published] [--smooth] [--out DIR]
    python -m nuturtle_eval.datasets calibrate --data DIR --robot K [--out FILE]

``mrclam`` / ``victoria`` write ``metrics.json``, ``trajectory.png``, ``errors.png``, ``nees.png`` and the
parameters used (``params.yaml``) into ``--out``, with ``--smooth`` also the smoothed run beside the
filter's (``smoothed.png``, ``smoothed_errors.png``, ``smoothed`` in metrics.json); ``--params FILE``
replaces the defaults (e.g. with what ``calibrate`` wrote). See docs/real_data.md.
"""

from __future__ import annotations

import os

# One BLAS thread unless the caller says otherwise, set before numpy loads OpenBLAS (which reads it once):
# the filter's small matrices gain nothing from threads, and two threads on two busy cores tripled the
# CPU time of an MRCLAM run (docs/real_data.md).
os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")

import argparse
import sys
from collections.abc import Callable, Sequence
from pathlib import Path
from typing import TYPE_CHECKING

from ..command_help import DefaultsHelpFormatter
from ..run_evaluation import write_metrics
from ..run_folder import RunFolder, check_no_other_run, check_replaceable, error_line, say_previous_result
from .experiment import ASSOCIATIONS, Experiment, ExperimentResult, run_experiment
from .setups import PROTOCOLS

# what a run writes into --out (the folder is replaced as a whole, nuturtle_eval.run_folder); --smooth adds
# the side-by-side figures of filter and smoother
OUTPUTS = ("metrics.json", "params.yaml", "trajectory.png", "errors.png", "nees.png")
SMOOTHED_OUTPUTS = ("smoothed.png", "smoothed_errors.png")
# the calibrate command's default window (docs/real_data.md: chosen on MRCLAM robot 1)
WINDOW_S = 10.0

if TYPE_CHECKING:
    from .evaluation import Evaluation
    from .setups import DatasetParams


def parse_args(argv: Sequence[str] | None = None) -> argparse.Namespace:
    return build_parser().parse_args(argv)


def build_parser() -> argparse.ArgumentParser:
    """The dataset command's command line."""
    parser = argparse.ArgumentParser(
        prog="python -m nuturtle_eval.datasets",
        description="EKF SLAM on the MRCLAM and Victoria Park datasets.",
        formatter_class=DefaultsHelpFormatter,
    )
    commands = parser.add_subparsers(dest="command", required=True)
    mrclam = commands.add_parser(
        "mrclam", help="one robot of a UTIAS MRCLAM dataset", formatter_class=DefaultsHelpFormatter
    )
    mrclam.add_argument("--data", required=True, type=Path, help="an MRCLAM_DatasetN directory")
    mrclam.add_argument("--robot", required=True, type=int, choices=range(1, 6), help="robot 1..5")
    mrclam.add_argument("--association", choices=ASSOCIATIONS, default="known",
                        help="the barcode's subject number as the landmark id (known), or the filter's own "
                        "association by joint compatibility (unknown)")  # fmt: skip
    victoria = commands.add_parser(
        "victoria", help="the Victoria Park run (tree detections, GPS)", formatter_class=DefaultsHelpFormatter
    )
    victoria.add_argument("--data", required=True, type=Path, help="the victoria_park directory")
    victoria.add_argument(
        "--protocol",
        choices=PROTOCOLS,
        default="aligned",
        help="start from the first minute aligned to the GPS (aligned, default) or from the literature's "
        "start pose, scored also at the GPS fixes within 25 ms (published); docs/real_data.md",
    )
    for command in (mrclam, victoria):
        command.add_argument(
            "--out", type=Path, default=None, help="output directory (default: results/NAME)"
        )
        command.add_argument("--params", type=Path, default=None, help="YAML with noise: and slam: overrides")
        command.add_argument("--no-progress", dest="progress", action="store_false", help="no progress bar")
        command.add_argument("--no-plots", dest="plots", action="store_false", help="metrics.json only")
        command.add_argument(
            "--smooth",
            action="store_true",
            help="also smooth the whole run (poses, map, associations) and report it beside the filter",
        )
    calibrate = commands.add_parser(
        "calibrate",
        help="fit MRCLAM motion and measurement noise to its Vicon truth",
        formatter_class=DefaultsHelpFormatter,
    )
    calibrate.add_argument("--data", required=True, type=Path, help="an MRCLAM_DatasetN directory")
    calibrate.add_argument("--robot", required=True, type=int, choices=range(1, 6), help="robot 1..5")
    calibrate.add_argument(
        "--window",
        type=float,
        default=WINDOW_S,
        help=f"window length of the motion and command fits (s, default {WINDOW_S:g})",
    )
    calibrate.add_argument("--out", type=Path, default=None, help="params YAML (default: stdout)")
    calibrate.add_argument("--no-progress", dest="progress", action="store_false", help="no progress bar")
    return parser


def _progress(total: int, enabled: bool, label: str):
    from tqdm import tqdm

    return tqdm(total=total, unit="samples", desc=label, file=sys.stderr, disable=not enabled, leave=False)


def _write_run(
    args: argparse.Namespace,
    experiment: Experiment,
    evaluate: Callable[[Experiment, ExperimentResult], Evaluation],
    params: DatasetParams,
) -> dict:
    """Run ``experiment`` with a progress bar, evaluate it and write the outputs into ``args.out``."""
    import yaml

    from .figures import plot_error_comparison, plot_errors, plot_nees, plot_side_by_side, plot_trajectory

    say_previous_result(args.out)
    with _progress(len(experiment.motion_t_ns), args.progress, experiment.name) as bar:
        result = run_experiment(experiment, bar.update)
    evaluation = evaluate(experiment, result)
    metrics = {"run": experiment.name, **evaluation.metrics}
    if args.smooth:
        from .smoothing import smooth_run

        print(f"{experiment.name}: smoothing {len(result.t_ns)} poses", file=sys.stderr)
        smoothed, decisions = smooth_run(experiment, result, revise=experiment.scans.ids is None)
        smoothed_evaluation = evaluate(experiment, smoothed)
        metrics["smoothed"] = {**smoothed_evaluation.metrics, **decisions}
    # written into a staging folder that replaces args.out only once every file is there
    folder = RunFolder(args.out, OUTPUTS + SMOOTHED_OUTPUTS)
    try:
        write_metrics(folder.path, metrics)
        (folder.path / "params.yaml").write_text(
            yaml.safe_dump(params.as_dict(), sort_keys=False), encoding="utf-8"
        )
        if args.plots:
            plot_trajectory(folder.path / "trajectory.png", evaluation, experiment.name)
            plot_errors(folder.path / "errors.png", evaluation)
            plot_nees(folder.path / "nees.png", evaluation)
            if args.smooth:
                plot_side_by_side(
                    folder.path / "smoothed.png", evaluation, smoothed_evaluation, experiment.name
                )
                plot_error_comparison(folder.path / "smoothed_errors.png", evaluation, smoothed_evaluation)
    except BaseException:
        folder.discard()
        raise
    folder.complete()
    return metrics


SUMMARY_KEYS = (
    "ate_rmse_m",
    "ate_rmse_aligned_m",
    "ate_rmse_published_m",
    "published_fixes",
    "landmark_rmse_m",
    "landmark_rmse_aligned_m",
    "landmark_nees_mean",
    "landmarks_true",
    "landmarks_mapped",
    "landmarks_mapped_once",
    "landmarks_spurious",
    "landmarks_merged",
    "nees_pose_mean",
    "nees_pose_within_95_fraction",
    "cpu_seconds",
    "update_ms_median",
    "update_ms_p99",
)


def summary(metrics: dict) -> str:
    """The main figures, one line each (those the run has: MRCLAM has no published protocol); with a
    smoothed run, filter and smoother side by side."""
    smoothed = metrics.get("smoothed")
    lines = [metrics["run"]] + ([] if smoothed is None else [f"  {'':32s}{'filter':>12s}{'smoother':>12s}"])
    for key in (key for key in SUMMARY_KEYS if key in metrics):
        values = [metrics.get(key)] + ([] if smoothed is None else [smoothed.get(key)])
        shown = "".join(f"{v:>12.4g}" if isinstance(v, float) else f"{v!s:>12s}" for v in values)
        lines.append(f"  {key:32s}{shown}")
    return "\n".join(lines)


def main(argv: Sequence[str] | None = None) -> int:
    args = parse_args(argv)
    from .setups import VICTORIA_PARAMS, load_params, mrclam_experiment, mrclam_params, victoria_experiment

    try:
        if args.command == "calibrate":
            return _calibrate(args)
        if args.command == "mrclam":
            from .evaluation import evaluate_mrclam
            from .mrclam import load_mrclam

            args.out = args.out or Path("results") / f"mrclam_robot{args.robot}_{args.association}"
            _check_out(args.out)
            params = load_params(mrclam_params(args.association), args.params)
            recording = load_mrclam(args.data, args.robot)
            experiment = mrclam_experiment(recording, params, args.association)
            metrics = _write_run(args, experiment, lambda e, r: evaluate_mrclam(e, r, recording), params)
        else:
            from .evaluation import evaluate_victoria
            from .victoria import load_victoria

            args.out = args.out or Path("results") / "victoria_park"
            _check_out(args.out)
            params = load_params(VICTORIA_PARAMS, args.params)
            recording = load_victoria(args.data)
            experiment = victoria_experiment(recording, params, args.protocol)
            metrics = _write_run(
                args, experiment, lambda e, r: evaluate_victoria(e, r, recording, args.protocol), params
            )
    except (ValueError, OSError) as error:
        print(f"error: {error_line(error)}", file=sys.stderr)
        return 2
    print(summary(metrics))
    print(f"results in {args.out}")
    return 0


def _check_out(out: Path) -> None:
    """ValueError for an ``out`` the run may not replace or another run is writing (run_folder), before
    anything is read."""
    check_replaceable(out, OUTPUTS + SMOOTHED_OUTPUTS)
    check_no_other_run(out)


def _calibrate(args: argparse.Namespace) -> int:
    import yaml

    from .calibration import calibrate_mrclam
    from .mrclam import load_mrclam

    recording = load_mrclam(args.data, args.robot)
    with _progress(len(recording.odometry_t_ns), args.progress, "calibrating") as bar:
        fit = calibrate_mrclam(recording, args.window, bar.update)
    text = yaml.safe_dump(fit.params_dict(), sort_keys=False)
    print(fit.report(), file=sys.stderr)
    if args.out is None:
        print(text, end="")
    else:
        args.out.parent.mkdir(parents=True, exist_ok=True)
        args.out.write_text(text, encoding="utf-8")
        print(f"parameters in {args.out}", file=sys.stderr)
    return 0


if __name__ == "__main__":
    sys.exit(main())
