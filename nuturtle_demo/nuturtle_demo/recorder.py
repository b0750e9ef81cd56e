"""Record every ROS topic into one MCAP file laid out as rosbag2 writes it (`ros2 bag record -a -s mcap`).

File layout (MCAP profile ``ros2``)
-----------------------------------
* one Schema per message type: name ``pkg/msg/Name``, encoding ``ros2msg``, data = the type's ``.msg``
  text followed by each type it depends on (recursively, each once), every one introduced by a line of
  80 ``=`` and ``MSG: pkg/Name``, exactly the concatenation rosbag2 stores;
* one Channel per topic: message encoding ``cdr``, metadata ``offered_qos_profiles`` (the publishers'
  QoS as rosbag2's YAML) and ``topic_type_hash`` when the middleware reports it;
* Messages: the CDR bytes as received (rclpy ``raw=True`` subscriptions, never deserialised), with
  ``log_time = publish_time =`` the recorder node's clock at reception (ns); with ``use_sim_time`` that
  is simulation time, like ``ros2 bag record --use-sim-time``.

Pieces: :class:`MessageDefinitions` (the schema texts), :class:`Ros2McapWriter` (the file, usable without a
ROS graph), :class:`TopicRecorder` (an rclpy node that discovers every topic with a publisher, subscribes
with a QoS that hears all its publishers, and writes what arrives).

Readers: the ``rosbags`` library (``rosbags.highlevel.AnyReader`` on the ``.mcap`` file), Foxglove,
``ros2 bag play`` / ``ros2 bag info`` on a full ROS install.

Message definitions come from the ``.msg`` files installed with the message packages
(``<prefix>/share/<pkg>/msg/<Name>.msg``), searched under the ``AMENT_PREFIX_PATH`` prefixes, the Python
prefix and the prefix that holds the package's Python module.
"""

from __future__ import annotations

import importlib
import importlib.util
import os
import re
import sys
import threading
from collections.abc import Iterable
from pathlib import Path
from types import TracebackType
from typing import Any

import yaml
from mcap.writer import CompressionType, Writer
from rclpy.clock import Clock, ClockType
from rclpy.node import Node
from rclpy.qos import DurabilityPolicy, HistoryPolicy, QoSProfile, ReliabilityPolicy

MCAP_PROFILE = "ros2"
LIBRARY = "nuturtle_demo.recorder"
SCHEMA_ENCODING = "ros2msg"
MESSAGE_ENCODING = "cdr"
SEPARATOR = "=" * 80
# Queue of each recording subscription: room for bursts when the executor falls behind
RECORD_DEPTH = 200
# ROS 2 .msg primitive types (and ROS 1's time/duration): they have no definition of their own
PRIMITIVES = frozenset(
    "bool byte char float32 float64 int8 uint8 int16 uint16 int32 uint32 int64 uint64 string wstring "
    "time duration".split()
)
# a field's type: its name, then an optional string bound (string<=N) and array suffix ([], [N], [<=N])
FIELD_TYPE = re.compile(r"^(?P<base>[A-Za-z0-9_/]+?)(<=\d+)?(\[[^\]]*\])?$")


def split_type_name(type_name: str) -> tuple[str, str]:
    """``'pkg/msg/Name'`` or ``'pkg/Name'`` -> ``('pkg', 'Name')``; ValueError for anything else."""
    parts = type_name.split("/")
    if len(parts) == 3 and parts[1] == "msg" or len(parts) == 2:
        if all(parts):
            return parts[0], parts[-1]
    raise ValueError(f"not a message type name: {type_name!r}")


def field_types(msg_text: str, package: str) -> list[str]:
    """The non-primitive field types of a ``.msg`` text, as ``pkg/Name``, in order of appearance.

    Comments and constants (``TYPE NAME=VALUE``) are skipped; a bare ``Name`` is in ``package``.
    """
    types: list[str] = []
    for raw_line in msg_text.splitlines():
        line = raw_line.split("#", 1)[0].strip()
        if not line:
            continue
        tokens = line.split()
        if len(tokens) < 2 or "=" in tokens[1] or (len(tokens) > 2 and tokens[2].startswith("=")):
            continue
        match = FIELD_TYPE.match(tokens[0])
        if match is None:
            raise ValueError(f"cannot parse the field type of {raw_line!r}")
        base = match.group("base")
        if base in PRIMITIVES:
            continue
        name = base if "/" in base else f"{package}/{base}"
        types.append("/".join(split_type_name(name)))
    return types


class MessageDefinitions:
    """``.msg`` texts and rosbag2-style full definitions of message types, found on disk and cached."""

    def __init__(self, search_prefixes: Iterable[Path] | None = None) -> None:
        self._extra_prefixes = [Path(p) for p in search_prefixes or ()]
        self._texts: dict[str, str] = {}

    def _prefixes(self, package: str) -> list[Path]:
        prefixes = list(self._extra_prefixes)
        prefixes += [Path(p) for p in os.environ.get("AMENT_PREFIX_PATH", "").split(os.pathsep) if p]
        prefixes.append(Path(sys.prefix))
        spec = importlib.util.find_spec(package)
        if spec is not None and spec.origin is not None:
            # <prefix>/lib/pythonX.Y/site-packages/<package>/__init__.py
            prefixes += list(Path(spec.origin).resolve().parents)
        return prefixes

    def msg_text(self, type_name: str) -> str:
        """The ``.msg`` file of ``type_name`` as installed; LookupError when no prefix has it."""
        package, name = split_type_name(type_name)
        key = f"{package}/{name}"
        if key not in self._texts:
            for prefix in self._prefixes(package):
                candidate = prefix / "share" / package / "msg" / f"{name}.msg"
                if candidate.is_file():
                    self._texts[key] = candidate.read_text(encoding="utf-8")
                    break
            else:
                raise LookupError(f"no {package}/msg/{name}.msg under share/ of any ROS prefix")
        return self._texts[key]

    def full_definition(self, type_name: str) -> str:
        """The type's ``.msg`` text, then each dependency (depth first, each once) as
        ``\\n`` + 80 ``=`` + ``\\nMSG: pkg/Name\\n`` + its ``.msg`` text: rosbag2's ``ros2msg`` schema."""
        package, name = split_type_name(type_name)
        root = f"{package}/{name}"
        order: list[str] = []
        stack = list(reversed(field_types(self.msg_text(root), package)))
        while stack:
            dependency = stack.pop()
            if dependency == root or dependency in order:
                continue
            order.append(dependency)
            dependency_package = dependency.split("/")[0]
            stack += reversed(field_types(self.msg_text(dependency), dependency_package))
        text = self.msg_text(root)
        for dependency in order:
            text += f"\n{SEPARATOR}\nMSG: {dependency}\n{self.msg_text(dependency)}"
        return text


def message_class(type_name: str) -> type:
    """The generated Python class of ``pkg/msg/Name`` (ImportError/AttributeError when not installed)."""
    package, name = split_type_name(type_name)
    return getattr(importlib.import_module(f"{package}.msg"), name)


def qos_profiles_yaml(profiles: Iterable[Any]) -> str:
    """rosbag2's ``offered_qos_profiles`` YAML of rclpy QoSProfile objects (policy names in lower case,
    durations as ``{sec, nsec}``)."""

    def policy(value: Any) -> str:
        return value.name.lower()

    def duration(value: Any) -> dict[str, int]:
        sec, nsec = divmod(int(value.nanoseconds), 1_000_000_000)
        return {"sec": sec, "nsec": nsec}

    return yaml.safe_dump(
        [
            {
                "history": policy(p.history),
                "depth": int(p.depth),
                "reliability": policy(p.reliability),
                "durability": policy(p.durability),
                "deadline": duration(p.deadline),
                "lifespan": duration(p.lifespan),
                "liveliness": policy(p.liveliness),
                "liveliness_lease_duration": duration(p.liveliness_lease_duration),
                "avoid_ros_namespace_conventions": bool(p.avoid_ros_namespace_conventions),
            }
            for p in profiles
        ],
        sort_keys=False,
    )


class Ros2McapWriter:
    """An MCAP file in the rosbag2 layout (module docstring); thread safe; use as a context manager.

    ``add_topic(topic, type_name, ...)`` once per topic, then ``write(topic, cdr_bytes, log_time_ns)``.
    """

    def __init__(self, path: str | Path, definitions: MessageDefinitions | None = None) -> None:
        self.path = Path(path)
        self.definitions = definitions or MessageDefinitions()
        self._stream = open(self.path, "wb")  # noqa: SIM115 (closed in close())
        self._writer = Writer(self._stream, compression=CompressionType.ZSTD)
        self._writer.start(profile=MCAP_PROFILE, library=LIBRARY)
        self._schemas: dict[str, int] = {}
        self._channels: dict[str, int] = {}
        self._sequence: dict[str, int] = {}
        self._lock = threading.Lock()
        self.message_count = 0
        self.closed = False

    @property
    def topics(self) -> list[str]:
        return list(self._channels)

    def add_topic(
        self, topic: str, type_name: str, offered_qos_profiles: str = "", type_hash: str = ""
    ) -> None:
        """Register ``topic`` of ``type_name`` (``pkg/msg/Name``); ValueError when already there,
        LookupError when its definition cannot be found."""
        with self._lock:
            if topic in self._channels:
                raise ValueError(f"topic {topic!r} is already recorded")
            if type_name not in self._schemas:
                definition = self.definitions.full_definition(type_name)
                self._schemas[type_name] = self._writer.register_schema(
                    name=type_name, encoding=SCHEMA_ENCODING, data=definition.encode("utf-8")
                )
            metadata = {"offered_qos_profiles": offered_qos_profiles}
            if type_hash:
                metadata["topic_type_hash"] = type_hash
            self._channels[topic] = self._writer.register_channel(
                topic=topic,
                message_encoding=MESSAGE_ENCODING,
                schema_id=self._schemas[type_name],
                metadata=metadata,
            )
            self._sequence[topic] = 0

    def write(self, topic: str, data: bytes, log_time_ns: int) -> None:
        """Append one CDR-serialised message of a registered topic (KeyError otherwise)."""
        with self._lock:
            if self.closed:
                return
            channel_id = self._channels[topic]
            self._sequence[topic] += 1
            self._writer.add_message(
                channel_id=channel_id,
                log_time=int(log_time_ns),
                data=bytes(data),
                publish_time=int(log_time_ns),
                sequence=self._sequence[topic] % 2**32,
            )
            self.message_count += 1

    def close(self) -> None:
        """Write the summary and index and close the file (idempotent)."""
        with self._lock:
            if self.closed:
                return
            self.closed = True
            self._writer.finish()
            self._stream.close()

    def __enter__(self) -> Ros2McapWriter:
        return self

    def __exit__(
        self, exc_type: type[BaseException] | None, exc: BaseException | None, tb: TracebackType | None
    ) -> None:
        self.close()


def recording_qos(offered: list[Any]) -> QoSProfile:
    """The QoS that hears every publisher, as rosbag2 chooses it: reliable only if all publishers are,
    transient local only if all are (so latched messages are delivered), keep last ``RECORD_DEPTH``."""
    reliable = all(p.reliability == ReliabilityPolicy.RELIABLE for p in offered)
    latched = all(p.durability == DurabilityPolicy.TRANSIENT_LOCAL for p in offered)
    return QoSProfile(
        history=HistoryPolicy.KEEP_LAST,
        depth=RECORD_DEPTH,
        reliability=ReliabilityPolicy.RELIABLE if reliable else ReliabilityPolicy.BEST_EFFORT,
        durability=DurabilityPolicy.TRANSIENT_LOCAL if latched else DurabilityPolicy.VOLATILE,
    )


class TopicRecorder(Node):
    """Node ``recorder``: subscribes (raw CDR) to every topic that has a publisher and writes each message
    to a :class:`Ros2McapWriter` stamped with this node's clock (pass ``use_sim_time`` to record in
    simulation time).

    Topics are discovered at start and then every ``discovery_period_s`` (wall time); topics in
    ``exclude``, with several types, or whose type has no Python class or ``.msg`` file here are left out
    with a warning. kwargs go to rclpy's Node.
    """

    def __init__(
        self,
        writer: Ros2McapWriter,
        exclude: Iterable[str] = (),
        discovery_period_s: float = 0.2,
        **kwargs: Any,
    ) -> None:
        super().__init__("recorder", **kwargs)
        self.writer = writer
        self._exclude = set(exclude)
        self._left_out: set[str] = set()
        self._recording: dict[str, Any] = {}
        self.discover()
        self.create_timer(discovery_period_s, self.discover, clock=Clock(clock_type=ClockType.STEADY_TIME))

    @property
    def recorded_topics(self) -> list[str]:
        return list(self._recording)

    def discover(self) -> None:
        """Subscribe to every new topic that has a publisher."""
        for topic, type_names in self.get_topic_names_and_types():
            if topic in self._recording or topic in self._left_out or topic in self._exclude:
                continue
            publishers = self.get_publishers_info_by_topic(topic)
            if not publishers:
                continue
            if len(type_names) != 1:
                self._leave_out(topic, f"it has several types {type_names}")
                continue
            type_name = type_names[0]
            type_hash = str(publishers[0].topic_type_hash)
            try:
                message_type = message_class(type_name)
                self.writer.add_topic(
                    topic,
                    type_name,
                    qos_profiles_yaml(p.qos_profile for p in publishers),
                    "" if type_hash == "INVALID" else type_hash,
                )
            except (ImportError, AttributeError, LookupError, ValueError) as error:
                self._leave_out(topic, str(error))
                continue
            self._recording[topic] = self.create_subscription(
                message_type,
                topic,
                lambda data, topic=topic: self._on_message(topic, data),
                recording_qos([p.qos_profile for p in publishers]),
                raw=True,
            )

    def _leave_out(self, topic: str, reason: str) -> None:
        self._left_out.add(topic)
        self.get_logger().warning(f"not recording {topic}: {reason}")

    def _on_message(self, topic: str, data: bytes) -> None:
        self.writer.write(topic, data, self.get_clock().now().nanoseconds)
