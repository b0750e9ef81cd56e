"""`robot_side`: the four robot-side nodes in one process, on one /clock subscription, each working as in
its own process (a real process over DDS)."""

from __future__ import annotations

import signal
import subprocess
import sys

from builtin_interfaces.msg import Time
from nav_msgs.msg import Odometry
from rosgraph_msgs.msg import Clock
from sensor_msgs.msg import JointState

from rclpy_harness import matched

NODE_NAMES = {"turtle_control", "odometry", "slam", "landmarks"}


def joint_state(stamp_ns: int, angle: float) -> JointState:
    msg = JointState(name=["wheel_left_joint", "wheel_right_joint"], position=[angle, angle])
    msg.header.stamp = Time(sec=stamp_ns // 10**9, nanosec=stamp_ns % 10**9)
    return msg


def stamp_ns(msg: Odometry) -> int:
    return msg.header.stamp.sec * 10**9 + msg.header.stamp.nanosec


def test_robot_side_runs_the_four_nodes_on_one_clock_subscription(ros, tmp_path):
    helper = ros.node("robot_side_watcher")
    clock = helper.create_publisher(Clock, "/clock", 10)
    joint_states = helper.create_publisher(JointState, "joint_states", 10)
    odoms: dict[str, list[Odometry]] = {"odom": [], "slam/odom": []}
    subscriptions = [helper.create_subscription(Odometry, t, odoms[t].append, 10) for t in odoms]
    # cwd outside the repository: its package folders would shadow the installed packages
    process = subprocess.Popen(
        [sys.executable, "-P", "-m", "nuslam.robot_side", "--ros-args", "-p", "use_sim_time:=true"],
        cwd=tmp_path, stdout=subprocess.DEVNULL, stderr=subprocess.PIPE, text=True,
    )  # fmt: skip
    try:
        assert ros.spin_until(lambda: NODE_NAMES <= set(helper.get_node_names()), 30.0), "nodes not up"
        assert ros.spin_until(lambda: matched(clock, joint_states, *subscriptions), 10.0)
        ros.spin_for(0.5)
        assert clock.get_subscription_count() == 1, "one /clock subscription for the four nodes"
        clock.publish(Clock(clock=Time(sec=5, nanosec=0)))
        ros.spin_for(0.2)
        stamps = [5 * 10**9 + k * 10**8 for k in range(3)]
        for k, stamp in enumerate(stamps):
            joint_states.publish(joint_state(stamp, 0.1 * k))
            ros.spin_for(0.1)
        assert ros.spin_until(lambda: all(len(o) == len(stamps) for o in odoms.values()), 10.0), {
            topic: len(received) for topic, received in odoms.items()
        }
        assert {topic: [stamp_ns(m) for m in received] for topic, received in odoms.items()} == dict.fromkeys(
            odoms, stamps
        ), "odometry and slam each answer every joint_states, stamped with it"
        assert process.poll() is None
    finally:
        process.send_signal(signal.SIGINT)
        code = process.wait(20.0)
    stderr = process.stderr.read()
    assert code == 0, stderr[-3000:]
    assert "Traceback" not in stderr and "ERROR" not in stderr, stderr[-3000:]
