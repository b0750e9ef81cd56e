"""Command line of the simulation + SLAM demo: ``python -m nuturtle_demo [options]`` (``./dev.sh run``).

Runs nusim, turtle_control, odometry, landmarks, slam and a figure-eight driver headless for two minutes of
robot time, faster than real time, then writes metrics.json, the figures, the occupancy grid, the
trajectories, the rosbag2 bag run/ (every topic: metadata.yaml + run.mcap) and config.yaml into the output
folder and prints a results table and every entry of that folder (docs/demo.md). With ``--robots N``
(N > 1) N robots drive the world, each with its own SLAM: a folder per robot (tb3_0/, ...) holds its
metrics.json and figures, summary.md a row per robot, and the printout each robot's results table and
that summary. The output folder is
replaced only by a complete run; a run stopped by SIGINT, SIGTERM or SIGHUP goes to OUT.incomplete. Exit
status: 2 for a bad input (one ``error:`` line, nothing written), 1 for a failed run, a failed save_map
or, with ``--check``, a failed target or a stopped run, else 0.
"""

from __future__ import annotations

import argparse
import sys
from collections.abc import Sequence
from pathlib import Path

from nuturtle_description.robot_params import add_model_argument
from nuturtle_eval.command_help import DefaultsHelpFormatter
from nuturtle_eval.run_evaluation import results_table
from nuturtle_eval.run_folder import error_line, outputs_line, unfinished_runs
from nuturtle_ros_common.dds_domain import add_domain_argument
from nuturtle_tools.relay_config import add_foxglove_argument, parse_endpoint

from .robot_stack import RobotResult, summary_table
from .run import (
    ASSOCIATIONS,
    BAG_NAME,
    MAX_ROBOTS,
    MODES,
    MOTION_SOURCES,
    DemoOptions,
    DemoResult,
    default_world,
    run_demo,
)


def parse_args(argv: Sequence[str] | None = None) -> argparse.Namespace:
    return build_parser().parse_args(argv)


def build_parser() -> argparse.ArgumentParser:
    """The demo's command line."""
    parser = argparse.ArgumentParser(
        prog="python -m nuturtle_demo",
        description="Headless simulation + EKF SLAM demo of a TurtleBot3: metrics, plots and a "
        "rosbag2 (MCAP) recording of every topic.",
        formatter_class=DefaultsHelpFormatter,
    )
    parser.add_argument("--association", choices=ASSOCIATIONS, default="unknown",
                        help="SLAM data association: landmark ids from nusim's fake sensor (known) or "
                        "cylinders detected in the LiDAR scan (unknown)")  # fmt: skip
    add_model_argument(parser)
    parser.add_argument("--world", type=Path, default=default_world(), help="nusim params YAML")
    parser.add_argument("--seed", type=int, default=0, help="seed of every noise stream of the simulator")
    parser.add_argument("--duration", type=float, default=120.0, help="simulation (robot) seconds to run")
    parser.add_argument("--out", type=Path, default=Path("out/latest"),
                        help="output folder, replaced as a whole when the run completes (a run stopped "
                        "early goes to OUT.incomplete)")  # fmt: skip
    parser.add_argument("--realtime", action="store_true",
                        help="pace the simulation at real time (to watch it live) "
                        "instead of as fast as it goes")  # fmt: skip
    parser.add_argument("--max-realtime-factor", type=float, default=20.0,
                        help="upper bound on simulated seconds per wall second "
                        "when not --realtime")  # fmt: skip
    parser.add_argument("--no-progress", action="store_true", help="no progress bar on stderr")
    parser.add_argument("--robots", type=int, default=1,
                        help=f"robots in the world (1 to {MAX_ROBOTS}), each with its own SLAM, named "
                        "tb3_0, tb3_1, ... (mapping only)")  # fmt: skip
    parser.add_argument("--check", action="store_true",
                        help="exit status 1 when a target of the results table fails or the run is "
                        "stopped early (for CI)")  # fmt: skip
    add_foxglove_argument(parser, "--realtime")
    add_domain_argument(parser)
    maps = parser.add_argument_group("maps and localization (docs/maps.md)")
    maps.add_argument("--motion-source", choices=MOTION_SOURCES, default="joint_states",
                      help="slam's motion input: the wheel angles or the odometry node's odom (the same "
                      "matched wheel slip as twist noise)")  # fmt: skip
    maps.add_argument("--map-file", type=Path, default=None,
                      help="slam's map file (JSON): loaded at start-up if it exists, "
                      "written by --save-map")  # fmt: skip
    maps.add_argument("--mode", choices=MODES, default="mapping",
                      help="slam's mode; localization keeps the loaded map fixed, starts slam at the map "
                      "origin and gives it the true start pose through initialpose")  # fmt: skip
    maps.add_argument("--save-map", action="store_true",
                      help="call slam's ~/save_map at the end of the run (needs --map-file)")  # fmt: skip
    maps.add_argument("--start", type=float, nargs=3, metavar=("X", "Y", "THETA"), default=None,
                      help="the robot's true start pose in nusim/world (m, m, rad) instead of the world "
                      "file's x0 y0 theta0")  # fmt: skip
    maps.add_argument("--initial-pose-std", type=float, nargs=3, metavar=("X", "Y", "THETA"),
                      default=(0.05, 0.05, 0.05),
                      help="standard deviations (m, m, rad) of the initialpose "
                      "given in localization")  # fmt: skip
    maps.add_argument("--route-radius", type=float, default=None,
                      help="the figure eight's loop radius (m) instead of the driver's 0.75")  # fmt: skip
    maps.add_argument("--route-start", type=float, default=0.0, metavar="S",
                      help="begin the figure eight S s into its route, the robot placed at the route's "
                      "pose there: continues a run that printed 'route: stopped S s in' (not with "
                      "--start)")  # fmt: skip
    return parser


def report(result: DemoResult, options: DemoOptions) -> str:
    lines = [
        f"model {options.model}, association {options.association}, seed {options.seed}, "
        f"world {options.world}",
        f"slam: {options.mode}, motion from {options.motion_source}"
        + ("" if options.map_file is None else f", map file {options.map_file}")
        + ("" if options.start is None else f", start {tuple(options.start)}"),
        "" if result.route is None else result.route.describe(),
        _route_line(result.route_time_s) if len(result.robots) == 1 else None,
        ""
        if result.interrupted is None
        else f"INCOMPLETE: interrupted by {result.interrupted} after {result.metrics.sim_seconds:.1f} of "
        f"{options.duration_s:.1f} s; the figures cover the time simulated so far; the last complete run is "
        f"still in {options.out_dir}/",
        *_robot_tables(result.robots),
        "",
        f"{result.message_count} messages on {len(result.recorded_topics)} topics recorded in the "
        f"rosbag2 bag {result.out_dir / BAG_NAME}/ (ros2 bag info / ros2 bag play)",
        outputs_line(result.out_dir),
    ]
    if result.saved_map is not None:
        success, message = result.saved_map
        lines.append(f"save_map: {'ok' if success else 'FAILED'}: {message}")
    return "\n".join(line for line in lines if line is not None)


def _route_line(route_time_s: float) -> str:
    """Where the route stopped, for the next session of one robot (several robots map once: no map_file)."""
    return f"route: stopped {route_time_s:.1f} s in (--route-start {route_time_s:.1f} goes on from there)"


def _robot_tables(robots: tuple[RobotResult, ...]) -> list[str]:
    """The one robot's results table, or each robot's under its name and then the summary of them all."""
    if len(robots) == 1:
        robot = robots[0]
        return [results_table(robot.metrics, more_rows=robot.grid_rows(), scope=robot.scope)]
    lines = []
    for robot in robots:
        T = robot.T_world_start
        lines += [
            f"robot {robot.name}, from ({T.x:.2f}, {T.y:.2f}, {T.theta:.3f}), outputs in {robot.out_dir}/:",
            results_table(robot.metrics, more_rows=robot.grid_rows(), scope=robot.scope),
            "",
        ]
    return [*lines, "every robot (summary.md):", summary_table(list(robots))]


def _failed(robots: tuple[RobotResult, ...]) -> list[str]:
    """Each robot's failed targets, named after the robot when there are several."""
    return [f"{robot.name}: {label}" if robot.name else label for robot in robots for label in robot.failed()]


def main(argv: Sequence[str] | None = None) -> int:
    args = parse_args(argv)
    try:
        foxglove = None if args.foxglove is None else parse_endpoint(args.foxglove)
        options = DemoOptions(
            association=args.association,
            model=args.model,
            world=args.world,
            seed=args.seed,
            duration_s=args.duration,
            out_dir=args.out,
            realtime=args.realtime,
            max_realtime_factor=args.max_realtime_factor,
            progress=not args.no_progress,
            motion_source=args.motion_source,
            map_file=args.map_file,
            mode=args.mode,
            save_map=args.save_map,
            start=args.start,
            initial_pose_std=tuple(args.initial_pose_std),
            route_radius=args.route_radius,
            route_start_s=args.route_start,
            foxglove=foxglove,
            domain_id=args.domain_id,
            robots=args.robots,
        )
    except ValueError as error:
        print(f"error: {error_line(error)}", file=sys.stderr)
        return 2
    for path in unfinished_runs(options.out_dir):
        print(f"note: {path}/ holds a run that was killed (INCOMPLETE); its bag is read by "
              f"python -m nuturtle_tools.replay {path}/{BAG_NAME}", file=sys.stderr)  # fmt: skip
    try:
        result = run_demo(options)
    except (OSError, ValueError, RuntimeError) as error:
        print(f"error: {error_line(error)}", file=sys.stderr)
        # a bad input (refused before the run started) is 2, a run that failed 1
        return 1 if getattr(error, "__notes__", None) else 2
    print(report(result, options))
    failed = _failed(result.robots)
    if result.interrupted is not None:
        failed.insert(0, f"the run is incomplete ({result.interrupted})")
    if args.check and failed:
        print(f"check failed: {'; '.join(failed)}", file=sys.stderr)
        return 1
    return 1 if result.saved_map is not None and not result.saved_map[0] else 0
