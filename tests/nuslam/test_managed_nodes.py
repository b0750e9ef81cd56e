"""`slam_managed` and `landmarks_managed` (`nuslam.managed_nodes`) driven as a lifecycle manager drives them:
through their real lifecycle services (lifecycle_msgs ChangeState, GetState, GetAvailableTransitions) over
DDS, by transition id as nav2's lifecycle_manager asks.

Expected poses come from turtlelib: slam's start pose composed with the odometry's relative poses.
"""

from __future__ import annotations

import signal
import subprocess
import sys

import pytest
from lifecycle_msgs.msg import Transition
from lifecycle_msgs.srv import ChangeState, GetAvailableTransitions, GetState
from nav_msgs.msg import Odometry
from rcl_interfaces.msg import Log
from rclpy.node import Node
from rclpy.parameter import Parameter
from rclpy.parameter_client import AsyncParameterClient
from rclpy.qos import qos_profile_sensor_data
from ros_test_messages import scan_message
from sensor_msgs.msg import LaserScan
from test_landmarks_node import T0_NS, scan_ranges
from test_slam_node import S, close_pose, pose_of
from test_slam_odom_input import odom_at
from visualization_msgs.msg import MarkerArray

from nuslam.managed_nodes import ManagedLandmarksNode, ManagedSlamNode
from rclpy_harness import matched, record_rosout, rosout_matched
from turtlelib import Transform2D

pytestmark = pytest.mark.ros

# how long a test waits to be sure that nothing comes (s)
QUIET_S = 0.3


class Lifecycle:
    """The lifecycle services of node ``name``, called from ``helper`` (what a lifecycle manager does)."""

    def __init__(self, ros, helper: Node, name: str) -> None:
        self.ros = ros
        self.change_state = helper.create_client(ChangeState, f"{name}/change_state")
        self.get_state = helper.create_client(GetState, f"{name}/get_state")
        self.get_transitions = helper.create_client(
            GetAvailableTransitions, f"{name}/get_available_transitions"
        )
        clients = (self.change_state, self.get_state, self.get_transitions)
        assert ros.spin_until(lambda: all(c.service_is_ready() for c in clients), 30.0), (
            "no lifecycle services"
        )

    def _call(self, client, request):
        future = client.call_async(request)
        assert self.ros.spin_until(future.done, 10.0), f"{client.srv_name} did not answer"
        return future.result()

    def transition(self, transition_id: int) -> bool:
        """ChangeState by id; its ``success``."""
        return self._call(
            self.change_state, ChangeState.Request(transition=Transition(id=transition_id))
        ).success

    def state(self) -> str:
        return self._call(self.get_state, GetState.Request()).current_state.label

    def available(self) -> set[str]:
        """The labels of the transitions available now."""
        response = self._call(self.get_transitions, GetAvailableTransitions.Request())
        return {item.transition.label for item in response.available_transitions}


def errors_of(logs: list[Log], name: str) -> list[str]:
    return [log.msg for log in logs if log.name == name and log.level == Log.ERROR]


def set_remotely(ros, helper: Node, node: str, parameter: Parameter):
    """Set ``parameter`` of ``node`` through its parameter service (what ``ros2 param set`` does); the
    SetParametersResult."""
    client = AsyncParameterClient(helper, node)
    assert ros.spin_until(client.services_are_ready, 10.0)
    future = client.set_parameters([parameter])
    assert ros.spin_until(future.done, 10.0)
    return future.result().results[0]


def test_slam_is_configured_activated_deactivated_reactivated_cleaned_up_and_shut_down(ros):
    T0 = Transform2D(0.5, -0.25, 0.7)
    parameters = {"motion_source": "odom", "scan_registration": False, "max_sample_gap": 1.0}
    parameters |= {"x0": T0.x, "y0": T0.y, "theta0": T0.theta, "observation_timeout": 100.0}
    overrides = [Parameter(name, value=value) for name, value in parameters.items()]
    node = ros.add(ManagedSlamNode(context=ros.context, parameter_overrides=overrides))
    helper = ros.node("slam_lifecycle_manager")
    lifecycle = Lifecycle(ros, helper, "slam")
    odom = helper.create_publisher(Odometry, "odom", 10)
    poses: list[Odometry] = []
    output = helper.create_subscription(Odometry, "slam/odom", poses.append, 10)

    def publish(t_ns: int, T_odom_body: Transform2D, answered: bool) -> None:
        count = len(poses)
        odom.publish(odom_at(t_ns, T_odom_body))
        if answered:
            assert ros.spin_until(lambda: len(poses) > count, 5.0), "no slam/odom"
        else:
            ros.spin_for(QUIET_S)
            assert len(poses) == count, "slam answered while not active"

    assert lifecycle.state() == "unconfigured"
    assert lifecycle.available() == {"configure", "shutdown"}
    assert helper.count_subscribers("odom") == 0, "unconfigured: no topics yet"

    assert lifecycle.transition(Transition.TRANSITION_CONFIGURE)
    assert lifecycle.state() == "inactive"
    assert ros.spin_until(lambda: matched(odom, output), 10.0)
    publish(9 * S, Transform2D(), answered=False)

    assert lifecycle.transition(Transition.TRANSITION_ACTIVATE)
    assert lifecycle.state() == "active"
    # the odometry's frame is its own: slam moves by its relative poses from the start pose
    T_odom_first = Transform2D(3.0, 1.0, -2.0)
    step = Transform2D(0.05, 0.0, 0.1)
    publish(10 * S, T_odom_first, answered=True)
    assert close_pose(poses[-1], T0)
    publish(10 * S + S // 2, T_odom_first @ step, answered=True)
    assert close_pose(poses[-1], T0 @ step)

    assert lifecycle.transition(Transition.TRANSITION_DEACTIVATE)
    assert lifecycle.state() == "inactive"
    # the robot drives on while slam is inactive: its odometry is not taken
    publish(11 * S, T_odom_first @ step @ step, answered=False)
    publish(11 * S + S // 2, T_odom_first @ step @ step @ step, answered=False)

    assert lifecycle.transition(Transition.TRANSITION_ACTIVATE)
    # 1.5 s of silence > max_sample_gap: the first samples after it are held until restart_samples (3) of
    # them agree, then the silence is bridged: the motion made while inactive is kept, on the kept estimate
    T_odom_back = [T_odom_first @ step @ step @ step @ step]
    T_odom_back += [T_odom_back[0] @ step, T_odom_back[0] @ step @ step]
    publish(12 * S, T_odom_back[0], answered=False)
    publish(12 * S + S // 2, T_odom_back[1], answered=False)
    publish(13 * S, T_odom_back[2], answered=True)
    assert ros.spin_until(lambda: len(poses) == 5, 5.0), "the three samples after the silence, each a pose"
    expected = T0 @ T_odom_first.inverse() @ T_odom_back[2]
    assert close_pose(poses[-1], expected), (pose_of(poses[-1]), expected)

    assert lifecycle.transition(Transition.TRANSITION_DEACTIVATE)
    assert lifecycle.transition(Transition.TRANSITION_CLEANUP)
    assert lifecycle.state() == "unconfigured"
    assert not hasattr(node, "timeline"), "cleanup drops the estimate"
    assert ros.spin_until(lambda: helper.count_subscribers("odom") == 0, 5.0), "cleanup drops the topics"
    assert lifecycle.transition(Transition.TRANSITION_UNCONFIGURED_SHUTDOWN)
    assert lifecycle.state() == "finalized"
    assert node.finalized


def test_a_bad_parameter_fails_configure_with_its_reason_and_the_node_stays_unconfigured(ros):
    node = ros.add(
        ManagedLandmarksNode(context=ros.context, parameter_overrides=[Parameter("range_std", value=-0.02)])
    )
    helper = ros.node("landmarks_lifecycle_manager")
    logs = record_rosout(helper)
    assert ros.spin_until(lambda: rosout_matched(helper), 10.0)
    lifecycle = Lifecycle(ros, helper, "landmarks")

    assert not lifecycle.transition(Transition.TRANSITION_CONFIGURE)
    assert lifecycle.state() == "unconfigured"
    assert ros.spin_until(lambda: errors_of(logs, "landmarks"), 5.0)
    (error,) = errors_of(logs, "landmarks")
    assert "configure failed" in error and "range_std" in error, error
    assert not node.configured

    # unconfigured, the parameter can be fixed; configured, it cannot (read at configure only)
    assert set_remotely(ros, helper, "landmarks", Parameter("range_std", value=0.02)).successful
    assert lifecycle.transition(Transition.TRANSITION_CONFIGURE)
    refused = set_remotely(ros, helper, "landmarks", Parameter("range_std", value=0.03))
    assert not refused.successful and "read at configure only" in refused.reason
    assert node.config.range_std == 0.02

    scans = helper.create_publisher(LaserScan, "scan", qos_profile_sensor_data)
    arrays: list[MarkerArray] = []
    output = helper.create_subscription(MarkerArray, "landmarks", arrays.append, 10)
    assert ros.spin_until(lambda: matched(scans, output), 10.0)
    assert lifecycle.transition(Transition.TRANSITION_ACTIVATE)
    scans.publish(scan_message(T0_NS, scan_ranges()))
    assert ros.spin_until(lambda: len(arrays) == 1, 5.0), "active: a scan gives its landmarks"
    assert lifecycle.transition(Transition.TRANSITION_DEACTIVATE)
    scans.publish(scan_message(T0_NS + S // 5, scan_ranges()))
    ros.spin_for(QUIET_S)
    assert len(arrays) == 1, "inactive: no output"
    assert lifecycle.transition(Transition.TRANSITION_INACTIVE_SHUTDOWN)
    assert lifecycle.state() == "finalized"


def test_slam_managed_starts_unconfigured_and_its_process_ends_after_a_shutdown_from_active(ros, tmp_path):
    helper = ros.node("slam_managed_manager")
    # a name of its own: an in-process slam of an earlier test may still be in the graph
    renamed = ["--ros-args", "-r", "__node:=slam_process"]
    # cwd outside the repository: its package folders would shadow the installed packages
    process = subprocess.Popen(
        [sys.executable, "-P", "-c", "from nuslam.managed_nodes import slam_main; slam_main()", *renamed],
        cwd=tmp_path, stdout=subprocess.DEVNULL, stderr=subprocess.PIPE, text=True,
    )  # fmt: skip
    try:
        lifecycle = Lifecycle(ros, helper, "slam_process")
        assert lifecycle.state() == "unconfigured"
        assert lifecycle.transition(Transition.TRANSITION_CONFIGURE)
        assert lifecycle.transition(Transition.TRANSITION_ACTIVATE)
        assert lifecycle.transition(Transition.TRANSITION_ACTIVE_SHUTDOWN)
        code = process.wait(10.0)
    finally:
        if process.poll() is None:
            process.send_signal(signal.SIGINT)
            process.wait(20.0)
    stderr = process.stderr.read()
    assert code == 0, stderr[-3000:]
    assert "Traceback" not in stderr and "ERROR" not in stderr, stderr[-3000:]
