"""Record every ROS topic into one rosbag2 bag directory, as ``ros2 bag record -a -s mcap`` does, written by
the ``rosbags`` library.

Output: a bag directory ``DIR/``
--------------------------------
* ``DIR/metadata.yaml``: rosbag2 metadata version 9, ``storage_identifier: mcap``; per topic its type, its
  ``serialization_format: cdr``, the QoS profiles its publishers offered (``offered_qos_profiles``), the
  RIHS01 ``type_description_hash`` and its message count; the bag's ``message_count``, ``starting_time``
  and ``duration``;
* ``DIR/<DIR name>.mcap``: MCAP with profile ``ros2`` and zstd-compressed chunks; one schema per message
  type (name ``pkg/msg/Name``, encoding ``ros2msg``: the type's definition followed by every type it
  depends on, each introduced by a line of 80 ``=`` and ``MSG: pkg/Name``); one channel per topic
  (message encoding ``cdr``, metadata ``offered_qos_profiles``); the messages are the CDR bytes as
  received (rclpy ``raw=True`` subscriptions, never deserialised), each stamped (log time = publish time)
  with the recorder node's clock at reception, in ns: with ``use_sim_time`` that is simulation time, like
  ``ros2 bag record --use-sim-time``.

Reading it
----------
* ``ros2 bag info DIR`` and ``ros2 bag play DIR`` on a ROS 2 install (Jazzy or later);
* ``rosbags.highlevel.AnyReader([Path(DIR)])`` in Python, ``reader.deserialize(raw, connection.msgtype)``;
* Foxglove opens ``DIR/<DIR name>.mcap``.

Pieces: :class:`BagWriter` (the bag, usable without a ROS graph), :func:`recording_qos` (the QoS that
hears every publisher of a topic), :class:`TopicTap` (discovers every topic with a publisher on a node
and hands each raw message to a :class:`TopicSink`: the bag here, the Foxglove relay in
``foxglove_relay``), :class:`TopicRecorder` (the node ``recorder``: a tap into a bag). Message
definitions and type hashes come from rosbags' Jazzy typestore (:func:`check_type`), so a topic whose type
it does not know (or knows in another version) is left out.
"""

from __future__ import annotations

import errno
import importlib
import threading
import time
from collections.abc import Collection, Iterable, Sequence
from pathlib import Path
from types import TracebackType
from typing import Any, Protocol

from rclpy.clock import Clock, ClockType
from rclpy.duration import Duration
from rclpy.node import Node
from rclpy.qos import DurabilityPolicy, HistoryPolicy, QoSProfile, ReliabilityPolicy
from rosbags.interfaces import (
    Connection,
    Qos,
    QosDurability,
    QosHistory,
    QosLiveliness,
    QosReliability,
    QosTime,
)
from rosbags.rosbag2 import CompressionFormat, CompressionMode, StoragePlugin, Writer
from rosbags.typesys import Stores, TypesysError, get_typestore
from rosbags.typesys.store import Typestore

from turtlelib.util.timebase import NS_PER_S

BAG_VERSION = 9
METADATA_FILE = "metadata.yaml"
MESSAGE_ENCODING = "cdr"
# rosbag2 reads custom_data as a map of strings (yaml-cpp rejects the null rosbags writes for none)
CUSTOM_DATA = {"recorded_by": __name__}
# Queue of each recording subscription: room for bursts when the executor falls behind
RECORD_DEPTH = 200
# Wall time between two flushes of a bag: the pending MCAP chunk is closed and written to the file, so a
# recorder killed with SIGKILL leaves every message but those of its last FLUSH_PERIOD_S in whole chunks
# (nuturtle_tools.bag_recovery reads them back)
FLUSH_PERIOD_S = 1.0


def _bag_time(duration: Duration) -> QosTime:
    return QosTime(*divmod(int(duration.nanoseconds), NS_PER_S))


def _bag_qos(profile: QoSProfile) -> Qos:
    """rosbags' form of an rclpy QoS profile (policies matched by name, durations as sec + nsec)."""
    return Qos(
        history=QosHistory[profile.history.name],
        depth=int(profile.depth),
        reliability=QosReliability[profile.reliability.name],
        durability=QosDurability[profile.durability.name],
        deadline=_bag_time(profile.deadline),
        lifespan=_bag_time(profile.lifespan),
        liveliness=QosLiveliness[profile.liveliness.name],
        liveliness_lease_duration=_bag_time(profile.liveliness_lease_duration),
        avoid_ros_namespace_conventions=bool(profile.avoid_ros_namespace_conventions),
    )


def _remove_bag(path: Path) -> None:
    """Delete the bag directory ``path`` (metadata.yaml and .mcap files only); FileExistsError when
    ``path`` is anything else."""
    entries = list(path.iterdir()) if path.is_dir() else None
    if entries is None or not all(
        entry.is_file() and (entry.name == METADATA_FILE or entry.suffix == ".mcap") for entry in entries
    ):
        raise FileExistsError(f"{path} exists and is not a rosbag2 MCAP bag: not replacing it")
    for entry in entries:
        entry.unlink()
    path.rmdir()


def check_type(typestore: Typestore, type_name: str, type_hashes: Collection[str] = ()) -> None:
    """LookupError unless ``typestore`` knows ``type_name`` (``pkg/msg/Name``) with the RIHS01 hash of every
    one of ``type_hashes`` (the publishers' ``RIHS01_<hex>``): the same definition on both sides."""
    try:
        known_hash = typestore.hash_rihs01(type_name)
    except (KeyError, TypesysError) as error:
        raise LookupError(f"the typestore does not know {type_name}") from error
    foreign = sorted(set(type_hashes) - {known_hash})
    if foreign:
        raise LookupError(
            f"the publishers' {type_name} ({', '.join(foreign)}) is not the typestore's ({known_hash})"
        )


class TopicSink(Protocol):
    """Where a :class:`TopicTap` sends what it hears: ``add_topic`` once per topic (ValueError, LookupError:
    the topic is left out), then ``write(topic, cdr_bytes, timestamp_ns)`` for each message."""

    def add_topic(
        self,
        topic: str,
        type_name: str,
        offered_qos_profiles: Sequence[QoSProfile] = (),
        type_hashes: Collection[str] = (),
    ) -> None: ...

    def write(self, topic: str, data: bytes, timestamp_ns: int) -> None: ...


class ClosingSink:
    """What the bag and the relay share: a lock, the messages written per topic (``message_counts``),
    ``closed``, and use as a context manager; a subclass implements ``close()``."""

    def __init__(self) -> None:
        self._lock = threading.Lock()
        self._counts: dict[str, int] = {}
        self.closed = False

    @property
    def message_counts(self) -> dict[str, int]:
        """Messages written so far, by topic."""
        with self._lock:
            return dict(self._counts)

    def close(self) -> None:
        raise NotImplementedError

    def __enter__(self) -> ClosingSink:
        return self

    def __exit__(
        self, exc_type: type[BaseException] | None, exc: BaseException | None, tb: TracebackType | None
    ) -> None:
        self.close()


class TeeSink:
    """One tap into several sinks: a topic goes to every sink that accepts it (``add_topic`` raises the
    first refusal only when all refuse), and each message to the sinks of its topic."""

    def __init__(self, *sinks: TopicSink) -> None:
        self.sinks = sinks
        self._routes: dict[str, list[TopicSink]] = {}

    def add_topic(
        self,
        topic: str,
        type_name: str,
        offered_qos_profiles: Sequence[QoSProfile] = (),
        type_hashes: Collection[str] = (),
    ) -> None:
        accepted, refusals = [], []
        for sink in self.sinks:
            try:
                sink.add_topic(topic, type_name, offered_qos_profiles, type_hashes)
                accepted.append(sink)
            except (LookupError, ValueError) as error:
                refusals.append(error)
        if not accepted:
            raise refusals[0]
        self._routes[topic] = accepted

    def write(self, topic: str, data: bytes, timestamp_ns: int) -> None:
        for sink in self._routes[topic]:
            sink.write(topic, data, timestamp_ns)


class BagWriter(ClosingSink):
    """A rosbag2 bag directory at ``path`` (module docstring) written through ``rosbags.rosbag2.Writer``;
    thread safe; use as a context manager.

    ``add_topic(topic, type_name, offered_qos_profiles)`` once per topic, then ``write(topic, cdr_bytes,
    timestamp_ns)``, which closes the pending chunk and writes it to the file every ``FLUSH_PERIOD_S`` of
    wall time (what a kill leaves, :mod:`nuturtle_tools.bag_recovery`, loses at most that); ``close()``
    (idempotent) finishes the .mcap file and writes metadata.yaml. ``path``
    must not exist (FileExistsError), unless ``overwrite`` and it is a bag, which is then replaced.
    ``typestore`` (default: rosbags' ROS 2 Jazzy types) gives the definitions and type hashes.
    """

    def __init__(self, path: str | Path, typestore: Typestore | None = None, overwrite: bool = False) -> None:
        self.path = Path(path)
        self.typestore = typestore or get_typestore(Stores.ROS2_JAZZY)
        if self.path.exists():
            if not overwrite:
                raise FileExistsError(f"{self.path} exists already")
            _remove_bag(self.path)
        self._bag = Writer(self.path, version=BAG_VERSION, storage_plugin=StoragePlugin.MCAP)
        self._bag.set_compression(CompressionMode.STORAGE, CompressionFormat.ZSTD)
        for key, value in CUSTOM_DATA.items():
            self._bag.set_custom_data(key, value)
        self._bag.open()
        self._flush()
        self._flushed_at = time.monotonic()
        self._connections: dict[str, Connection] = {}
        # the first OSError of a write (the bag is then no longer written)
        self.failure: OSError | None = None
        super().__init__()

    @property
    def topics(self) -> list[str]:
        """The registered topics, in order of registration."""
        return list(self._connections)

    @property
    def message_count(self) -> int:
        """Messages written so far, all topics."""
        return sum(self.message_counts.values())

    def add_topic(
        self,
        topic: str,
        type_name: str,
        offered_qos_profiles: Sequence[QoSProfile] = (),
        type_hashes: Collection[str] = (),
    ) -> None:
        """Register ``topic`` of ``type_name`` (``pkg/msg/Name``) with the QoS profiles its publishers offer.

        ``type_hashes``: the publishers' RIHS01 hashes of the type (``RIHS01_<hex>``), each of which must
        be the typestore's. ValueError when the topic is already there; LookupError when the typestore
        does not know the type or knows another definition of it.
        """
        with self._lock:
            if topic in self._connections:
                raise ValueError(f"topic {topic!r} is already recorded")
            check_type(self.typestore, type_name, type_hashes)
            self._connections[topic] = self._bag.add_connection(
                topic,
                type_name,
                typestore=self.typestore,
                serialization_format=MESSAGE_ENCODING,
                offered_qos_profiles=[_bag_qos(profile) for profile in offered_qos_profiles],
            )
            self._counts[topic] = 0

    def write(self, topic: str, data: bytes, timestamp_ns: int) -> None:
        """Append one CDR-serialised message of a registered topic (KeyError otherwise) stamped
        ``timestamp_ns``; ignored once closed or failed. An OSError of the file (a full disk: ENOSPC, a
        file size limit: EFBIG) is kept in ``failure`` and ends the writing: :meth:`check` raises it."""
        with self._lock:
            if self.closed or self.failure is not None:
                return
            try:
                self._bag.write(self._connections[topic], int(timestamp_ns), data)
                if time.monotonic() - self._flushed_at >= FLUSH_PERIOD_S:
                    self._flush()
                    self._flushed_at = time.monotonic()
            except OSError as error:
                self.failure = error
                return
            self._counts[topic] += 1

    def _flush(self) -> None:
        """Close the pending chunk of rosbags' MCAP storage writer and write the file's buffer out."""
        storage = self._bag.storage
        if storage.chunk.bio.tell():
            storage.close_chunk()
        storage.bio.flush()

    def check(self) -> None:
        """OSError, naming the bag, once a write failed (``failure``)."""
        if self.failure is not None:
            code = errno.errorcode.get(self.failure.errno or 0)
            reason = f"{self.failure.strerror} ({code})" if code else str(self.failure)
            raise OSError(f"cannot write the bag {self.path.name}/: {reason}")

    def close(self) -> None:
        """Finish the .mcap file (summary and index) and write metadata.yaml (idempotent). After a failed
        write the bag is left as it is (the replay recovers its complete chunks, docs/replay.md) and
        :meth:`check` raises."""
        with self._lock:
            if self.closed:
                return
            self.closed = True
            try:
                self._bag.close()
            except OSError as error:
                self.failure = self.failure or error
        self.check()


def absolute(topic: str) -> str:
    """The topic name with its leading slash (the form discovery gives)."""
    return topic if topic.startswith("/") else "/" + topic


def message_class(type_name: str) -> type:
    """The generated Python class of ``pkg/msg/Name``: ValueError for another form of name,
    ImportError/AttributeError when it is not installed."""
    package, interface, name = type_name.split("/")
    return getattr(importlib.import_module(f"{package}.{interface}"), name)


def recording_qos(offered: Iterable[QoSProfile]) -> QoSProfile:
    """The QoS that hears every publisher, as rosbag2 chooses it: reliable only if all publishers are,
    transient local only if all are (so latched messages are delivered; a transient-local subscription
    would not match a volatile publisher), keep last ``RECORD_DEPTH``."""
    profiles = list(offered)
    reliable = all(p.reliability == ReliabilityPolicy.RELIABLE for p in profiles)
    latched = all(p.durability == DurabilityPolicy.TRANSIENT_LOCAL for p in profiles)
    return QoSProfile(
        history=HistoryPolicy.KEEP_LAST,
        depth=RECORD_DEPTH,
        reliability=ReliabilityPolicy.RELIABLE if reliable else ReliabilityPolicy.BEST_EFFORT,
        durability=DurabilityPolicy.TRANSIENT_LOCAL if latched else DurabilityPolicy.VOLATILE,
    )


class TopicTap:
    """Discovery on ``node``: subscribes (raw CDR, :func:`recording_qos`) to every topic that has a
    publisher and hands each message to ``sink``, stamped with ``node``'s clock at reception (simulation
    time when the node uses it).

    Topics are discovered now and then every ``discovery_period_s`` (wall time); topics in ``exclude``,
    with several types, or whose type has no Python class here or that the sink refuses are left out with
    one warning each: ``not <purpose> <topic>: <reason>``.
    """

    def __init__(
        self,
        node: Node,
        sink: TopicSink,
        exclude: Iterable[str] = (),
        discovery_period_s: float = 0.2,
        purpose: str = "recording",
    ) -> None:
        self.node = node
        self.sink = sink
        self.purpose = purpose
        self._exclude = set(exclude)
        self._left_out: set[str] = set()
        self._subscriptions: dict[str, Any] = {}
        self.discover()
        node.create_timer(discovery_period_s, self.discover, clock=Clock(clock_type=ClockType.STEADY_TIME))

    @property
    def topics(self) -> list[str]:
        """The topics tapped so far, in order of discovery."""
        return list(self._subscriptions)

    def discover(self) -> None:
        """Subscribe to every new topic that has a publisher."""
        for topic, type_names in self.node.get_topic_names_and_types():
            if topic in self._subscriptions or topic in self._left_out or topic in self._exclude:
                continue
            publishers = self.node.get_publishers_info_by_topic(topic)
            if not publishers:
                continue
            if len(type_names) != 1:
                self._leave_out(topic, f"it has several types {type_names}")
                continue
            offered = [p.qos_profile for p in publishers]
            hashes = {str(p.topic_type_hash) for p in publishers} - {"INVALID"}
            try:
                message_type = message_class(type_names[0])
                self.sink.add_topic(topic, type_names[0], offered, hashes)
            except (ImportError, AttributeError, LookupError, ValueError) as error:
                self._leave_out(topic, str(error))
                continue
            self._subscriptions[topic] = self.node.create_subscription(
                message_type,
                topic,
                lambda data, topic=topic: self.sink.write(
                    topic, data, self.node.get_clock().now().nanoseconds
                ),
                recording_qos(offered),
                raw=True,
            )

    def _leave_out(self, topic: str, reason: str) -> None:
        self._left_out.add(topic)
        self.node.get_logger().warning(f"not {self.purpose} {topic}: {reason}")


class TopicRecorder(Node):
    """Node ``recorder``: a :class:`TopicTap` into ``writer``, a :class:`BagWriter` or a :class:`TeeSink`
    that includes one (pass ``use_sim_time`` to record in simulation time); kwargs go to rclpy's Node."""

    def __init__(
        self,
        writer: TopicSink,
        exclude: Iterable[str] = (),
        discovery_period_s: float = 0.2,
        **kwargs: Any,
    ) -> None:
        super().__init__("recorder", **kwargs)
        self.writer = writer
        self.tap = TopicTap(self, writer, exclude, discovery_period_s)

    @property
    def recorded_topics(self) -> list[str]:
        return self.tap.topics
