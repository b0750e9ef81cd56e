"""run_node survives any single message: an exception in a callback (rclpy's own time source included) is
logged and the node keeps spinning.

Issue: one /clock message with a negative ``sec`` killed turtle_control, odometry, landmarks and slam
(rclpy's ``Time.from_msg`` raised out of ``rclpy.spin``). Tested on the real executables, and in process on
``spin_once_guarded`` itself.
"""

from __future__ import annotations

import os
import signal
import subprocess
import sys
import time

import pytest
from builtin_interfaces.msg import Time
from nav_msgs.msg import Odometry
from rcl_interfaces.msg import Log
from rclpy.parameter import Parameter
from rosgraph_msgs.msg import Clock
from sensor_msgs.msg import JointState

from nuturtle_control.odometry import OdometryNode
from nuturtle_ros_common.node_main import spin_once_guarded
from rclpy_harness import matched, record_rosout

pytestmark = pytest.mark.ros

NODES = [
    "nuturtle_control.turtle_control",
    "nuturtle_control.odometry",
    "nuslam.landmarks_node",
    "nuslam.slam_node",
]
NEGATIVE_CLOCK = Clock(clock=Time(sec=-5, nanosec=0))


def joint_state(sec: int, angle: float) -> JointState:
    msg = JointState(name=["wheel_left_joint", "wheel_right_joint"], position=[angle, angle])
    msg.header.stamp = Time(sec=sec, nanosec=0)
    return msg


def errors_of(logs: list[Log], name: str) -> list[str]:
    return [log.msg for log in logs if log.name == name and log.level == Log.ERROR]


def test_every_node_executable_survives_a_negative_clock(ros, tmp_path):
    helper = ros.node("clock_attacker")
    logs = record_rosout(helper)
    clock = helper.create_publisher(Clock, "/clock", 10)
    # cwd outside the repository: its package folders would shadow the installed packages
    processes = {
        module: subprocess.Popen(
            [sys.executable, "-m", module, "--ros-args", "-p", "use_sim_time:=true"],
            cwd=tmp_path,
            stdout=subprocess.DEVNULL,
            stderr=subprocess.PIPE,
            text=True,
        )
        for module in NODES
    }
    try:
        # every node subscribes /clock (use_sim_time)
        assert ros.spin_until(lambda: clock.get_subscription_count() >= len(NODES), 30.0), "nodes not up"
        ros.spin_for(0.5)
        for _ in range(3):
            clock.publish(NEGATIVE_CLOCK)
            ros.spin_for(0.2)
        names = ["turtle_control", "odometry", "landmarks", "slam"]
        assert ros.spin_until(lambda: all(errors_of(logs, name) for name in names), 10.0), [
            name for name in names if not errors_of(logs, name)
        ]
        ros.spin_for(1.0)
        for module, process in processes.items():
            assert process.poll() is None, f"{module} died:\n{process.stderr.read()}"
        assert all("the node goes on" in errors_of(logs, name)[0] for name in names)
    finally:
        for process in processes.values():
            process.send_signal(signal.SIGINT)
        deadline = time.monotonic() + 20.0
        codes = {
            module: process.wait(max(0.1, deadline - time.monotonic()))
            for module, process in processes.items()
        }
    failed = {module: processes[module].stderr.read() for module, code in codes.items() if code != 0}
    assert not failed, f"each stops cleanly on Ctrl-C: {codes}\n{failed}"


def test_spin_once_guarded_logs_a_callback_exception_and_the_node_goes_on(ros):
    node = ros.add(
        OdometryNode(context=ros.context, parameter_overrides=[Parameter("use_sim_time", value=True)])
    )
    helper = ros.node("guarded_helper")
    logs = record_rosout(helper)
    clock = helper.create_publisher(Clock, "/clock", 10)
    joint_states = helper.create_publisher(JointState, "joint_states", 10)
    odoms: list[Odometry] = []
    odom = helper.create_subscription(Odometry, "odom", odoms.append, 10)
    assert ros.spin_until(lambda: matched(clock, joint_states, odom), 10.0)
    clock.publish(Clock(clock=Time(sec=7, nanosec=0)))
    assert ros.spin_until(lambda: node.get_clock().now().nanoseconds == 7 * 10**9, 5.0)
    clock.publish(NEGATIVE_CLOCK)
    raised = []
    deadline = time.monotonic() + 5.0
    while not raised and time.monotonic() < deadline:
        if not spin_once_guarded(ros.executor, node.get_logger(), timeout_sec=0.05):
            raised.append(True)
    assert raised, "rclpy's time source raised on the negative clock"
    assert node.get_clock().now().nanoseconds == 7 * 10**9, "the clock kept its last valid time"
    joint_states.publish(joint_state(1, 0.0))
    assert ros.spin_until(lambda: len(odoms) == 1, 5.0), "the node still works"
    ros.spin_for(0.2)
    (error,) = errors_of(logs, "odometry")
    assert "a callback raised ValueError" in error and "Seconds value must not be negative" in error


# the loaded OpenBLAS libraries' own thread counts (numpy's and scipy's), read through OpenBLAS's C API
BLAS_THREADS_PROBE = """
import ctypes, sys, importlib
importlib.import_module(sys.argv[1])
assert "numpy" not in sys.modules, "the package must come first"
import numpy, scipy.linalg
counts = {}
for path in sorted({line.split()[-1] for line in open("/proc/self/maps") if "openblas" in line}):
    library = ctypes.CDLL(path)
    getters = [n for n in ("scipy_openblas_get_num_threads64_", "scipy_openblas_get_num_threads",
                           "openblas_get_num_threads64_", "openblas_get_num_threads") if hasattr(library, n)]
    counts[path] = getattr(library, getters[0])()
print(sorted(set(counts.values())), len(counts))
"""


@pytest.mark.parametrize("given", [None, "2"])
@pytest.mark.parametrize("package", ["nuslam", "nuturtle_control", "nusim"])
def test_every_node_package_runs_openblas_on_one_thread_unless_told(package, given, tmp_path):
    """numpy's and scipy's OpenBLAS, as the libraries report it: a node's package (imported before its
    node module, before numpy) gives them one thread, and a value the user set wins (OpenBLAS caps it at
    the cores)."""
    env = {key: value for key, value in os.environ.items() if key != "OPENBLAS_NUM_THREADS"}
    if given is not None:
        env["OPENBLAS_NUM_THREADS"] = given
    result = subprocess.run(
        [sys.executable, "-P", "-c", BLAS_THREADS_PROBE, package],
        cwd=tmp_path, env=env, capture_output=True, text=True,
    )  # fmt: skip
    expected = 1 if given is None else min(int(given), os.cpu_count() or 1)
    assert result.stdout.strip() == f"[{expected}] 2", result.stderr[-2000:]
