"""Fuzz tests of every node: hypothesis-drawn hostile messages (hostile_messages.py) published into the real
nodes, in process over real DDS.

* Liveness, one test per node (a fresh node per example): after a drawn batch of hostile messages on each of
  its inputs (accepted or refused), no callback has raised, everything the node published has finite values
  and valid stamps, and clean messages still give the outputs they should.
* Clock: the four nodes that run on /clock (use_sim_time) after hostile /clock messages: rclpy's own time
  source raises inside its callback for a negative sec (the only exceptions allowed), and the nodes keep
  working on the next valid clock.
* Estimate unharmed: slam (known and unknown association) and odometry driven by a clean, deterministic
  stream (the Burger on an arc at 20 Hz, observations of four landmarks every fifth sample, built by hand
  from geometry), once alone and once with drawn messages the input contract (hostile_messages.CONTRACT)
  refuses interleaved: every output answering a clean message is the same (to 1e-12), the last ones too.

Every spin goes through ``spin_once_guarded`` (as ``run_node`` spins the nodes); a `Probe` around every
callback of a node under test counts the messages it has processed, so that each publish waits until the
node has taken it (rather than for a time), and records what a callback raised. Publishers are reliable with
a deep queue; each message is sent alone, because the nodes' own subscriptions keep only 10 (scans 5).
"""

from __future__ import annotations

import array
import itertools
import math
import traceback
from collections import Counter
from collections.abc import Callable, Iterator, Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np
import pytest
from builtin_interfaces.msg import Time
from geometry_msgs.msg import PoseWithCovarianceStamped, Twist
from hostile_messages import (
    DRIVE,
    JOINT_STATE_FAMILIES,
    OBSERVATION_FAMILIES,
    POSE_FAMILIES,
    SCAN_CYLINDER_XY,
    T_BODY_SENSOR,
    WHEELS,
    S,
    Sent,
    consistent_bursts,
    cylinder_array,
    cylinder_scan_ranges,
    hostile_clocks,
    hostile_joint_states,
    hostile_marker_arrays,
    hostile_odometry,
    hostile_pose_stamped,
    hostile_scans,
    hostile_twists,
    joint_state,
    many_joints,
    many_markers,
    pose_stamped,
    refused_joint_states,
    refused_marker_arrays,
    refused_odometry,
    refused_pose_stamped,
    refused_scans,
    relative,
    scan_message,
    stamp,
    stamp_key,
    twist,
    wheel_command,
)
from hypothesis import HealthCheck, Phase, example, given, settings
from hypothesis import strategies as st
from nav_msgs.msg import Odometry, Path
from rclpy.node import Node
from rclpy.parameter import Parameter
from rclpy.publisher import Publisher
from rclpy.qos import QoSProfile, ReliabilityPolicy, qos_profile_sensor_data
from rosgraph_msgs.msg import Clock
from sensor_msgs.msg import JointState, LaserScan
from visualization_msgs.msg import Marker, MarkerArray

from nusim.nusim_node import NusimNode
from nuslam.landmarks_node import LandmarksNode
from nuslam.slam_node import SlamNode
from nuturtle_control.odometry import OdometryNode
from nuturtle_control.turtle_control import TurtleControlNode
from nuturtle_description.robot_params import burger_params
from rclpy_harness import RosHarness, matched
from turtlelib import Transform2D

pytestmark = pytest.mark.ros

RELIABLE = QoSProfile(depth=1000, reliability=ReliabilityPolicy.RELIABLE)
DT_NS = S // 20  # the Burger's joint_states at 20 Hz
T_REF_NS = 1_700_000_000 * S + 123_456_789  # the liveness tests' last clean sample (every ns digit used)
PHI_REF = (12.5, -3.25)
# the liveness tests' clean samples after the batch: a time base 12,345 s earlier (a restarted simulator),
# which a node must take after at most CONTRACT.restart_after samples whatever the batch left
RECOVERY_NS = T_REF_NS - 12_345 * S
RECOVERY_SAMPLES = 6
ROBOT = burger_params()
TOL = 1e-12


def fuzz(max_examples: int) -> settings:
    """Deterministic (derandomize: CI draws the same examples every run), no deadline, no shrinking (an
    example takes a node's life; the falsifying one is reported as drawn), no database."""
    return settings(
        max_examples=max_examples,
        deadline=None,
        derandomize=True,
        database=None,
        phases=(Phase.explicit, Phase.generate),
        report_multiple_bugs=False,
        print_blob=False,
        suppress_health_check=[
            HealthCheck.function_scoped_fixture,  # one rclpy context per test, fresh nodes per example
            HealthCheck.too_slow,
            HealthCheck.data_too_large,
            HealthCheck.large_base_example,
            HealthCheck.filter_too_much,
        ],
    )


@st.composite
def batches(draw, *items: st.SearchStrategy, max_size: int = 8) -> list[Sent]:
    """Lists of drawn items (a burst counts as one item and is sent as its samples)."""
    drawn = draw(st.lists(st.one_of(*items), min_size=1, max_size=max_size))
    return [sent for item in drawn for sent in (item if isinstance(item, list) else [item])]


# --- probing, publishing, recording -------------------------------------------------------------------------


@dataclass(frozen=True)
class Failure:
    node: str
    entity: str  # the topic of a subscription, or "timer"
    text: str  # the formatted exception

    def __str__(self) -> str:
        return f"{self.node} {self.entity}: {self.text}"


class Probe:
    """Wraps every subscription and timer callback of ``node``: counts the calls once they return (by topic,
    "timer" for timers) and records what they raise, re-raising it (spin_once_guarded logs and counts it, as
    in run_node). The executor reads ``callback`` when it runs one, so the wrappers see every message."""

    def __init__(self, node: Node) -> None:
        self.node = node
        self.calls: Counter[str] = Counter()
        self.failures: list[Failure] = []
        self.topics = {subscription.topic_name for subscription in node.subscriptions}
        for subscription in node.subscriptions:
            subscription.callback = self._counted(subscription.topic_name, subscription.callback)
        for timer in node.timers:
            timer.callback = self._counted("timer", timer.callback)

    def _counted(self, entity: str, callback: Callable) -> Callable:
        def counted(*args):
            try:
                return callback(*args)
            except Exception:
                self.failures.append(
                    Failure(self.node.get_fully_qualified_name(), entity, traceback.format_exc())
                )
                raise
            finally:
                self.calls[entity] += 1

        return counted


_rig_numbers = itertools.count()


class Rig:
    """Nodes under test in a namespace of their own (a fresh one per rig), each behind a `Probe`, and a
    helper node publishing their inputs and recording their outputs."""

    def __init__(self, ros: RosHarness, name: str) -> None:
        self.ros = ros
        self.namespace = f"/fuzz_{name}_{next(_rig_numbers)}"
        self.nodes: list[Node] = []
        self.probes: list[Probe] = []
        self.helper = ros.node("fuzz_helper", namespace=self.namespace)
        self.publishers: dict[str, Publisher] = {}
        self.outputs: dict[str, list] = {}
        self.lost: list[Sent] = []
        self._failures_before = ros.callback_failures
        self._stamps_unchecked: set[str] = set()

    def add(self, node_type: type[Node], cli_args: list[str] | None = None, **parameters) -> Node:
        overrides = [Parameter(name, value=value) for name, value in parameters.items()]
        node = node_type(
            context=self.ros.context,
            namespace=self.namespace,
            parameter_overrides=overrides,
            cli_args=cli_args,
        )
        self.ros.add(node)
        self.nodes.append(node)
        self.probes.append(Probe(node))
        return node

    def publish_to(self, topic: str, msg_type: type, qos: QoSProfile = RELIABLE) -> None:
        self.publishers[topic] = self.helper.create_publisher(msg_type, topic, qos)

    def record(
        self, topic: str, msg_type: type, qos: QoSProfile = RELIABLE, valid_stamps: bool = True
    ) -> list:
        """Record what the nodes publish on ``topic``; ``valid_stamps``: its stamps must be valid (not for
        outputs that carry an input's stamp the input contract does not check: scans, observations)."""
        received: list = []
        self.helper.create_subscription(msg_type, topic, received.append, qos)
        self.outputs[topic] = received
        if not valid_stamps:
            self._stamps_unchecked.add(topic)
        return received

    def wait_matched(self) -> None:
        """Every publisher and recorder of the helper matched, and every input of the nodes under test."""
        endpoints = [*self.publishers.values(), *self.helper.subscriptions]
        inputs = [s for node in self.nodes for s in node.subscriptions if s.topic_name != "/parameter_events"]
        assert self.ros.spin_guarded_until(lambda: matched(*endpoints, *inputs), 10.0), "DDS matching"

    def send(self, item: Sent, reliable: bool = True, timeout_s: float = 10.0) -> bool:
        """Publish ``item`` and spin until every node under test that subscribes to its topic has processed
        it. A reliable topic must deliver it (AssertionError otherwise); on a best-effort one (scan, /clock)
        it may be lost: False, and it is listed in ``lost``."""
        publisher = self.publishers[item.topic]
        topic = publisher.topic_name
        takers = [probe for probe in self.probes if topic in probe.topics]
        before = sum(probe.calls[topic] for probe in takers)
        publisher.publish(item.msg)
        done = self.ros.spin_guarded_until(
            lambda: sum(probe.calls[topic] for probe in takers) >= before + len(takers),
            timeout_s if reliable else min(timeout_s, 5.0),
        )
        assert done or not reliable, f"not processed within {timeout_s} s: {item!r}"
        if not done:
            self.lost.append(item)
        return done

    def answer(self, topic: str, header_stamp: Time, since: int = 0, timeout_s: float = 2.0) -> Any | None:
        """The first output on ``topic`` after index ``since`` stamped ``header_stamp`` (None if none
        comes)."""
        key = stamp_key(header_stamp)
        received = self.outputs[topic]

        def find():
            return next((m for m in received[since:] if stamp_key(output_stamp(m)) == key), None)

        self.ros.spin_guarded_until(lambda: find() is not None, timeout_s)
        return find()

    def failures(self) -> list[Failure]:
        return [failure for probe in self.probes for failure in probe.failures]

    def assert_no_failures(self, allowed: Callable[[Failure], bool] = lambda failure: False) -> None:
        """No callback of a node under test raised (but ``allowed`` ones), and nothing else did either."""
        failures = self.failures()
        unexpected = [failure for failure in failures if not allowed(failure)]
        assert not unexpected, "callbacks raised:\n" + "\n".join(map(str, unexpected[:3]))
        others = self.ros.callback_failures - self._failures_before - len(failures)
        assert others == 0, f"{others} exceptions outside the nodes under test"

    def assert_outputs_finite(self) -> None:
        """Every recorded output has finite floats and (but where ``record`` says) valid stamps."""
        for topic, received in self.outputs.items():
            for index, msg in enumerate(received):
                bad = defects(msg, stamps=topic not in self._stamps_unchecked)
                assert not bad, f"{topic} output {index} of {len(received)}: {bad[:5]}"

    def close(self) -> None:
        for node in [*self.nodes, self.helper]:
            self.ros.remove(node)


def output_stamp(msg: Any) -> Time:
    if isinstance(msg, MarkerArray):
        return msg.markers[0].header.stamp if msg.markers else Time(sec=-1)
    return msg.header.stamp


def defects(msg: Any, path: str = "", stamps: bool = True) -> list[str]:
    """Where a message has a non-finite float or (``stamps``) a stamp with nanosec >= 1e9: its fields'
    paths."""
    if isinstance(msg, float):
        return [] if math.isfinite(msg) else [f"{path} = {msg!r}"]
    if isinstance(msg, Time):
        return (
            [] if msg.nanosec < S or not stamps else [f"{path} = ({msg.sec}, {msg.nanosec}): invalid stamp"]
        )
    if isinstance(msg, (array.array, np.ndarray)):
        values = np.asarray(msg)
        if values.dtype.kind != "f":
            return []
        bad = np.flatnonzero(~np.isfinite(values))
        return [f"{path}[{bad[0]}] = {values.flat[bad[0]]!r} ({len(bad)} non-finite)"] if len(bad) else []
    if isinstance(msg, (list, tuple)):
        return [defect for k, item in enumerate(msg) for defect in defects(item, f"{path}[{k}]", stamps)]
    if hasattr(msg, "get_fields_and_field_types"):
        return [
            defect
            for name in msg.get_fields_and_field_types()
            for defect in defects(getattr(msg, name), f"{path}.{name}", stamps)
        ]
    return []


def close(a: float | np.ndarray, b: float | np.ndarray, tol: float = TOL) -> bool:
    a, b = np.asarray(a, dtype=float), np.asarray(b, dtype=float)
    return a.shape == b.shape and bool(np.all(np.abs(a - b) <= tol))


def pose_of(odom: Odometry) -> tuple[float, float, float, float]:
    p, q = odom.pose.pose.position, odom.pose.pose.orientation
    return p.x, p.y, q.z, q.w


# --- odometry -----------------------------------------------------------------------------------------------


def recovery_samples(angles: tuple[float, float] = (1.0, 2.0)) -> list[Sent]:
    """The robot standing at ``angles``, RECOVERY_SAMPLES samples on the recovery time base."""
    return [
        Sent("joint_states", "clean", joint_state(RECOVERY_NS + k * DT_NS, angles))
        for k in range(RECOVERY_SAMPLES)
    ]


LAST_RECOVERY_STAMP = stamp(RECOVERY_NS + (RECOVERY_SAMPLES - 1) * DT_NS)

# an explicit example (odometry, slam), run every time: finite but huge wheel angles on a stamp back in time,
# then back to 0 rad 50 ms later (an increment that overflows the kinematics without raising)
HUGE_ANGLES_BACK_IN_TIME = [
    Sent("joint_states", "huge angles, back in time", joint_state(T_REF_NS - S, (1e304, 1e304))),
    Sent("joint_states", "50 ms later, at 0 rad", joint_state(T_REF_NS - S + DT_NS, (0.0, 0.0))),
]


@fuzz(max_examples=40)
@example(batch=HUGE_ANGLES_BACK_IN_TIME)
@example(batch=[Sent("joint_states", "10,000 joints", many_joints(T_REF_NS + DT_NS, wheels=PHI_REF))])
@given(
    batch=batches(
        hostile_joint_states(T_REF_NS, PHI_REF),
        consistent_bursts(T_REF_NS, PHI_REF),
        hostile_pose_stamped("initialpose", ("odom", ""), T_REF_NS),
    )
)
def test_odometry_lives_through_hostile_joint_states_and_initial_poses(ros, batch):
    rig = Rig(ros, "odometry")
    try:
        rig.add(OdometryNode)
        rig.publish_to("joint_states", JointState)
        rig.publish_to("initialpose", PoseWithCovarianceStamped)
        odoms = rig.record("odom", Odometry)
        rig.record("odometry/path", Path)
        rig.wait_matched()
        rig.send(Sent("joint_states", "clean", joint_state(T_REF_NS, PHI_REF)))
        for item in batch:
            rig.send(item)
        # recovery: a clean initial pose, then the robot standing on a new time base
        start = Transform2D(0.3, -0.2, 0.5)
        rig.send(Sent("initialpose", "clean", pose_stamped(start, "odom", RECOVERY_NS)))
        since = len(odoms)
        for item in recovery_samples():
            rig.send(item)
        odom = rig.answer("odom", LAST_RECOVERY_STAMP, since)
        rig.assert_no_failures()
        rig.assert_outputs_finite()
        assert odom is not None, "no odom for the clean joint_states after the batch"
        expected = (start.x, start.y, math.sin(start.theta / 2), math.cos(start.theta / 2))
        assert close(pose_of(odom), expected), f"standing after initialpose {expected}: {pose_of(odom)}"
        assert (odom.twist.twist.linear.x, odom.twist.twist.angular.z) == (0.0, 0.0)
    finally:
        rig.close()


# --- turtle_control -----------------------------------------------------------------------------------------


@fuzz(max_examples=40)
@given(batch=batches(hostile_twists()))
def test_turtle_control_lives_through_hostile_twists(ros, batch):
    rig = Rig(ros, "turtle_control")
    try:
        rig.add(TurtleControlNode)
        rig.publish_to("cmd_vel", Twist)
        wheel_cmds = rig.record("wheel_cmd", JointState)
        rig.wait_matched()
        for item in batch:
            rig.send(item)
        since = len(wheel_cmds)
        rig.send(Sent("cmd_vel", "clean", twist(0.1, 0.5)))
        # phi_dot = ((vx -+ omega d / 2) / r): (1.818, 4.242) rad/s, under the 6.36 rad/s limit
        half_track = 0.5 * ROBOT.track_width
        expected = (
            (0.1 - 0.5 * half_track) / ROBOT.wheel_radius,
            (0.1 + 0.5 * half_track) / ROBOT.wheel_radius,
        )
        assert ros.spin_guarded_until(
            lambda: any(close(cmd.velocity, expected, 1e-9) for cmd in wheel_cmds[since:]), 2.0
        ), f"no wheel_cmd {expected} for a clean cmd_vel after the batch"
        rig.assert_no_failures()
        rig.assert_outputs_finite()
        for cmd in wheel_cmds:
            assert list(cmd.name) == list(WHEELS) and len(cmd.velocity) == 2
            assert max(abs(v) for v in cmd.velocity) <= ROBOT.max_wheel_speed * (1 + 1e-12), list(
                cmd.velocity
            )
    finally:
        rig.close()


# --- nusim --------------------------------------------------------------------------------------------------

NUSIM_WORLD = {
    "realtime_factor": 10.0,
    "cmd_timeout": 0.0,
    "obstacles.x": [1.0],
    "obstacles.y": [0.0],
    "obstacles.r": [0.05],
    "input_noise": 0.0,
    "slip_fraction": 0.0,
    "basic_sensor_variance": 0.0,
}


@fuzz(max_examples=20)
@example(batch=[Sent("wheel_cmd", "10,000 joints", many_joints(0, "velocity", (1.0, 1.0)))])
@given(
    batch=batches(
        hostile_joint_states(T_REF_NS, field="velocity", topic="wheel_cmd"),
        hostile_pose_stamped("nusim/teleport", ("nusim/world", ""), T_REF_NS),
    )
)
def test_nusim_lives_through_hostile_wheel_commands_and_teleports(ros, batch):
    rig = Rig(ros, "nusim")
    try:
        rig.add(NusimNode, **NUSIM_WORLD)
        rig.publish_to("wheel_cmd", JointState)
        rig.publish_to("nusim/teleport", PoseWithCovarianceStamped)
        joint_states = rig.record("joint_states", JointState)
        truth = rig.record("nusim/ground_truth", Odometry)
        rig.record("scan", LaserScan, qos_profile_sensor_data)
        rig.record("fake_sensor", MarkerArray)
        rig.record("nusim/path", Path)
        rig.wait_matched()
        for item in batch:
            rig.send(item)
        # recovery: stop, teleport to a free pose, then drive
        rig.send(Sent("wheel_cmd", "clean", wheel_command(0.0, 0.0)))
        target = Transform2D(-0.5, 0.4, 1.0)
        since = len(truth)
        rig.send(Sent("nusim/teleport", "clean", pose_stamped(target, "nusim/world")))
        expected = (target.x, target.y, math.sin(target.theta / 2), math.cos(target.theta / 2))
        assert ros.spin_guarded_until(
            lambda: any(close(pose_of(odom), expected, 1e-9) for odom in truth[since:]), 5.0
        ), "the robot is not at a clean teleport's pose"
        since = len(joint_states)
        rig.send(Sent("wheel_cmd", "clean", wheel_command(2.0, 2.5)))
        # the motors take round(w * 41.67) mcu
        taken = [round(w * ROBOT.motor_cmd_per_rad_sec) / ROBOT.motor_cmd_per_rad_sec for w in (2.0, 2.5)]
        assert ros.spin_guarded_until(
            lambda: any(close(js.velocity, taken, 1e-9) for js in joint_states[since:]), 5.0
        ), f"the wheels do not turn at {taken} rad/s after a clean wheel_cmd"
        rig.assert_no_failures()
        rig.assert_outputs_finite()
    finally:
        rig.close()


@pytest.fixture
def nusim_rig(ros) -> Iterator[Rig]:
    rig = Rig(ros, "nusim_refusing")
    rig.add(NusimNode, **NUSIM_WORLD)
    rig.publish_to("wheel_cmd", JointState)
    rig.publish_to("nusim/teleport", PoseWithCovarianceStamped)
    rig.record("nusim/ground_truth", Odometry)
    rig.wait_matched()
    yield rig
    rig.close()


@fuzz(max_examples=20)
@given(refused=refused_pose_stamped("nusim/teleport", "nusim/world"))
def test_nusim_does_not_move_the_robot_for_a_teleport_the_contract_refuses(ros, nusim_rig, refused):
    """The robot stands at the start pose (no wheel command, no noise) through every refused teleport."""
    truth = nusim_rig.outputs["nusim/ground_truth"]
    nusim_rig.send(refused)
    since = len(truth)
    assert ros.spin_guarded_until(lambda: len(truth) > since + 1, 5.0), "no ground truth"
    assert close(pose_of(truth[-1]), (0.0, 0.0, 0.0, 1.0)), f"moved to {pose_of(truth[-1])} by {refused!r}"
    nusim_rig.assert_no_failures()
    nusim_rig.assert_outputs_finite()


# --- landmarks ----------------------------------------------------------------------------------------------


@fuzz(max_examples=20)
@example(
    batch=[Sent("scan", "100,000 ranges", scan_message(T_REF_NS, np.resize(cylinder_scan_ranges(), 100_000)))]
)
@given(batch=batches(hostile_scans(T_REF_NS)))
def test_landmarks_lives_through_hostile_scans(ros, batch):
    rig = Rig(ros, "landmarks")
    try:
        rig.add(LandmarksNode)
        rig.publish_to("scan", LaserScan)
        # stamped with the scan's stamp, which the contract does not check
        landmarks = rig.record("landmarks", MarkerArray, valid_stamps=False)
        # subscribed: the node also builds the cluster markers
        rig.record("landmarks/clusters", MarkerArray, valid_stamps=False)
        rig.wait_matched()
        for item in batch:
            rig.send(item, reliable=False)
        since = len(landmarks)
        clean = Sent("scan", "clean", scan_message(RECOVERY_NS, cylinder_scan_ranges()))
        array = None
        for _ in range(3):  # best effort: a lost scan is sent again
            rig.send(clean, reliable=False)
            array = rig.answer("landmarks", clean.msg.header.stamp, since, timeout_s=1.0)
            if array is not None:
                break
        rig.assert_no_failures()
        rig.assert_outputs_finite()
        assert array is not None, "no landmarks for a clean scan after the batch"
        found = [(m.pose.position.x, m.pose.position.y) for m in array.markers if m.action == Marker.ADD]
        assert any(math.dist(xy, SCAN_CYLINDER_XY) < 0.015 for xy in found), found
        assert len(rig.lost) <= len(batch) // 2, f"{len(rig.lost)} of {len(batch)} scans lost"
    finally:
        rig.close()


@pytest.fixture
def landmarks_rig(ros) -> Iterator[Rig]:
    rig = Rig(ros, "landmarks_refusing")
    rig.add(LandmarksNode)
    rig.publish_to("scan", LaserScan)
    rig.record("landmarks", MarkerArray, valid_stamps=False)
    rig.wait_matched()
    yield rig
    rig.close()


_scan_numbers = itertools.count()


@fuzz(max_examples=30)
@given(refused=refused_scans(0))
def test_landmarks_publishes_nothing_for_a_scan_of_an_inconsistent_layout(ros, landmarks_rig, refused):
    rig = landmarks_rig
    n = next(_scan_numbers)
    refused.msg.header.stamp = stamp(T_REF_NS + n * S)
    clean = Sent("scan", "clean", scan_message(T_REF_NS + n * S + S // 2, cylinder_scan_ranges()))
    since = len(rig.outputs["landmarks"])
    for item in (refused, clean):
        assert any(rig.send(item, reliable=False) for _ in range(3)), f"lost three times: {item!r}"
    answer = rig.answer("landmarks", clean.msg.header.stamp, since)
    rig.assert_no_failures()
    rig.assert_outputs_finite()
    assert answer is not None, "no landmarks for a clean scan"
    stamps = [stamp_key(output_stamp(array)) for array in rig.outputs["landmarks"][since:]]
    assert stamp_key(refused.msg.header.stamp) not in stamps, f"landmarks published for {refused!r}"


# --- slam ---------------------------------------------------------------------------------------------------

# true landmarks in map (slam starts at the origin): id -> (x, y)
LANDMARKS = {3: (1.2, 0.4), 7: (0.5, -1.0), 12: (-0.6, 0.8), 20: (1.6, -0.3)}


def observation_topic(association: str) -> tuple[str, str]:
    """(topic, frame) of slam's observations: nusim's fake sensor in the body frame, or the landmarks node's
    cylinders in the LiDAR frame."""
    return ("fake_sensor", "base_footprint") if association == "known" else ("landmarks", "base_scan")


def slam_rig(ros: RosHarness, association: str, name: str, with_odometry: bool = False) -> Rig:
    """slam (and odometry, its odom renamed wheel_odom so that slam's odom input is the test's alone)."""
    rig = Rig(ros, name)
    rig.add(SlamNode, association=association, observation_timeout=100.0)
    if with_odometry:
        rig.add(OdometryNode, cli_args=["--ros-args", "-r", "odom:=wheel_odom"])
        rig.record("wheel_odom", Odometry)
    topic, _ = observation_topic(association)
    rig.publish_to("joint_states", JointState)
    rig.publish_to("odom", Odometry)
    rig.publish_to(topic, MarkerArray)
    rig.publish_to("initialpose", PoseWithCovarianceStamped)  # slam's (and odometry's) relocalization
    rig.publish_to("scan", LaserScan)  # slam's occupancy grid
    rig.record("slam/odom", Odometry)
    rig.record("slam/map", MarkerArray, valid_stamps=False)  # stamped with an observation's stamp
    rig.record("slam/path", Path)
    rig.wait_matched()
    return rig


SLAM_BATCHES = batches(
    hostile_joint_states(T_REF_NS, PHI_REF),
    consistent_bursts(T_REF_NS, PHI_REF),
    hostile_odometry(T_REF_NS),
    hostile_pose_stamped("initialpose", ("map", ""), T_REF_NS),
    # "observations": the association's topic (landmarks or fake_sensor)
    hostile_marker_arrays(("base_scan", "base_footprint"), T_REF_NS, "observations"),
    hostile_marker_arrays(("base_scan", "base_footprint"), T_REF_NS, "observations"),
    hostile_scans(T_REF_NS),
)
# explicit examples, run every time: 10,000 joints and 10,000 markers
HUGE_ARRAYS = [
    Sent("joint_states", "10,000 joints", many_joints(T_REF_NS + DT_NS, wheels=PHI_REF)),
    Sent("observations", "10,000 markers", many_markers(10_000, "out of range", "base_footprint", (1, 0))),
]


@pytest.mark.parametrize("association", ["unknown", "known"])
@fuzz(max_examples=25)
@example(batch=HUGE_ANGLES_BACK_IN_TIME)
@example(batch=HUGE_ARRAYS)
@given(batch=SLAM_BATCHES)
def test_slam_lives_through_hostile_joint_states_odom_and_observations(ros, association, batch):
    topic, frame = observation_topic(association)
    rig = slam_rig(ros, association, f"slam_{association}")
    rig.publishers["observations"] = rig.publishers[topic]
    try:
        # a start: standing at PHI_REF, the landmarks seen from the origin
        rig.send(Sent("joint_states", "clean", joint_state(T_REF_NS - DT_NS, PHI_REF)))
        rig.send(Sent("joint_states", "clean", joint_state(T_REF_NS, PHI_REF)))
        T_frame = T_BODY_SENSOR if frame == "base_scan" else Transform2D()
        rig.send(Sent(topic, "clean", cylinder_array(frame, T_REF_NS, relative(T_frame, LANDMARKS))))
        for item in batch:
            rig.send(item)
        # recovery: standing on a new time base, then new landmarks (ids 500, 501) seen at its last sample
        since = {name: len(rig.outputs[name]) for name in ("slam/odom", "slam/map")}
        for item in recovery_samples():
            rig.send(item)
        odom = rig.answer("slam/odom", LAST_RECOVERY_STAMP, since["slam/odom"])
        new = [(500, 1.0, 0.3), (501, 0.8, -0.6)]
        rig.send(Sent(topic, "clean", cylinder_array(frame, RECOVERY_NS + 5 * DT_NS, new)))
        slam_map = rig.answer("slam/map", LAST_RECOVERY_STAMP, since["slam/map"])
        rig.assert_no_failures()
        rig.assert_outputs_finite()
        assert odom is not None, "no slam/odom for the clean joint_states after the batch"
        assert slam_map is not None, "no slam/map for a clean observation after the batch"
        ids = {m.id for m in slam_map.markers if m.ns == "landmarks" and m.action == Marker.ADD}
        if association == "known" and len(ids - {500, 501}) < 20:  # (a full map may refuse new landmarks)
            assert {500, 501} <= ids, f"the new landmarks are not mapped: {sorted(ids)}"
    finally:
        rig.close()


# --- /clock -------------------------------------------------------------------------------------------------

CLOCK_REF_NS = 100 * S
CLOCK_AFTER_NS = 200 * S + 5


def node_time_ns(node: Node) -> int:
    return node.get_clock().now().nanoseconds


@fuzz(max_examples=20)
@given(batch=batches(hostile_clocks(CLOCK_REF_NS)))
def test_nodes_on_sim_time_keep_working_after_hostile_clocks(ros, batch):
    rig = Rig(ros, "clock")
    try:
        nodes = [
            rig.add(node_type, use_sim_time=True)
            for node_type in (OdometryNode, TurtleControlNode, LandmarksNode, SlamNode)
        ]
        for topic, msg_type in (
            ("/clock", Clock),
            ("joint_states", JointState),
            ("cmd_vel", Twist),
            ("scan", LaserScan),
            ("initialpose", PoseWithCovarianceStamped),
        ):
            rig.publish_to(topic, msg_type)  # slam's odom and landmarks come from the other two nodes
        rig.record("odom", Odometry)
        rig.record("slam/odom", Odometry)
        rig.record("wheel_cmd", JointState)
        rig.record("landmarks", MarkerArray, valid_stamps=False)
        rig.wait_matched()

        def clock_reaches(t_ns: int) -> None:
            # /clock is best effort (depth 1 in rclpy's time source): sent until every node's clock shows it
            msg = Sent("/clock", "clean", Clock(clock=stamp(t_ns)))
            for _ in range(20):
                rig.send(msg, reliable=False, timeout_s=0.2)
                if all(node_time_ns(node) == t_ns for node in nodes):
                    return
            raise AssertionError(f"clocks at {[node_time_ns(n) for n in nodes]} ns, not {t_ns} ns")

        clock_reaches(CLOCK_REF_NS)
        for item in batch:
            rig.send(item, reliable=False)
        clock_reaches(CLOCK_AFTER_NS)
        # every node works on the valid clock
        since = {name: len(received) for name, received in rig.outputs.items()}
        t_ns = CLOCK_AFTER_NS
        rig.send(Sent("joint_states", "clean", joint_state(t_ns, (0.0, 0.0))))
        rig.send(Sent("joint_states", "clean", joint_state(t_ns + DT_NS, (0.1, 0.1))))
        rig.send(Sent("cmd_vel", "clean", twist(0.1, 0.0)))
        scan = Sent("scan", "clean", scan_message(t_ns, cylinder_scan_ranges()))
        for _ in range(3):
            if rig.send(scan, reliable=False):
                break
        assert rig.answer("odom", stamp(t_ns + DT_NS), since["odom"]) is not None, "odometry: no odom"
        assert rig.answer("slam/odom", stamp(t_ns + DT_NS), since["slam/odom"]) is not None, "slam: no odom"
        assert rig.answer("landmarks", stamp(t_ns), since["landmarks"]) is not None, "landmarks: nothing"
        # turtle_control stamps its command with its clock: the valid one
        cmd = rig.answer("wheel_cmd", stamp(CLOCK_AFTER_NS), since["wheel_cmd"])
        assert cmd is not None, f"turtle_control: no wheel_cmd stamped {stamp(CLOCK_AFTER_NS)}"
        assert close(cmd.velocity, (0.1 / ROBOT.wheel_radius,) * 2, 1e-9)
        # rclpy's time source raises on a negative sec inside its own callback: the only exceptions allowed
        rig.assert_no_failures(allowed=lambda failure: failure.entity == "/clock")
        rig.assert_outputs_finite()
    finally:
        rig.close()


# --- the estimate, unharmed by refused messages -------------------------------------------------------------

T0_NS = 1_700_000_000 * S + 987_654_321
STEPS = 80  # 4 s at 20 Hz
OBSERVE_EVERY = 5
PHI0 = (10.0, 20.0)
VX, OMEGA = 0.15, 0.3  # m/s, rad/s: wheel increments of 0.19 and 0.26 rad per sample, under the 0.48 allowed


def wheel_speeds(vx: float, omega: float) -> tuple[float, float]:
    half_track = 0.5 * ROBOT.track_width
    return (vx - omega * half_track) / ROBOT.wheel_radius, (vx + omega * half_track) / ROBOT.wheel_radius


SPEEDS = wheel_speeds(VX, OMEGA)


def clean_sample(k: int) -> tuple[int, tuple[float, float]]:
    """The stamp and wheel angles of clean sample k."""
    t_s = k * DT_NS / S
    return T0_NS + k * DT_NS, (PHI0[0] + SPEEDS[0] * t_s, PHI0[1] + SPEEDS[1] * t_s)


def true_pose(k: int) -> Transform2D:
    """The robot at sample k: the exact arc of constant wheel speeds from the origin."""
    t_s = k * DT_NS / S
    return DRIVE.step(Transform2D(), SPEEDS[0] * t_s, SPEEDS[1] * t_s)


def odom_values(odom: Odometry | None) -> np.ndarray | None:
    if odom is None:
        return None
    p, q = odom.pose.pose.position, odom.pose.pose.orientation
    t = odom.twist.twist
    return np.array(
        [p.x, p.y, p.z, q.x, q.y, q.z, q.w, *odom.pose.covariance, t.linear.x, t.linear.y, t.angular.z]
    )


def map_values(array: MarkerArray | None) -> dict | None:
    if array is None:
        return None
    return {
        (m.ns, m.id): np.array(
            [
                m.pose.position.x,
                m.pose.position.y,
                m.pose.orientation.z,
                m.pose.orientation.w,
                m.scale.x,
                m.scale.y,
            ]
        )
        for m in array.markers
        if m.action == Marker.ADD
    }


class Answer:
    """What the nodes published for one clean message: slam/odom and odometry's odom for sample k, or
    slam/map for the observation at sample k (``values``: the numbers compared, None if nothing came)."""

    def __init__(self, what: str, k: int, values: Any) -> None:
        self.what, self.k, self.values = what, k, values

    def __repr__(self) -> str:
        return f"Answer({self.what} for clean sample {self.k})"

    def same(self, other: Answer) -> tuple[bool, str]:
        if other.values is None or self.values is None:
            if other.values is None and self.values is None:
                return True, ""
            return (
                False,
                "no answer (the clean run had one)"
                if other.values is None
                else "an answer (not in the clean run)",
            )
        if isinstance(self.values, dict):
            if self.values.keys() != other.values.keys():
                return False, f"markers {sorted(other.values)} instead of {sorted(self.values)}"
            worst = max(
                (float(np.max(np.abs(self.values[k] - other.values[k]))) for k in self.values), default=0.0
            )
        else:
            worst = (
                float(np.max(np.abs(self.values - other.values)))
                if self.values.shape == other.values.shape
                else math.inf
            )
        return bool(worst <= TOL), f"largest difference {worst!r}"


# the refused messages of each input, drawn after clean sample k: (t_ns, phi) of k, t_next_ns of k + 1, the
# observing frame and its pose T_frame
def refused_joint_states_after(c: dict) -> st.SearchStrategy[Sent]:
    return refused_joint_states(
        c["t_ns"], c["phi"], c["t_next_ns"], families=c["families"] or JOINT_STATE_FAMILIES
    )


def refused_observations_after(c: dict) -> st.SearchStrategy[Sent]:
    known = c["association"] == "known"
    families = c["families"] or OBSERVATION_FAMILIES
    return refused_marker_arrays(
        c["t_ns"], c["T_frame"], c["frame"], LANDMARKS, True, known, c["topic"], families=families
    )


def refused_poses_after(c: dict) -> st.SearchStrategy[Sent]:
    families = c["families"] or POSE_FAMILIES
    return st.one_of(
        refused_odometry(c["t_ns"], families=families),
        refused_pose_stamped("initialpose", "odom", c["t_ns"], families=families),
    )


REFUSED_INPUTS = {
    "joint_states": refused_joint_states_after,  # into slam and odometry
    "observations": refused_observations_after,  # into slam (landmarks or fake_sensor)
    "poses": refused_poses_after,  # odom into slam, initialpose into odometry
}


def drive(
    rig: Rig, association: str, data: Any = None, refused_input: str = "", families: Sequence[str] = ()
) -> Iterator[tuple[Answer, list[Sent]]]:
    """Send the clean stream into ``rig``, yielding what answers each clean message with the refused
    messages sent since the previous clean sample; with ``data``, after each clean sample (and its
    observation) up to 3 refused messages of ``refused_input`` (REFUSED_INPUTS; of ``families``, default
    all), drawn; at most 2 joint_states in a row (3 consistent ones may restart the node)."""
    topic, frame = observation_topic(association)
    hostile: list[Sent] = []
    for k in range(STEPS):
        t_ns, phi = clean_sample(k)
        since = {name: len(received) for name, received in rig.outputs.items()}
        rig.send(Sent("joint_states", "clean", joint_state(t_ns, phi)))
        for name in ("slam/odom", "wheel_odom"):
            answer = rig.answer(name, stamp(t_ns), since[name], timeout_s=1.0)
            yield Answer(name, k, odom_values(answer)), hostile
        T_frame = true_pose(k) @ (T_BODY_SENSOR if frame == "base_scan" else Transform2D())
        if k % OBSERVE_EVERY == 0:
            since = len(rig.outputs["slam/map"])
            rig.send(Sent(topic, "clean", cylinder_array(frame, t_ns, relative(T_frame, LANDMARKS))))
            answer = rig.answer("slam/map", stamp(t_ns), since, timeout_s=1.0)
            yield Answer("slam/map", k, map_values(answer)), hostile
        hostile = []
        if data is None or k == STEPS - 1:
            continue
        context = {
            "t_ns": t_ns,
            "phi": phi,
            "t_next_ns": clean_sample(k + 1)[0],
            "T_frame": T_frame,
            "frame": frame,
            "topic": topic,
            "association": association,
            "families": tuple(families),
        }
        drawn = data.draw(
            st.lists(REFUSED_INPUTS[refused_input](context), max_size=3),
            label=f"refused after clean sample {k}",
        )
        for item in drawn[:2] if refused_input == "joint_states" else drawn:
            rig.send(item)
            hostile.append(item)


class CleanRun:
    """The answers of slam and odometry to the clean stream alone (a short repr: hypothesis prints it)."""

    def __init__(self, answers: list[Answer]) -> None:
        self.answers = answers

    def __repr__(self) -> str:
        return f"CleanRun({len(self.answers)} answers)"


_clean_runs: dict[str, CleanRun] = {}


@pytest.fixture
def clean_run(ros, association) -> CleanRun:
    """The clean stream's answers, computed once per association (deterministic: any run gives them)."""
    if association not in _clean_runs:
        rig = slam_rig(ros, association, f"reference_{association}", with_odometry=True)
        try:
            answers = [answer for answer, _ in drive(rig, association)]
            rig.assert_no_failures()
            rig.assert_outputs_finite()
        finally:
            rig.close()
        assert all(a.values is not None for a in answers), "the clean stream is answered"
        last_map = [a for a in answers if a.what == "slam/map"][-1].values
        assert len(last_map) == 2 * len(LANDMARKS), "every landmark mapped (and its ellipse)"
        _clean_runs[association] = CleanRun(answers)
    return _clean_runs[association]


def assert_unharmed(rig: Rig, clean_run: CleanRun, answers: Iterator[tuple[Answer, list[Sent]]]) -> None:
    """Every answer equals the clean run's (to 1e-12), else an AssertionError names the first that differs
    and the refused messages sent before it."""
    sent_so_far: list[Sent] = []
    previous: list[Sent] | None = None
    for index, (answer, hostile) in enumerate(answers):
        if hostile is not previous:  # the answers of one clean sample share its list
            sent_so_far += hostile
            previous = hostile
        reference = clean_run.answers[index]
        assert (answer.what, answer.k) == (reference.what, reference.k)
        same, difference = reference.same(answer)
        if not same:
            families = Counter(item.family for item in sent_so_far)
            raise AssertionError(
                f"{answer.what} for clean sample {answer.k} differs from the clean run's: {difference}; "
                f"refused messages sent since the previous clean sample: {hostile or 'none'}; "
                f"all so far: {dict(families)}"
            )
    rig.assert_no_failures()
    rig.assert_outputs_finite()


# the association mode changes only the observations' path: refused joint_states and poses are tested once
@pytest.mark.parametrize(
    ("association", "refused_input"),
    [
        ("unknown", "joint_states"),
        ("unknown", "poses"),
        ("unknown", "observations"),
        ("known", "observations"),
    ],
)
@fuzz(max_examples=6)
@given(data=st.data())
def test_refused_messages_leave_the_slam_and_odometry_estimates_unharmed(
    ros, association, refused_input, clean_run, data
):
    rig = slam_rig(ros, association, f"harm_{association}", with_odometry=True)
    try:
        assert_unharmed(rig, clean_run, drive(rig, association, data, refused_input))
    finally:
        rig.close()
