"""Command line of the bag replay: ``python -m nuturtle_tools.replay BAG [options]`` (``nuturtle-replay``,
``./dev.sh replay``).

Plays a recording (a rosbag2 bag directory of MCAP or sqlite3 storage, a single .mcap file such as the
demo's ``run/run.mcap``, or a ROS 1 .bag) with /clock into the real `landmarks` and `slam` nodes, as fast
as they keep up (no message dropped) or at ``--rate``, and writes ``slam/`` (the SLAM outputs, a rosbag2
MCAP bag), ``trajectory.png``, ``map.json``, ``covariance.png``, ``config.yaml`` and ``metrics.json`` (with
ground truth in the bag: ``errors.png`` and the accuracy metrics) into ``--out`` (docs/replay.md).
``--play-only`` runs only the player, for nodes of your own. Exit code 2 for an unreadable bag, a missing
topic, a bad option or params file, or a Foxglove port in use (one ``error:`` line, nothing written);
1 for a replay that failed once playing (a full disk) and, with ``--check``, for a failed target.
SIGINT, SIGTERM and SIGHUP end a replay alike: the outputs of what was played go to ``OUT.incomplete``.

The heavy modules (rclpy, the nodes, matplotlib) are imported only once the arguments are good.
"""

from __future__ import annotations

import os

if __name__ == "__main__":
    # One BLAS thread unless the caller says otherwise, set before numpy loads OpenBLAS (which reads it
    # once), as the demo and the dataset command do: slam's small matrices gain nothing from threads.
    os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")

import argparse
import math
import sys
from collections.abc import Sequence
from pathlib import Path
from typing import Any

from nuturtle_description.robot_params import add_model_argument
from nuturtle_eval.command_help import DefaultsHelpFormatter
from nuturtle_ros_common.dds_domain import add_domain_argument

from .relay_config import add_foxglove_argument, parse_endpoint

TOPIC_ROLES = ("scan", "joint_states", "odom", "truth", "fake_sensor")


def parse_args(argv: Sequence[str] | None = None) -> argparse.Namespace:
    return build_parser().parse_args(argv)


def build_parser() -> argparse.ArgumentParser:
    """The replay's command line."""
    parser = argparse.ArgumentParser(
        prog="python -m nuturtle_tools.replay",
        description="Replay a recording (MCAP or sqlite3 bag directory, a single .mcap, or a ROS 1 .bag) "
        "with /clock into the landmarks and slam nodes: SLAM outputs, trajectory, map and metrics.",
        formatter_class=DefaultsHelpFormatter,
    )
    parser.add_argument(
        "bag", type=Path, help="bag directory (metadata.yaml), a single .mcap / .db3 file or a ROS 1 .bag"
    )
    parser.add_argument("--out", type=Path, default=Path("out/replay"),
                        help="output folder, replaced as a whole when the replay completes (one stopped "
                        "early goes to OUT.incomplete)")  # fmt: skip
    parser.add_argument("--params", type=Path, default=None,
                        help="ROS params YAML; its slam and landmarks sections (and /**) go to those nodes "
                        "(default: the demo's config.yaml next to a demo recording, if there)")  # fmt: skip
    parser.add_argument("--association", choices=("known", "unknown"), default=None,
                        help="SLAM data association (default: the params file's, else unknown): LiDAR "
                        "landmarks from the scan, or landmark ids from the fake sensor topic")  # fmt: skip
    add_model_argument(parser)
    parser.add_argument("--motion-source", choices=("joint_states", "odom"), default=None,
                        help="slam's motion_source parameter "
                        "(default: the params file's, else the node's)")  # fmt: skip
    parser.add_argument("--namespace", default="", metavar="NS",
                        help="replay the robot recorded under the namespace NS (e.g. tb3_1 of a --robots 2 "
                        "demo bag): the topics below are then /NS/scan ..., the nodes run under NS with "
                        "the frames NS/odom, NS/base_footprint, NS/base_scan (default: none)")  # fmt: skip
    parser.add_argument(
        "--map-frame",
        default="",
        metavar="FRAME",
        help="slam's map frame (default: NS/map with --namespace, else the params file's)",
    )
    for role in TOPIC_ROLES:
        played = "nusim/ground_truth (metrics only)" if role == "truth" else role
        default = "/nusim/ground_truth" if role == "truth" else f"/{role}"
        parser.add_argument("--" + role.replace("_", "-") + "-topic", default=None, dest=f"{role}_topic",
                            help=f"bag topic played as {played} (default: {default}, under /NS with "
                            "--namespace)")  # fmt: skip
    parser.add_argument("--rate", type=float, default=None,
                        help="play at RATE x real time (log time against the wall clock); 0 = as fast as "
                        "the nodes keep up, nothing dropped (default; 1.0 with --play-only)")  # fmt: skip
    parser.add_argument("--play-only", action="store_true",
                        help="only the player and /clock, for your own nodes "
                        "(no landmarks or slam in this process)")  # fmt: skip
    parser.add_argument("--wait-for-subscribers", type=float, default=5.0, metavar="S",
                        help="with --play-only: wait up to S wall seconds for a subscriber on every played "
                        "topic before playing")  # fmt: skip
    parser.add_argument("--smooth", action="store_true",
                        help="also smooth slam's whole run at the end and write it beside the filter's "
                        "outputs (OUT/smoothed/, metrics.json 'smoothed')")  # fmt: skip
    parser.add_argument("--max-range-m", type=float, default=None, metavar="M",
                        help="cut the played scans to M metres, as a shorter-ranged LiDAR would see them "
                        "(range_max lowered, readings beyond it no return), e.g. 3.5 for an LDS-01 "
                        "(default: as recorded)")  # fmt: skip
    parser.add_argument("--no-progress", action="store_true", help="no progress bar on stderr")
    parser.add_argument("--check", action="store_true",
                        help="exit status 1 when a target of the results table fails (a nusim recording) "
                        "or the replay is stopped early (for CI)")  # fmt: skip
    add_foxglove_argument(parser, "--rate 1")
    add_domain_argument(parser, "private; env with --play-only, for your own nodes")
    return parser


def no_landmarks_hint(metrics: dict[str, Any]) -> str | None:
    """Why slam got no landmarks from the LiDAR, from the counts of ``metrics`` (metrics.json): no scan in
    the bag, none reaching the landmarks node, every one refused by it, or no cylinder found in them.
    None when some landmarks arrived, or the observations are the fake sensor's."""
    if metrics.get("observation_topic") != "landmarks" or metrics["map_landmarks"] > 0:
        return None
    played = metrics["scans_played"]
    received = metrics.get("scans_received_by_landmarks", 0)
    refused = metrics.get("scans_refused_by_landmarks", 0)
    if played == 0:
        return "no landmarks: the bag's scan topic has no messages"
    if received == 0:
        return f"no landmarks: none of the {played} scans played reached the landmarks node"
    if refused == received:
        return (
            f"no landmarks: the landmarks node refused all {refused} scans it received, the last because: "
            f"{metrics.get('last_scan_refusal', 'unknown')} (/diagnostics `landmarks: detector` counts them)"
        )
    return (
        f"no landmarks: the landmarks node took {received - refused} of {received} scans but slam mapped "
        "no cylinder (none of the detector's sizes in range? see landmarks/clusters in slam/)"
    )


def motion_gate_warning(metrics: dict[str, Any]) -> str | None:
    """What slam's motion gate refused, bridged and restarted, from ``metrics`` (metrics.json): a refused
    sample or a restart of the motion stream loses motion (a robot faster than the bounds slam was given is
    refused sample after sample); a bridged silence keeps the source's net motion across it, in one step.
    None when nothing was refused."""
    refused, restarts = metrics.get("slam_motion_samples_refused", 0), metrics.get("slam_motion_restarts", 0)
    if not refused and not restarts:
        return None
    bridged, longest_s = (
        metrics.get(k, 0) for k in ("slam_motion_silences_bridged", "slam_motion_longest_bridge_s")
    )
    return (
        f"warning: slam refused {refused} {metrics['motion_source']} samples, bridged {bridged} silences of "
        f"the stream (the longest {longest_s:.1f} s; the net motion across each kept as one step) and "
        f"restarted it {restarts} times (the motion across a restart is lost); the last: "
        f"{metrics['slam_motion_last_refusal']}. A robot that is not the model's describes itself with "
        "max_linear_speed, max_angular_speed (and wheel_radius, track_width, lidar_x ...; docs/robot.md); "
        "a source with long silences needs max_sample_gap, max_bridged_gap"
    )


def slam_line(metrics: dict[str, Any]) -> str:
    """What slam made of the bag, in one line, from ``metrics`` (metrics.json's ``slam_mode``,
    ``map_landmarks`` and ``slam_*`` counts): its mode, the landmarks in its map, the loops it closed, the
    relocalizations of its slip recovery and the scans it held."""
    mode, landmarks = metrics["slam_mode"], metrics["map_landmarks"]
    mapped = f"{landmarks} landmarks mapped" if mode == "mapping" else f"{landmarks} landmarks in its map"
    loops = metrics.get("slam_loops_closed")
    closed = "loop closure off" if loops is None else f"{loops} loops closed"
    return (
        f"slam: {mode}, {mapped}, {closed}, {metrics['slam_relocalizations']} relocalizations after slip, "
        f"{metrics['slam_scans_held']} scans held"
    )


def summary(result: Any) -> str:
    """The printed report: what slam made of the bag (:func:`slam_line`), the results table when there
    is ground truth (with the demo's targets for a nusim recording only), then the counts, the notes and
    why there are no landmarks if so."""
    metrics = result.metrics
    lines = [
        f"replayed {metrics['bag']} ({metrics['storage']}), association {metrics['association']}, "
        f"motion from {metrics['motion_source']}"
    ]
    if "slam_mode" in metrics:
        lines.append(slam_line(metrics))
    if result.interrupted is not None:
        lines.append(
            f"INCOMPLETE: interrupted by {result.interrupted}; the outputs cover what was played so far"
        )
    if result.accuracy:
        from nuturtle_eval.run_evaluation import results_table

        lines += ["", results_table(run_metrics(metrics), targets=metrics["nusim_recording"]), ""]
        if not metrics["nusim_recording"]:
            lines.append("(not a nusim recording: the demo's targets do not apply)")
    if "grid_found_fraction" in metrics:
        lines += [grid_agreement_line(metrics), ""]
    if "smoothed" in metrics:
        lines += smoothed_rows(metrics) + [""]
    rows = ["| count | value |", "|---|---:|"]
    for topic, count in metrics["messages_played"].items():
        rows.append(f"| messages played, {topic} | {count} |")
    for key in ("scans_received_by_landmarks", "scans_refused_by_landmarks"):
        if key in metrics:
            rows.append(f"| {key.replace('_', ' ')} | {metrics[key]} |")
    for key in ("observation_arrays_received", "observation_arrays_applied", "observation_arrays_skipped",
                "observation_arrays_pending"):  # fmt: skip
        if key in metrics:
            rows.append(f"| {key.replace('_', ' ')} ({metrics['observation_topic']}) | {metrics[key]} |")
    if "slam_grid_cells" in metrics:
        megabytes = metrics["slam_grid_bytes"] / 1e6, metrics["slam_grid_max_bytes"] / 1e6
        rows.append(f"| occupancy grid: cells / MB (at most) / scans past grid.max_size_m | "
                    f"{metrics['slam_grid_cells']} / {megabytes[0]:.1f} ({megabytes[1]:.1f}) / "
                    f"{metrics['slam_grid_scans_past_bound']} |")  # fmt: skip
    for key in ("slam_motion_samples_refused", "slam_motion_silences_bridged", "slam_motion_restarts",
                "slam_stalls"):  # fmt: skip
        if key in metrics:
            rows.append(f"| {key.replace('_', ' ')} | {metrics[key]} |")
    if "slam_loops_closed" in metrics:
        refused = metrics["slam_loop_candidates_refused"]
        reasons = ", ".join(f"{reason} {count}" for reason, count in refused.items())
        rows.append(f"| slam loops closed / candidates refused ({reasons or 'none'}) / keyframes | "
                    f"{metrics['slam_loops_closed']} / {sum(refused.values())} / "
                    f"{metrics['slam_loop_keyframes']} |")  # fmt: skip
        renders = metrics["slam_loop_grid_renders"]
        cpu_s = metrics["slam_loop_cpu_seconds"], metrics["slam_loop_grid_render_cpu_seconds"]
        rows.append(f"| slam loop closure CPU (s): steps / {renders} grid renderings | "
                    f"{cpu_s[0]:.1f} / {cpu_s[1]:.1f} |")  # fmt: skip
    if metrics.get("slam_loop_last_correction_m") is not None:
        rows.append(f"| slam last loop correction (m, rad) | {metrics['slam_loop_last_correction_m']:.3f}, "
                    f"{metrics['slam_loop_last_correction_rad']:+.3f} |")  # fmt: skip
    if metrics.get("slam_last_correction_m") is not None:
        rows.append(f"| slam last correction (m, rad) | {metrics['slam_last_correction_m']:.3f}, "
                    f"{metrics['slam_last_correction_rad']:+.3f} |")  # fmt: skip
    rows.append(f"| replay wall time (s) / bag time (s) | {metrics['replay_wall_seconds']:.1f} / "
                f"{metrics['bag_seconds']:.1f} |")  # fmt: skip
    lines += rows
    lines += [f"note: {note}" for note in metrics["notes"]]
    for hint in (no_landmarks_hint(metrics), motion_gate_warning(metrics)):
        if hint is not None:
            lines.append(hint)
    from nuturtle_eval.run_folder import outputs_line

    lines.append(outputs_line(result.out_dir))
    return "\n".join(lines)


def grid_agreement_line(metrics: dict[str, Any]) -> str:
    """slam's grid against the scans at the truth's poses (metrics.json's ``grid_*``), in one line."""
    found, unexplained = metrics["grid_found_fraction"], metrics["grid_unexplained_fraction"]
    return (
        f"grid agreement: {_percent(found)} of the {metrics['grid_reference_cells']} cells the scans hit at "
        f"the truth's poses found, {_percent(unexplained)} of the grid's {metrics['grid_occupied_cells']} "
        "occupied cells unexplained (within 0.10 m)"
    )


def _percent(fraction: float | None) -> str:
    return "n/a" if fraction is None else f"{100.0 * fraction:.1f} %"


# (metrics.json key, label) compared between the filter and the smoothed run
SMOOTHED_ROWS = (
    ("ate_rmse_slam_m", "ATE RMSE (m)"),
    ("final_position_error_slam_m", "final position error (m)"),
    ("final_heading_error_slam_rad", "final heading error (rad)"),
    ("landmark_rmse_m", "landmark RMSE (m)"),
    ("landmarks_mapped", "landmarks mapped"),
    ("landmarks_spurious", "landmarks spurious"),
)


def smoothed_rows(metrics: dict[str, Any]) -> list[str]:
    """The filter and the smoothed run side by side (the figures both have: not None, not NaN), then the
    smoother's CPU."""
    smoothed = metrics["smoothed"]
    rows = ["| | filter | smoother |", "|---|---:|---:|"]
    for key, label in SMOOTHED_ROWS:
        if _measured(metrics.get(key)) and _measured(smoothed.get(key)):
            values = [metrics[key], smoothed[key]]
            rows.append(
                f"| {label} | "
                + " | ".join(f"{v:.4f}" if isinstance(v, float) else str(v) for v in values)
                + " |"
            )
    rows.append(f"| smoother CPU (s) | | {smoothed['smoother_cpu_seconds']:.2f} |")
    return rows


def _measured(value: Any) -> bool:
    """A figure that was measured: neither None (not judged) nor NaN (could not be measured)."""
    return value is not None and not (isinstance(value, float) and math.isnan(value))


def recording_params(bag: Path) -> Path | None:
    """The demo's config.yaml beside its recording (``OUT/config.yaml`` for the bag ``OUT/run/`` or its file
    ``OUT/run/run.mcap``): the parameters the live run used, so a replay repeats it. None elsewhere."""
    bag_dir = bag if bag.is_dir() else bag.parent
    candidate = bag_dir.parent / "config.yaml"
    return candidate if candidate.is_file() else None


def main(argv: Sequence[str] | None = None) -> int:
    args = parse_args(argv)
    from nuturtle_eval.run_folder import error_line, unfinished_runs

    from .bag_source import BagError, BagSource

    try:
        BagSource(args.bag)  # checks the path before anything heavy is imported
        from .replay_run import ReplayOptions, default_topics, run_replay

        params = args.params if args.params is not None else recording_params(args.bag)
        if params is not None and args.params is None:
            print(f"parameters of the recorded run: {params} (--params to choose others)", file=sys.stderr)
        foxglove = None if args.foxglove is None else parse_endpoint(args.foxglove)
        options = ReplayOptions(
            bag=args.bag,
            out_dir=args.out,
            params=params,
            association=args.association,
            motion_source=args.motion_source,
            model=args.model,
            topics={
                role: getattr(args, f"{role}_topic") or default
                for role, default in default_topics(args.namespace.strip("/")).items()
            },
            rate=args.rate,
            play_only=args.play_only,
            wait_for_subscribers_s=args.wait_for_subscribers,
            progress=not args.no_progress,
            foxglove=foxglove,
            domain_id=getattr(args, "domain_id", None),
            smooth=args.smooth,
            max_range_m=args.max_range_m,
            namespace=args.namespace,
            map_frame=args.map_frame,
        )
        for path in unfinished_runs(options.out_dir):
            print(f"note: {path}/ holds a replay that was killed (INCOMPLETE)", file=sys.stderr)
        result = run_replay(options)
    except (BagError, ValueError, OSError, RuntimeError) as error:
        print(f"error: {error_line(error)}", file=sys.stderr)
        # a bad input (refused before anything was played) is 2, a replay that failed 1
        return 1 if getattr(error, "__notes__", None) else 2
    print(summary(result))
    failed = failed_targets(result)
    if result.interrupted is not None:
        failed.insert(0, f"the replay is incomplete ({result.interrupted})")
    if args.check and failed:
        print(f"check failed: {'; '.join(failed)}", file=sys.stderr)
        return 1
    return 0


def failed_targets(result: Any) -> list[str]:
    """The demo's targets the results table marks failed: a nusim recording with accuracy metrics only."""
    metrics = result.metrics
    if not (result.accuracy and metrics["nusim_recording"]):
        return []
    from nuturtle_eval.run_evaluation import failed_targets

    return failed_targets(run_metrics(metrics))


def run_metrics(metrics: dict[str, Any]) -> Any:
    """The :class:`nuturtle_eval.metrics.RunMetrics` in a replay's metrics.json values."""
    from nuturtle_eval.metrics import RunMetrics

    values = {key: metrics[key] for key in RunMetrics.__dataclass_fields__}
    values["nees_pose_band_95"] = tuple(values["nees_pose_band_95"])
    return RunMetrics(**values)


if __name__ == "__main__":
    sys.exit(main())
