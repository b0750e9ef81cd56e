"""Every node stops cleanly, as a user (or launch, `timeout`, systemd, docker) stops it, and answers
``--help`` without starting.

Issue: a SIGINT to a launch's process group (a script, `timeout`, a service manager: launch then signals its
nodes a second time) ended every node with a KeyboardInterrupt traceback and exit code -2; rclpy's signal
handler shut the context down from its own thread while a callback ran (a callback ERROR with a 20-line
traceback: slam, nusim, the relay); SIGHUP killed every node without its stop; ``--help`` started the node.

Real processes started as the README runs them (``python -P -m <module> --ros-args ...``, each in its own
session so that its process group can be signalled), real signals, real DDS. All nodes start at once and
are stopped at once: node ``k`` gets SIGINT, SIGTERM or SIGHUP (``STOP_SIGNALS[k % 3]``: each signal on
several nodes, the handling being `run_node`'s, shared), then a second SIGINT during its stop. The nodes that
command motion are driven by real commands until the end and must leave a zero command as their last word.
"""

from __future__ import annotations

import importlib
import os
import re
import signal
import subprocess
import sys
import threading
import time
from collections.abc import Callable
from dataclasses import dataclass, field
from datetime import timedelta
from pathlib import Path

import pytest
from geometry_msgs.msg import Twist
from nav_msgs.msg import Odometry
from rclpy.node import Node
from ros_test_messages import cylinder_array, stamp
from sensor_msgs.msg import JointState
from visualization_msgs.msg import MarkerArray

from nuturtle_ros_common.node_main import STOP_DEADLINE_ENV, STOP_DEADLINE_S, stop_deadline_s
from nuturtle_ros_common.stop_signals import STOP_SIGNALS
from rclpy_harness import RosHarness, matched

pytestmark = pytest.mark.ros

# executable name -> (module, ROS arguments): the commanding nodes on topics of their own, so that the last
# message on each is that node's; turtle_control fed by this test with a command that never times out
NODES = {
    "nusim": ("nusim.nusim_node", []),
    "turtle_control": (
        "nuturtle_control.turtle_control",
        ["-r", "cmd_vel:=stops/cmd_vel", "-r", "wheel_cmd:=stops/wheel_cmd", "-p", "cmd_timeout:=0.0"],
    ),
    "odometry": ("nuturtle_control.odometry", []),
    "circle": ("nuturtle_control.circle", ["-r", "cmd_vel:=stops/circle_cmd_vel"]),
    "landmarks": ("nuslam.landmarks_node", []),
    "slam": ("nuslam.slam_node", []),
    "slam_side": ("nuslam.slam_side", []),
    "robot_side": (
        "nuslam.robot_side",
        [
            "-r",
            "cmd_vel:=stops/cmd_vel",
            "-r",
            "wheel_cmd:=stops/robot_side/wheel_cmd",
            "-p",
            "cmd_timeout:=0.0",
        ],
    ),
    "driver": (
        "nuturtle_demo.driver",
        ["-r", "cmd_vel:=stops/driver_cmd_vel", "-p", "start_delay:=0.0", "-p", "feedback:=false"],
    ),
    "foxglove_relay": ("nuturtle_tools.foxglove_relay", ["-p", "port:=0"]),
}
# the topic each commanding node's last message is read on, and that message's type
COMMANDS = {
    "turtle_control": ("stops/wheel_cmd", JointState),
    "robot_side": ("stops/robot_side/wheel_cmd", JointState),
    "circle": ("stops/circle_cmd_vel", Twist),
    "driver": ("stops/driver_cmd_vel", Twist),
}
# the second SIGINT comes once the node has logged that it stops on its first signal (its stop then takes
# 0.1-1.5 s), at most this long after the first: sent sooner, on a loaded machine both could be pending
# before the node's main thread runs a handler, and Python runs pending handlers in signal-number order
# (SIGINT, 2, before SIGTERM, 15)
SECOND_SIGNAL_AFTER_S = 10.0
# a node still running this long after its signal hangs (launch sends SIGTERM after 5 s, SIGKILL 5 s later)
HANG_S = 10.0


@dataclass
class Run:
    """One started node process: what it wrote on stderr, and once it has ended its exit code and the time
    from its first stop signal to its end."""

    process: subprocess.Popen
    stderr: list[str] = field(default_factory=list)
    started: threading.Event = field(default_factory=threading.Event)
    stop_s: float | None = None

    def read(self) -> None:
        for line in self.process.stderr:
            self.stderr.append(line)
            if "parameters:" in line:
                self.started.set()
        self.started.set()

    @property
    def text(self) -> str:
        return "".join(self.stderr)


def start(module: str, arguments: list[str], cwd: Path) -> Run:
    """``python -P -m module arguments`` in its own session, stderr read by a thread (cwd outside the
    repository, whose package folders would shadow the installed packages)."""
    return start_python(["-m", module, *arguments], cwd)


def start_python(arguments: list[str], cwd: Path, env: dict[str, str] | None = None) -> Run:
    """``python -P arguments`` as :func:`start` runs it (``env`` added to the environment)."""
    process = subprocess.Popen(
        [sys.executable, "-P", *arguments], cwd=cwd, stdout=subprocess.PIPE,
        stderr=subprocess.PIPE, text=True, start_new_session=True, env={**os.environ, **(env or {})},
    )  # fmt: skip
    run = Run(process)
    threading.Thread(target=run.read, daemon=True).start()
    return run


def command(helper: Node, topic: str, message_type: type, received: dict[str, list]) -> None:
    received[topic] = []
    helper.create_subscription(message_type, topic, received[topic].append, 10)


def is_zero(message: Twist | JointState) -> bool:
    if isinstance(message, JointState):
        return list(message.velocity) == [0.0, 0.0]
    return message == Twist()


def end(runs: dict[str, Run], ros: RosHarness, during: Callable[[], object] = lambda: None) -> None:
    """Spin (calling ``during`` each step) until every run has ended or HANG_S has passed since now; record
    each one's stop time; kill what still runs."""
    t0 = time.monotonic()
    while any(run.process.poll() is None for run in runs.values()) and time.monotonic() - t0 < HANG_S:
        during()
        ros.spin_for(0.02)
        for run in runs.values():
            if run.stop_s is None and run.process.poll() is not None:
                run.stop_s = time.monotonic() - t0
    for run in runs.values():
        if run.process.poll() is None:
            os.killpg(run.process.pid, signal.SIGKILL)
        run.process.wait()


@pytest.fixture(scope="module")
def stopped(tmp_path_factory) -> tuple[dict[str, Run], dict[str, list]]:
    """Every node started at once, driven, stopped by its signal and a second SIGINT: the runs, and every
    command message received per topic."""
    ros = RosHarness()
    helper = ros.node("stop_watcher")
    feed = helper.create_publisher(Twist, "stops/cmd_vel", 10)
    received: dict[str, list] = {}
    for topic, message_type in COMMANDS.values():
        command(helper, topic, message_type, received)
    cwd = tmp_path_factory.mktemp("stops")
    runs = {
        name: start(module, ["--ros-args", *arguments], cwd) for name, (module, arguments) in NODES.items()
    }
    driving = Twist()
    driving.linear.x = 0.1
    try:
        assert all(run.started.wait(60.0) for run in runs.values()), "nodes not up"

        def moving() -> bool:
            feed.publish(driving)
            return all(any(not is_zero(m) for m in received[topic]) for topic, _ in COMMANDS.values())

        assert ros.spin_until(moving, 20.0), {topic: len(messages) for topic, messages in received.items()}
        for k, run in enumerate(runs.values()):
            os.killpg(run.process.pid, STOP_SIGNALS[k % len(STOP_SIGNALS)])

        def stopping() -> bool:
            return all(
                f"{STOP_SIGNALS[k % len(STOP_SIGNALS)].name}: stopping" in run.text
                or run.process.poll() is not None
                for k, run in enumerate(runs.values())
            )

        ros.spin_until(stopping, SECOND_SIGNAL_AFTER_S)
        for run in runs.values():
            if run.process.poll() is None:
                os.killpg(run.process.pid, signal.SIGINT)
        # the commands go on until every node has ended: turtle_control's last word is its own
        end(runs, ros, lambda: feed.publish(driving))
        ros.spin_for(0.2)
        return runs, received
    finally:
        for run in runs.values():
            if run.process.poll() is None:
                os.killpg(run.process.pid, signal.SIGKILL)
                run.process.wait()
        ros.shutdown()


@pytest.mark.parametrize("name", NODES)
def test_every_node_stops_cleanly_on_its_signal_and_a_second_sigint(stopped, name):
    runs, _ = stopped
    run = runs[name]
    k = list(NODES).index(name)
    assert run.stop_s is not None, f"{name} still ran {HANG_S} s after its signal:\n{run.text[-3000:]}"
    assert run.process.returncode == 0, run.text[-3000:]
    assert "Traceback" not in run.text and "ERROR" not in run.text, run.text[-3000:]
    assert f"{STOP_SIGNALS[k % len(STOP_SIGNALS)].name}: stopping" in run.text, run.text[-3000:]


@pytest.mark.parametrize("name", COMMANDS)
def test_a_commanding_node_leaves_a_zero_command_when_it_stops(stopped, name):
    _, received = stopped
    topic, _ = COMMANDS[name]
    messages = received[topic]
    assert any(not is_zero(message) for message in messages), "it was commanding motion"
    assert is_zero(messages[-1]), messages[-1]


@pytest.mark.parametrize(("name", "option"), [("foxglove_relay", "--help"), ("driver", "-h")])
def test_a_node_executable_answers_help_without_starting(name, option, tmp_path):
    """As the issue found them: these two started their node on ``--help``."""
    module, arguments = NODES[name]
    result = subprocess.run(
        [sys.executable, "-P", "-m", module, option, "--ros-args", *arguments],
        cwd=tmp_path, capture_output=True, text=True, timeout=60,
    )  # fmt: skip
    assert result.returncode == 0, result.stderr[-3000:]
    assert result.stdout.startswith(f"usage: {name} [-h] [--ros-args ...]"), result.stdout[:300]
    assert result.stderr == "", "nothing started, nothing logged"


@pytest.mark.parametrize("name", NODES)
def test_every_node_main_answers_help_with_its_parameters(name, capsys):
    """Every node's ``main`` (what its console script and ``python -m`` call), in this process: the usage,
    the node's documentation with its parameters, how to pass ROS arguments; exit 0 before any rclpy.init."""
    module, arguments = NODES[name]
    with pytest.raises(SystemExit) as stop:
        importlib.import_module(module).main([name, "--help", "--ros-args", *arguments])
    assert stop.value.code == 0
    usage = capsys.readouterr().out
    assert usage.startswith(f"usage: {name} [-h] [--ros-args ...]"), usage[:300]
    assert "Parameters" in usage and "-p NAME:=VALUE" in usage and "SIGTERM" in usage, usage


def test_a_node_refuses_an_argument_it_does_not_know_and_a_params_file_rcl_cannot_read(capsys, tmp_path):
    main = importlib.import_module(NODES["slam"][0]).main
    with pytest.raises(SystemExit) as stop:
        main(["slam", "--bogus"])
    assert stop.value.code == 2
    assert "slam: error: unrecognized arguments: --bogus" in capsys.readouterr().err
    broken = tmp_path / "broken.yaml"
    broken.write_text("slam: {ros__parameters: {association: [known")
    with pytest.raises(SystemExit) as stop:
        main(["slam", "--ros-args", "--params-file", str(broken)])
    assert stop.value.code == 2
    error = capsys.readouterr().err
    assert error.splitlines()[-1].startswith(
        "slam: error: Failed to parse ROS arguments: Couldn't parse params"
    )


def test_slam_stops_cleanly_while_busy(ros, tmp_path):
    """slam flooded with wheel angles and landmark arrays (each applied scan publishes its pose, path and
    map), stopped by SIGTERM (what launch sends after its timeout) in the middle: no callback may fail on a
    context that goes down under it (before: "a callback raised RCLError: Failed to publish: publisher's
    context is invalid" with its traceback)."""
    helper = ros.node("slam_feeder")
    joint_states = helper.create_publisher(JointState, "joint_states", 100)
    landmarks = helper.create_publisher(MarkerArray, "landmarks", 100)
    outputs = []
    odom_subscription = helper.create_subscription(Odometry, "slam/odom", outputs.append, 100)
    run = start("nuslam.slam_node", [], tmp_path)
    points = [(k, 0.5 + 0.1 * k, (-1) ** k * 0.4) for k in range(8)]
    angle = [0.0]

    def feed() -> None:
        now_ns = helper.get_clock().now().nanoseconds
        angle[0] += 0.002
        message = JointState(name=["wheel_left_joint", "wheel_right_joint"], position=[angle[0]] * 2)
        message.header.stamp = stamp(now_ns)
        joint_states.publish(message)
        landmarks.publish(cylinder_array("base_scan", now_ns, points))

    try:
        assert run.started.wait(60.0), run.text[-3000:]
        assert ros.spin_until(lambda: matched(joint_states, landmarks, odom_subscription), 20.0)
        deadline = time.monotonic() + 10.0
        while len(outputs) < 50 and time.monotonic() < deadline:
            feed()
            ros.spin_for(0.005)
        assert len(outputs) >= 50, "slam is busy"
        os.killpg(run.process.pid, signal.SIGTERM)
        end({"slam": run}, ros, feed)
    finally:
        if run.process.poll() is None:
            os.killpg(run.process.pid, signal.SIGKILL)
            run.process.wait()
    assert run.stop_s is not None, run.text[-3000:]
    assert run.process.returncode == 0, run.text[-3000:]
    assert "Traceback" not in run.text and "ERROR" not in run.text, run.text[-3000:]


# A node whose safe stop never returns (a driver blocked on its serial port, a middleware that deadlocks)
STUCK_NODE = """
import sys, time
from rclpy.node import Node
from nuturtle_ros_common.node_main import run_node

class StuckStop(Node):
    def __init__(self):
        super().__init__("stuck_stop")

    def stop(self):
        time.sleep(3600.0)

sys.exit(run_node(StuckStop, "stuck_stop", "stop() never returns", ["stuck_stop", "--ros-args"]))
"""


def test_a_stop_that_never_ends_ends_the_process_by_the_deadline_and_says_where_it_was(tmp_path):
    """Issue: in CI turtle_control logged "SIGTERM: stopping" and was still there 10 s later (killed: exit
    code -9, no word of where it hung). Past the stop deadline (here 1 s, set by ``NUTURTLE_STOP_DEADLINE_S``
    as a launch with a shorter SIGKILL would; ``STOP_DEADLINE_S`` by default) from the start of its stop the
    process prints every thread's stack and exits with code 1, whatever it is blocked in."""
    run = start_python(["-c", STUCK_NODE], tmp_path, env={STOP_DEADLINE_ENV: "1"})
    try:
        assert run.started.wait(60.0), run.text[-3000:]
        os.killpg(run.process.pid, signal.SIGTERM)
        run.process.wait(timeout=1.0 + HANG_S)
    finally:
        if run.process.poll() is None:
            os.killpg(run.process.pid, signal.SIGKILL)
            run.process.wait()
    assert run.process.returncode == 1, run.text[-3000:]
    assert "SIGTERM: stopping" in run.text, run.text[-3000:]
    assert f"Timeout ({timedelta(seconds=1)})!" in run.text, run.text[-3000:]
    assert re.search(r'File "<string>", line \d+ in stop\n', run.text), run.text[-3000:]


@pytest.mark.parametrize("value", ["0", "-1", "nan", "inf", "eight"])
def test_an_invalid_stop_deadline_is_refused(monkeypatch, value):
    monkeypatch.setenv(STOP_DEADLINE_ENV, value)
    with pytest.raises(ValueError, match=STOP_DEADLINE_ENV):
        stop_deadline_s()


def test_the_stop_deadline_is_the_default_unless_set(monkeypatch):
    monkeypatch.delenv(STOP_DEADLINE_ENV, raising=False)
    assert stop_deadline_s() == STOP_DEADLINE_S
    monkeypatch.setenv(STOP_DEADLINE_ENV, "2.5")
    assert stop_deadline_s() == 2.5
