"""`bag_player`: plays recorded messages into DDS as raw CDR, with /clock, as ``ros2 bag play --clock`` does,
and the executor steps that give in-process nodes back-pressure.

The node
--------
:class:`BagPlayer` has one publisher per :class:`PlayedTopic` (a bag topic, e.g. ``/my_scan``, played under
another name, e.g. ``scan``, with the recorded message type; one bag topic may be played under several
names, e.g. a Gazebo ``/odom`` as both ``odom`` and the ground truth) and one on ``/clock``
(rosgraph_msgs/Clock). :meth:`BagPlayer.publish_message` publishes a message's CDR bytes untouched on each
of its names (rclpy's ``Publisher.publish(bytes)`` publishes serialised data as it is).

QoS (:func:`played_qos`): reliable, volatile, keep last ``PLAY_DEPTH``; a sensor topic (the scan) mirrors
the reliability and durability its recorded publishers offered (``offered_qos_profiles``: the LiDAR's best
effort, so a subscriber that asks for best effort, as the landmarks node does with sensor-data QoS, or
reliable from a reliable recording, both match), and is best effort when the recording does not say.

Back-pressure
-------------
All nodes of a replay run in one process on one SingleThreadedExecutor, and a publication to a subscription
of the same context is delivered during ``publish`` (Fast DDS's intra-process delivery; the replay tests
count every scan through to slam), so running the executor until no callback is ready
(:func:`run_until_idle`) after each log-time step of publications (replay_run.py) lets every node, and every
node that hears their outputs in turn (scan -> landmarks -> slam), finish with them before the next step
goes out: nothing is dropped whatever the speed, and nothing sleeps. :func:`wait_until` waits
on the executor (running callbacks meanwhile) for a wall-clock deadline: the pace of ``--rate``.
"""

from __future__ import annotations

import time
from collections.abc import Iterable, Sequence
from dataclasses import dataclass
from typing import Any

from rclpy.executors import (
    ConditionReachedException,
    Executor,
    ShutdownException,
    TimeoutException,
)
from rclpy.node import Node
from rclpy.qos import DurabilityPolicy, HistoryPolicy, QoSProfile, ReliabilityPolicy
from rclpy.serialization import serialize_message
from rosgraph_msgs.msg import Clock

from nuturtle_ros_common.conversions import stamp_from_nanoseconds
from nuturtle_ros_common.node_main import run_guarded

from .bag_source import BagMessage, BagTopic
from .recorder import TopicSink, absolute, message_class

CLOCK_TOPIC = "/clock"
# Queue of each played publisher (room for a burst to an external, slower subscriber)
PLAY_DEPTH = 100


def played_qos(topic: BagTopic, sensor: bool) -> QoSProfile:
    """The QoS a topic is played with (module docstring): reliable, volatile, keep last ``PLAY_DEPTH``; for a
    ``sensor`` topic the recorded publishers' reliability and durability (best effort / volatile unless
    every recorded publisher offered reliable / transient local), best effort when none was recorded."""
    reliability, durability = ReliabilityPolicy.RELIABLE, DurabilityPolicy.VOLATILE
    if sensor:
        offered = list(topic.offered_qos)
        reliable = bool(offered) and all(q.reliability.name == "RELIABLE" for q in offered)
        latched = bool(offered) and all(q.durability.name == "TRANSIENT_LOCAL" for q in offered)
        reliability = ReliabilityPolicy.RELIABLE if reliable else ReliabilityPolicy.BEST_EFFORT
        durability = DurabilityPolicy.TRANSIENT_LOCAL if latched else DurabilityPolicy.VOLATILE
    return QoSProfile(
        history=HistoryPolicy.KEEP_LAST, depth=PLAY_DEPTH, reliability=reliability, durability=durability
    )


@dataclass(frozen=True)
class PlayedTopic:
    """The bag topic ``bag_topic`` (``/my_scan``) of ``type_name`` played as ``name`` (``scan``) with
    ``qos``."""

    bag_topic: str
    name: str
    type_name: str
    qos: QoSProfile


class BagPlayer(Node):
    """The `bag_player` node (module docstring) for ``topics``; kwargs go to rclpy's Node.

    ``publish_clock(t_ns)`` publishes /clock (when the log time moved on), ``publish_message(message)`` the
    message on each name its bag topic is played as (KeyError for a topic not in ``topics``); ``topics``
    the played topics by bag topic, ``played`` the messages published per bag topic. ``relay_to(sink)``
    also hands /clock and every played message, with its log time, to a
    :class:`~nuturtle_tools.recorder.TopicSink` (the Foxglove relay) without a subscription.
    ValueError for two played topics of one name.
    """

    def __init__(self, topics: Sequence[PlayedTopic], **kwargs: Any) -> None:
        super().__init__("bag_player", **kwargs)
        names = [absolute(topic.name) for topic in topics]
        if len(set(names)) < len(names):
            raise ValueError(f"several bag topics played under one name: {sorted(names)}")
        self.topics: dict[str, list[PlayedTopic]] = {}
        self.publishers_by_topic: dict[str, list[Any]] = {}
        for topic in topics:
            publisher = self.create_publisher(message_class(topic.type_name), topic.name, topic.qos)
            self.topics.setdefault(topic.bag_topic, []).append(topic)
            self.publishers_by_topic.setdefault(topic.bag_topic, []).append(publisher)
        self.clock_publisher = self.create_publisher(Clock, CLOCK_TOPIC, QoSProfile(depth=PLAY_DEPTH))
        self.played = dict.fromkeys(self.topics, 0)
        self.clock_ns: int | None = None
        self._sink: TopicSink | None = None

    def relay_to(self, sink: TopicSink) -> None:
        """Hand /clock and the played messages to ``sink`` too, each on its played topic."""
        sink.add_topic(CLOCK_TOPIC, "rosgraph_msgs/msg/Clock", [self.clock_publisher.qos_profile])
        for played in self.topics.values():
            for topic in played:
                sink.add_topic(absolute(topic.name), topic.type_name, [topic.qos])
        self._sink = sink

    def publish_clock(self, t_ns: int) -> bool:
        """/clock at ``t_ns`` unless the clock is there already; True when published."""
        if self.clock_ns is not None and t_ns <= self.clock_ns:
            return False
        clock = Clock(clock=stamp_from_nanoseconds(int(t_ns)))
        self.clock_publisher.publish(clock)
        self.clock_ns = int(t_ns)
        if self._sink is not None:
            self._sink.write(CLOCK_TOPIC, serialize_message(clock), self.clock_ns)
        return True

    def publish_message(self, message: BagMessage) -> None:
        """The message's CDR bytes on each name its bag topic is played as."""
        for topic, publisher in zip(
            self.topics[message.topic], self.publishers_by_topic[message.topic], strict=True
        ):
            publisher.publish(message.data)
            if self._sink is not None:
                self._sink.write(absolute(topic.name), message.data, message.log_time_ns)
        self.played[message.topic] += 1

    def reliable_publishers(self, bag_topic: str | None = None) -> list[Any]:
        """The reliable publishers of ``bag_topic`` (of every played topic and /clock if None)."""
        names = list(self.topics) if bag_topic is None else [bag_topic]
        reliable = [
            publisher
            for name in names
            for topic, publisher in zip(self.topics[name], self.publishers_by_topic[name], strict=True)
            if topic.qos.reliability == ReliabilityPolicy.RELIABLE
        ]
        return reliable + ([self.clock_publisher] if bag_topic is None else [])

    def subscription_counts(self) -> dict[str, int]:
        """Matched subscriptions per played topic (by its played name) and /clock."""
        counts = {
            topic.name: publisher.get_subscription_count()
            for name, publishers in self.publishers_by_topic.items()
            for topic, publisher in zip(self.topics[name], publishers, strict=True)
        }
        counts[CLOCK_TOPIC] = self.clock_publisher.get_subscription_count()
        return counts


def _run_ready(executor: Executor, logger: Any, timeout_sec: float) -> bool | None:
    """Run one ready callback (waiting up to ``timeout_sec``), as ``Executor.spin_once`` does, guarded like
    ``nuturtle_ros_common.node_main.spin_once_guarded``: a callback's exception is logged (throttled) and
    the spinning goes on. True when a callback ran, False when the wait ended without one, None when
    the executor's wait finished its batch (rclpy raises its TimeoutException after the last ready
    callback of a zero-timeout wait)."""
    try:
        handler, _entity, _node = executor.wait_for_ready_callbacks(timeout_sec=timeout_sec)
    except TimeoutException:
        return None
    except (ShutdownException, ConditionReachedException):
        return False

    def run() -> None:
        handler()
        handler.result()  # raises what the callback raised

    run_guarded(run, logger)
    return True


def run_until_idle(executor: Executor, logger: Any) -> int:
    """Run callbacks until a fresh wait finds none ready (never waits); returns how many ran.

    rclpy's zero-timeout wait yields the callbacks ready at that moment and then raises TimeoutException,
    so "nothing is ready" is a TimeoutException with no callback run since the previous one.
    """
    ran = 0
    ran_since_wait = False
    while True:
        outcome = _run_ready(executor, logger, 0.0)
        if outcome:
            ran += 1
            ran_since_wait = True
        elif outcome is None and ran_since_wait:
            ran_since_wait = False  # that batch is done: look again
        else:
            return ran


def wait_until(executor: Executor, logger: Any, deadline_s: float) -> None:
    """Run callbacks as they become ready until the monotonic clock reaches ``deadline_s`` (no sleep: the
    executor's wait blocks)."""
    while (remaining := deadline_s - time.monotonic()) > 0.0:
        _run_ready(executor, logger, remaining)


def spin_until(executor: Executor, logger: Any, predicate: Any, timeout_s: float) -> bool:
    """Run callbacks until ``predicate()`` holds or ``timeout_s`` (wall) passed; its last value."""
    deadline = time.monotonic() + timeout_s
    while time.monotonic() < deadline:
        if predicate():
            return True
        _run_ready(executor, logger, 0.02)
    return predicate()


class Pacer:
    """Wall-clock pace of ``rate`` x real time for log times (ns): ``deadline_s(t_ns)`` the monotonic time
    at which a message of log time ``t_ns`` is due, counted from the first message (``rate`` > 0)."""

    def __init__(self, rate: float) -> None:
        if not rate > 0.0:
            raise ValueError(f"rate must be > 0, got {rate!r}")
        self.rate = float(rate)
        self._origin: tuple[int, float] | None = None

    def deadline_s(self, t_ns: int) -> float:
        if self._origin is None:
            self._origin = (int(t_ns), time.monotonic())
        t0_ns, wall0_s = self._origin
        return wall0_s + (t_ns - t0_ns) * 1e-9 / self.rate


def wait_for_acks(publishers: Iterable[Any], timeout_s: float) -> bool:
    """``wait_for_all_acked`` on each reliable publisher: the only back-pressure a player has from
    subscribers in other processes (True when all acknowledged within ``timeout_s`` each)."""
    from rclpy.duration import Duration

    return all(publisher.wait_for_all_acked(Duration(seconds=timeout_s)) for publisher in publishers)
