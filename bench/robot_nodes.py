"""Benchmark: CPU and memory of the robot-side nodes (landmarks, slam, odometry, turtle_control) run as a
user runs them and fed a recording at real-time rate (docs/benchmarks.md, "Robot-side nodes").

Layouts:

- ``separate``: each node is its own process, started with the command line `ros2 launch nuslam
  slam.launch.py` gives it: its config YAML, then the launch arguments as a ``/**`` parameter file
  (``nuslam.launch_nodes`` / ``nuturtle_control.launch_nodes``).
- ``one``: the four in one process (``nuslam robot_side``, what ``one_process:=true`` starts), with the same
  parameter files.

This process plays the nodes' inputs from the recording at real time: scan, joint_states and cmd_vel, and
with ``--time sim`` the recorded /clock (nusim's 100 Hz), every node on sim time; with ``--time wall`` no
/clock. Everything runs in a DDS domain of its own (discovery on localhost only). It subscribes to
``slam/odom`` only, to check that slam ran (a navigation stack's one input from slam).

Measured per node process, from just before the first message played to 0.5 s after the last (its work):
CPU (user + system time from /proc/PID/stat) per robot second played; at the end the resident memory
(VmRSS), the proportional share (Pss: shared library pages divided among the processes that map them,
so the Pss of several processes adds up to what they take together) and the peak (VmHWM).

Usage: .venv/bin/python -P bench/robot_nodes.py [--bag RUN] [--time sim|wall] [--layout separate|one|both]
       [--repeat N] [--write]
Without --bag a 60 s demo (seed 0, unknown association) is recorded first into a temporary folder.
"""

from __future__ import annotations

import argparse
import os
import signal
import subprocess
import sys
import tempfile
import time
from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

ROOT = Path(__file__).resolve().parents[1]
DOCS = ROOT / "docs" / "benchmarks.md"
SECTION = "## Robot-side nodes"
CLOCK_TICK_S = 1.0 / os.sysconf("SC_CLK_TCK")
# The played topics (bag name -> played name) and how many subscriptions of each the nodes hold (scan:
# landmarks and slam's occupancy grid; joint_states: odometry and slam)
INPUTS = {"/scan": "scan", "/joint_states": "joint_states", "/cmd_vel": "cmd_vel"}
SUBSCRIBERS = {"scan": 2, "joint_states": 2, "cmd_vel": 1}
NODE_MODULES = {
    "landmarks": "nuslam.landmarks_node",
    "slam": "nuslam.slam_node",
    "odometry": "nuturtle_control.odometry",
    "turtle_control": "nuturtle_control.turtle_control",
}
ONE_PROCESS_MODULE = "nuslam.robot_side"
START_TIMEOUT_S = 30.0
STOP_TIMEOUT_S = 10.0


@dataclass
class ProcessUse:
    """One node process: CPU-s between two samples and its memory at the end (MB)."""

    name: str
    cpu_s: float
    rss_mb: float
    pss_mb: float
    peak_mb: float


def cpu_seconds(pid: int) -> float:
    """User + system CPU time of process ``pid`` (s), from /proc/PID/stat (fields 14 and 15)."""
    fields = Path(f"/proc/{pid}/stat").read_text().rsplit(")", 1)[1].split()
    return (int(fields[11]) + int(fields[12])) * CLOCK_TICK_S


def memory_mb(pid: int) -> tuple[float, float, float]:
    """(VmRSS, Pss, VmHWM) of process ``pid`` in MB (1e6 bytes)."""

    def kilobytes(text: str, key: str) -> float:
        line = next(line for line in text.splitlines() if line.startswith(key + ":"))
        return float(line.split()[1])

    status = Path(f"/proc/{pid}/status").read_text()
    rollup = Path(f"/proc/{pid}/smaps_rollup").read_text()
    return tuple(
        k * 1.024e-3
        for k in (kilobytes(status, "VmRSS"), kilobytes(rollup, "Pss"), kilobytes(status, "VmHWM"))
    )


def node_parameters(use_sim_time: bool, model: str) -> dict[str, list[Any]]:
    """Each node's `parameters` list, as slam.launch.py builds it (unknown association)."""
    from nuslam.launch_nodes import landmarks_parameters, slam_parameters
    from nuturtle_control.launch_nodes import odometry_parameters, turtle_control_parameters

    return {
        "landmarks": landmarks_parameters(use_sim_time),
        "slam": slam_parameters("unknown", use_sim_time, model),
        "odometry": odometry_parameters(use_sim_time, model),
        "turtle_control": turtle_control_parameters(use_sim_time, model),
    }


def commands(
    layout: str, use_sim_time: bool, model: str, folder: Path, profile: Path | None = None
) -> dict[str, list[str]]:
    """The command line of each process of ``layout`` (name -> argv); with ``profile``, each runs under
    cProfile, which writes ``profile/<name>.prof`` when the process exits."""
    from nuturtle_ros_common.launch_parameters import ros_arguments

    if profile is not None:
        profile.mkdir(parents=True, exist_ok=True)

    def python(name: str) -> list[str]:
        profiler = [] if profile is None else ["-m", "cProfile", "-o", str(profile / f"{name}.prof")]
        return [sys.executable, "-P", *profiler, "-m"]

    if layout == "one":
        from nuslam.launch_nodes import robot_side_parameters

        parameters = robot_side_parameters("unknown", use_sim_time, model)
        arguments = ros_arguments(parameters, folder / "robot_side")
        return {"robot_side": [*python("robot_side"), ONE_PROCESS_MODULE, *arguments]}
    return {
        name: [*python(name), NODE_MODULES[name], *ros_arguments(parameters, folder / name)]
        for name, parameters in node_parameters(use_sim_time, model).items()
    }


def record_demo(folder: Path, duration_s: float) -> Path:
    """A demo run of ``duration_s`` robot seconds recorded under ``folder``; its bag folder."""
    out = folder / "demo"
    command = [sys.executable, "-P", "-m", "nuturtle_demo", "--duration", str(duration_s), "--out", str(out)]
    print(f"recording a {duration_s:g} s demo ...", file=sys.stderr)
    subprocess.run([*command, "--no-progress"], check=True, cwd=ROOT, stdout=subprocess.DEVNULL)
    return out / "run"


class Feeder:
    """Plays the nodes' inputs from ``bag`` at real time into domain ``domain_id`` (module docstring)."""

    def __init__(self, bag: Path, domain_id: int, use_sim_time: bool) -> None:
        import rclpy
        from rclpy.executors import SingleThreadedExecutor

        from nuturtle_tools.bag_source import BagSource
        from nuturtle_tools.player import BagPlayer, PlayedTopic, played_qos

        self.source = BagSource(bag).open()
        missing = sorted(set(INPUTS) - set(self.source.topics))
        if missing:
            raise SystemExit(f"error: {bag} has no {', '.join(missing)}")
        self.use_sim_time = use_sim_time
        self.context = rclpy.Context()
        rclpy.init(context=self.context, domain_id=domain_id)
        played = [
            PlayedTopic(name, INPUTS[name], topic.type_name, played_qos(topic, name == "/scan"))
            for name, topic in self.source.topics.items()
            if name in INPUTS
        ]
        self.player = BagPlayer(played, context=self.context)
        self.slam_odom = 0

        def count(_message: Any) -> None:
            self.slam_odom += 1

        from nav_msgs.msg import Odometry

        self.player.create_subscription(Odometry, "slam/odom", count, 10)
        self.executor = SingleThreadedExecutor(context=self.context)
        self.executor.add_node(self.player)

    def wait_for_nodes(self, processes: dict[str, subprocess.Popen]) -> None:
        """Until every input has its subscribers (and /clock on sim time: one per process, the nodes of one
        process share theirs) and slam/odom its publisher."""
        from nuturtle_tools.player import spin_until

        expected = dict(SUBSCRIBERS, **({"/clock": len(processes)} if self.use_sim_time else {}))

        def ready() -> bool:
            for name, process in processes.items():
                if process.poll() is not None:
                    raise SystemExit(f"error: {name} exited with {process.returncode} at start-up")
            counts = self.player.subscription_counts()
            subscribed = all(counts.get(name, 0) >= n for name, n in expected.items())
            return subscribed and self.player.count_publishers("slam/odom") > 0

        if not spin_until(self.executor, self.player.get_logger(), ready, START_TIMEOUT_S):
            raise SystemExit(
                f"error: the nodes did not subscribe within {START_TIMEOUT_S} s: "
                f"{self.player.subscription_counts()}"
            )
        time.sleep(1.0)  # the nodes' start-up work (parameters, first timers) settles

    def play(self) -> float:
        """Every input message (and /clock on sim time) at its log time's real-time pace; the robot
        seconds played."""
        from nuturtle_tools.player import Pacer, wait_until

        logger = self.player.get_logger()
        pacer = Pacer(1.0)
        names = [*INPUTS, *(["/clock"] if self.use_sim_time else [])]
        first_ns = last_ns = None
        for message in self.source.messages(names):
            wait_until(self.executor, logger, pacer.deadline_s(message.log_time_ns))
            if message.topic == "/clock":
                self.player.publish_clock(message.log_time_ns)
            else:
                self.player.publish_message(message)
            first_ns = message.log_time_ns if first_ns is None else first_ns
            last_ns = message.log_time_ns
        wait_until(self.executor, logger, time.monotonic() + 0.5)  # the last messages' work
        return (last_ns - first_ns) * 1e-9

    def close(self) -> None:
        import rclpy

        self.player.destroy_node()
        self.executor.shutdown()
        self.source.close()
        rclpy.try_shutdown(context=self.context)


def run_layout(
    bag: Path, layout: str, use_sim_time: bool, model: str, log_folder: Path, profile: Path | None = None
) -> tuple[float, list[ProcessUse], int]:
    """Start ``layout``'s processes, play ``bag`` into them; (robot seconds, per-process use, slam/odom
    messages heard)."""
    from nuturtle_ros_common.dds_domain import lease_domain

    lease = lease_domain()
    env = dict(os.environ, ROS_DOMAIN_ID=str(lease.domain_id), ROS_AUTOMATIC_DISCOVERY_RANGE="LOCALHOST")
    os.environ.update(ROS_AUTOMATIC_DISCOVERY_RANGE="LOCALHOST")
    os.environ.pop("ROS_LOCALHOST_ONLY", None)
    folder = log_folder / layout
    processes: dict[str, subprocess.Popen] = {}
    feeder = None
    try:
        for name, argv in commands(layout, use_sim_time, model, folder, profile).items():
            (folder / name).mkdir(parents=True, exist_ok=True)
            with (folder / f"{name}.log").open("w") as log:
                processes[name] = subprocess.Popen(
                    argv, env=env, cwd=ROOT, stdout=log, stderr=subprocess.STDOUT
                )
        feeder = Feeder(bag, lease.domain_id, use_sim_time)
        feeder.wait_for_nodes(processes)
        before = {name: cpu_seconds(p.pid) for name, p in processes.items()}
        robot_s = feeder.play()
        uses = [
            ProcessUse(name, cpu_seconds(p.pid) - before[name], *memory_mb(p.pid))
            for name, p in processes.items()
        ]
        return robot_s, uses, feeder.slam_odom
    finally:
        for process in processes.values():
            if process.poll() is None:
                process.send_signal(signal.SIGINT)
        for name, process in processes.items():
            try:
                process.wait(STOP_TIMEOUT_S)
            except subprocess.TimeoutExpired:
                process.kill()
                print(f"warning: {name} did not stop within {STOP_TIMEOUT_S} s", file=sys.stderr)
        if feeder is not None:
            feeder.close()
        lease.release()


def table(rows: Sequence[tuple[str, str, float, list[ProcessUse], int]]) -> str:
    """Markdown: per layout and clock, each process's CPU-s per robot second and memory, and the total."""
    lines = [
        "| layout | clock | process | CPU-s per robot s | RSS (MB) | Pss (MB) | peak RSS (MB) |",
        "|---|---|---|---:|---:|---:|---:|",
    ]
    for layout, clock, robot_s, uses, _heard in rows:
        for use in [
            *uses,
            ProcessUse(
                "**total**",
                *(sum(getattr(u, f) for u in uses) for f in ("cpu_s", "rss_mb", "pss_mb", "peak_mb")),
            ),
        ]:
            lines.append(
                f"| {layout} | {clock} | {use.name} | {use.cpu_s / robot_s:.3f} | {use.rss_mb:.0f} | "
                f"{use.pss_mb:.0f} | {use.peak_mb:.0f} |"
            )
    return "\n".join(lines)


def feed_description(bag: Path) -> str:
    """What was played: the recording's length and each played topic's rate."""
    from nuturtle_tools.bag_source import BagSource

    with BagSource(bag).open() as source:
        seconds = (source.end_ns - source.start_ns) / 1e9
        rates = ", ".join(
            f"`{name}` {source.topics[name].message_count / seconds:.0f} Hz"
            for name in [*INPUTS, "/clock"]
            if name in source.topics
        )
    played = f"`{bag.parent.name}/{bag.name}` ({seconds:.0f} s)"
    return f"Fed {played} at real time: {rates} (/clock on sim time only)."


def main(argv: Sequence[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument(
        "--bag", type=Path, help="a recording with /scan, /joint_states, /cmd_vel (and /clock)"
    )
    parser.add_argument(
        "--duration", type=float, default=60.0, help="robot seconds of the demo recorded without --bag"
    )
    parser.add_argument("--time", choices=("sim", "wall", "both"), default="sim")
    parser.add_argument("--layout", choices=("separate", "one", "both"), default="both")
    parser.add_argument("--model", default="burger")
    parser.add_argument(
        "--repeat", type=int, default=1, help="runs of each case; the one of least total CPU is kept"
    )
    parser.add_argument("--profile", type=Path, help="write each process's cProfile into this folder")
    parser.add_argument("--write", action="store_true", help=f"write the table into {DOCS.relative_to(ROOT)}")
    args = parser.parse_args(argv)
    with tempfile.TemporaryDirectory(prefix="robot-nodes-") as temp:
        folder = Path(temp)
        bag = args.bag if args.bag is not None else record_demo(folder, args.duration)
        layouts = ("separate", "one") if args.layout == "both" else (args.layout,)
        clocks = ("sim", "wall") if args.time == "both" else (args.time,)
        rows = []
        for layout in layouts:
            for clock in clocks:
                runs = []
                for k in range(args.repeat):
                    print(f"{layout}, {clock} time, run {k + 1} of {args.repeat} ...", file=sys.stderr)
                    runs.append(
                        run_layout(
                            bag, layout, clock == "sim", args.model, folder / f"{clock}{k}", args.profile
                        )
                    )
                robot_s, uses, heard = min(runs, key=lambda run: sum(u.cpu_s for u in run[1]))
                if heard == 0:
                    raise SystemExit(f"error: slam published nothing ({layout}, {clock} time): see the logs")
                rows.append((layout, clock, robot_s, uses, heard))
        text = table(rows)
    print(text)
    if args.write:
        header = (
            f"{SECTION}\n\n`.venv/bin/python -P bench/robot_nodes.py {' '.join(sys.argv[1:])}` "
            f"(x86_64, {os.cpu_count()} cores, "
            f"Python {sys.version.split()[0]}, {time.strftime('%Y-%m-%d')}). {feed_description(bag)}\n\n"
        )
        sys.path.insert(0, str(ROOT / "bench"))  # bench_docs
        from bench_docs import write_section

        write_section(SECTION, header + text, DOCS)
    return 0


if __name__ == "__main__":
    sys.exit(main())
