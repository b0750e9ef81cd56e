"""Watch a running system from Foxglove: every ROS topic relayed live on a Foxglove WebSocket (foxglove-sdk).

Protocol: the Foxglove WebSocket protocol (subprotocol ``foxglove.sdk.v1``) served by ``foxglove-sdk``.
Each topic is one channel: schema name ``pkg/msg/Name``, schema encoding ``ros2msg`` with the same schema
text a rosbag2 MCAP recording holds (rosbags' ``generate_msgdef``: the type's definition, then each type it
uses after a line of 80 ``=`` and ``MSG: pkg/Name``), message encoding ``cdr``; each message is the CDR
bytes as received (rclpy ``raw=True``), with log time = the relaying node's clock at reception in ns
(simulation time under ``use_sim_time``). The server advertises the ``time`` capability and broadcasts
that clock (at most every ``TIME_PERIOD_NS`` of it), so Foxglove's timeline follows simulation time.

Latched topics (every publisher transient local, such as ``slam/map`` or ``nusim/walls``) keep what a
transient-local subscriber would get, which is sent again on its channel whenever a client subscribes, so a
viewer that connects late still sees the map. A latched TFMessage topic (``/tf_static``, where each node
publishes its own static transforms) keeps what tf2 holds: the union of every message's transforms, the
newest per child frame, sent as one message (``nusim/world -> map`` from one publisher and the LiDAR mount
from another both reach a late viewer). Any other latched topic keeps its last message: rclpy's message
info names no publisher, so one message per publisher cannot be told apart there (every such topic here has
one publisher). (The protocol has no per-client send: clients already subscribed receive that message
twice.)

Without tf2_msgs (the wheels-only install) no node broadcasts ``/tf``. The demo and the replay then give
the relay the transforms the 3D panel needs from what the run already knows: ``tf_from_odometry`` topics
(nav_msgs/Odometry) are also relayed as ``/tf`` (tf2_msgs/TFMessage, ``header.frame_id ->
child_frame_id``), and ``static_transforms`` are served on the latched ``/tf_static``.

Pieces: :class:`FoxgloveRelay` (the server, a :class:`~nuturtle_tools.recorder.TopicSink`, usable without a
ROS graph), :class:`FoxgloveRelayNode` (the node ``foxglove_relay``: a
:class:`~nuturtle_tools.recorder.TopicTap` into a relay, ``ros2 run nuturtle_tools foxglove_relay``).

Parameters of the node (:class:`~nuturtle_tools.relay_config.RelayConfig`, read-only): ``host``
(127.0.0.1), ``port`` (8765; 0: any free port), ``discovery_period`` (0.5 s between two looks for new
topics). docs/live.md has the rest.

Binding: ``host`` 127.0.0.1 (the default) serves this machine only. Any other address (``0.0.0.0``: every
interface) lets anyone on that network read every topic of the system: choose it explicitly.
"""

from __future__ import annotations

import importlib.util
import math
import sys
from collections.abc import Collection, Iterable, Sequence
from dataclasses import dataclass
from typing import Any

from rclpy.node import Node
from rclpy.qos import DurabilityPolicy, QoSProfile
from rosbags.typesys import Stores, get_typestore
from rosbags.typesys.store import Typestore

from nuturtle_ros_common.node_main import run_node
from nuturtle_ros_common.ros_params import declare_dataclass
from turtlelib import Transform2D

from .recorder import MESSAGE_ENCODING, ClosingSink, TopicTap, absolute, check_type
from .relay_config import DEFAULT_HOST, DEFAULT_PORT, RelayConfig

SCHEMA_ENCODING = "ros2msg"
# Least clock advance (ns) between two time broadcasts: 20 Hz
TIME_PERIOD_NS = 50_000_000
TF_TOPIC = "/tf"
TF_STATIC_TOPIC = "/tf_static"
TF_TYPE = "tf2_msgs/msg/TFMessage"
ODOMETRY_TYPE = "nav_msgs/msg/Odometry"


@dataclass(frozen=True)
class StaticTransform:
    """``T_parent_child``: the planar pose of frame ``child`` in frame ``parent`` (both non-empty)."""

    parent: str
    child: str
    T_parent_child: Transform2D

    def __post_init__(self) -> None:
        if not self.parent or not self.child or self.parent == self.child:
            raise ValueError(f"a transform needs two different frames, got {self.parent!r} -> {self.child!r}")


class _LatchedResend:
    """Server listener: on a client's subscription to a latched channel, its last message again."""

    def __init__(self, relay: FoxgloveRelay) -> None:
        self._relay = relay

    def on_subscribe(self, client: Any, channel: Any) -> None:
        self._relay.resend_latched(channel.id)

    def on_unsubscribe(self, client: Any, channel: Any) -> None:
        """Nothing to do: the server stops sending by itself."""


class FoxgloveRelay(ClosingSink):
    """A Foxglove WebSocket server on ``host:port`` relaying ROS topics (module docstring); thread safe;
    use as a context manager (``close()`` stops the server).

    ``add_topic(topic, type_name, offered_qos_profiles, type_hashes)`` advertises a channel (ValueError
    when the topic is already there; LookupError when the typestore does not know the type or knows another
    definition), ``write(topic, cdr_bytes, timestamp_ns)`` sends a message to the clients subscribed to it.
    ``port`` is the bound port (the free one chosen for port 0); ``url`` ``ws://host:port``. OSError with
    the address and the reason when the server cannot bind (the port is in use, the address is not this
    machine's). ``typestore`` (default: rosbags' ROS 2 Jazzy types) gives the schemas; ``name`` is the
    server's name shown to clients. ``tf_from_odometry`` (nav_msgs/Odometry topics) are also relayed as
    their transforms on ``/tf``, and ``static_transforms`` are served on the latched ``/tf_static``: for a
    system without tf2_msgs (module docstring).
    """

    def __init__(
        self,
        host: str = DEFAULT_HOST,
        port: int = DEFAULT_PORT,
        name: str = "nuturtle",
        typestore: Typestore | None = None,
        tf_from_odometry: Collection[str] = (),
        static_transforms: Sequence[StaticTransform] = (),
    ) -> None:
        import foxglove
        from foxglove.websocket import Capability

        config = RelayConfig(host=host, port=port)
        self.typestore = typestore or get_typestore(Stores.ROS2_JAZZY)
        self._foxglove = foxglove
        self._context = foxglove.Context()
        super().__init__()
        self._channels: dict[str, Any] = {}
        # latched channels by id, the last message (data, log time) of each, and for a latched TFMessage
        # channel its transforms by child frame
        self._latched_channels: dict[int, Any] = {}
        self._latched: dict[int, tuple[bytes, int]] = {}
        self._static_transforms: dict[int, dict[str, Any]] = {}
        self._tf_from_odometry = {absolute(topic) for topic in tf_from_odometry}
        self._last_time_ns: int | None = None
        try:
            self._server = foxglove.start_server(
                name=name,
                host=config.host,
                port=config.port,
                context=self._context,
                capabilities=[Capability.Time],
                server_listener=_LatchedResend(self),
                supported_encodings=[MESSAGE_ENCODING],
            )
        except RuntimeError as error:
            hint = (
                " (another relay or foxglove_bridge holds it: choose another port)"
                if "in use" in str(error)
                else ""
            )
            raise OSError(
                f"cannot serve the Foxglove WebSocket on {config.host}:{config.port}: {error}{hint}"
            ) from error
        self.host = config.host
        self.port = int(self._server.port)
        if self._tf_from_odometry:
            self._add_channel(TF_TOPIC, TF_TYPE, latched=False)
        if static_transforms:
            self._add_channel(TF_STATIC_TOPIC, TF_TYPE, latched=True)
            self.write(
                TF_STATIC_TOPIC, self._tf_message([_stamped(self.typestore, t) for t in static_transforms]), 0
            )

    @property
    def url(self) -> str:
        host = f"[{self.host}]" if ":" in self.host else self.host
        return f"ws://{host}:{self.port}"

    @property
    def topics(self) -> list[str]:
        """The relayed topics (channels), in order of advertisement."""
        with self._lock:
            return list(self._channels)

    def add_topic(
        self,
        topic: str,
        type_name: str,
        offered_qos_profiles: Sequence[QoSProfile] = (),
        type_hashes: Collection[str] = (),
    ) -> None:
        """Advertise ``topic`` of ``type_name``; latched when every offered profile is transient local."""
        check_type(self.typestore, type_name, type_hashes)
        latched = bool(offered_qos_profiles) and all(
            p.durability == DurabilityPolicy.TRANSIENT_LOCAL for p in offered_qos_profiles
        )
        self._add_channel(topic, type_name, latched)

    def _add_channel(self, topic: str, type_name: str, latched: bool) -> None:
        definition, _ = self.typestore.generate_msgdef(type_name, ros_version=2)
        schema = self._foxglove.Schema(name=type_name, encoding=SCHEMA_ENCODING, data=definition.encode())
        with self._lock:
            if topic in self._channels:
                raise ValueError(f"topic {topic!r} is already relayed")
            channel = self._foxglove.Channel(
                topic, schema=schema, message_encoding=MESSAGE_ENCODING, context=self._context
            )
            self._channels[topic] = channel
            self._counts[topic] = 0
            if latched:
                self._latched_channels[channel.id()] = channel
                if type_name == TF_TYPE:
                    self._static_transforms[channel.id()] = {}

    def write(self, topic: str, data: bytes, timestamp_ns: int) -> None:
        """Send one CDR message of an advertised topic (KeyError otherwise) with log time ``timestamp_ns``
        (and, for a ``tf_from_odometry`` topic, its transform on ``/tf``); ignored once closed."""
        timestamp_ns = int(timestamp_ns)
        with self._lock:
            if self.closed:
                return
            channel = self._channels[topic]
            channel.log(data, log_time=timestamp_ns)
            self._counts[topic] += 1
            if channel.id() in self._static_transforms:
                self._latched[channel.id()] = (self._merged_transforms(channel.id(), data), timestamp_ns)
            elif channel.id() in self._latched_channels:
                self._latched[channel.id()] = (data, timestamp_ns)
            if self._last_time_ns is None or timestamp_ns - self._last_time_ns >= TIME_PERIOD_NS:
                self._last_time_ns = timestamp_ns
                self._server.broadcast_time(timestamp_ns)
        if topic in self._tf_from_odometry:
            self.write(TF_TOPIC, self._odometry_tf(data), timestamp_ns)

    def resend_latched(self, channel_id: int) -> None:
        """Send the last message of a latched channel again (nothing for another channel or none yet)."""
        with self._lock:
            if self.closed or channel_id not in self._latched:
                return
            data, timestamp_ns = self._latched[channel_id]
            self._latched_channels[channel_id].log(data, log_time=timestamp_ns)

    def _merged_transforms(self, channel_id: int, data: bytes) -> bytes:
        """The CDR TFMessage of every transform the channel has carried, the newest per child frame, after
        the TFMessage ``data``."""
        by_child = self._static_transforms[channel_id]
        for transform in self.typestore.deserialize_cdr(data, TF_TYPE).transforms:
            by_child[transform.child_frame_id] = transform
        return self._tf_message(list(by_child.values()))

    def _odometry_tf(self, data: bytes) -> bytes:
        """The CDR TFMessage of one nav_msgs/Odometry: ``header.frame_id -> child_frame_id`` at its pose."""
        types = self.typestore.types
        odometry = self.typestore.deserialize_cdr(data, ODOMETRY_TYPE)
        pose = odometry.pose.pose
        transform = types["geometry_msgs/msg/Transform"](
            translation=types["geometry_msgs/msg/Vector3"](
                x=pose.position.x, y=pose.position.y, z=pose.position.z
            ),
            rotation=pose.orientation,
        )
        stamped = types["geometry_msgs/msg/TransformStamped"](
            header=odometry.header, child_frame_id=odometry.child_frame_id, transform=transform
        )
        return self._tf_message([stamped])

    def _tf_message(self, transforms: list[Any]) -> bytes:
        message = self.typestore.types[TF_TYPE](transforms=transforms)
        return bytes(self.typestore.serialize_cdr(message, TF_TYPE))

    def close(self) -> None:
        """Stop the server (idempotent)."""
        with self._lock:
            if self.closed:
                return
            self.closed = True
        self._server.stop()


def _stamped(typestore: Typestore, static: StaticTransform) -> Any:
    """geometry_msgs/TransformStamped (rosbags type) of a planar transform, stamp 0 (static)."""
    types = typestore.types
    T = static.T_parent_child
    half = 0.5 * T.theta
    return types["geometry_msgs/msg/TransformStamped"](
        header=types["std_msgs/msg/Header"](
            stamp=types["builtin_interfaces/msg/Time"](sec=0, nanosec=0), frame_id=static.parent
        ),
        child_frame_id=static.child,
        transform=types["geometry_msgs/msg/Transform"](
            translation=types["geometry_msgs/msg/Vector3"](x=T.x, y=T.y, z=0.0),
            rotation=types["geometry_msgs/msg/Quaternion"](x=0.0, y=0.0, z=math.sin(half), w=math.cos(half)),
        ),
    )


def tf2_msgs_installed() -> bool:
    """Whether the nodes here can broadcast /tf (tf2_msgs importable: every full ROS install)."""
    return importlib.util.find_spec("tf2_msgs") is not None


def slam_view_transforms(slam: Any, extra: Sequence[StaticTransform] = ()) -> dict[str, Any]:
    """The relay's keyword arguments ``tf_from_odometry`` and ``static_transforms`` for a 3D view around
    the `slam` node ``slam`` where no node broadcasts /tf (module docstring): slam's pose (its ``~/odom``,
    ``/slam/odom`` or ``/<namespace>/slam/odom``: ``map_id -> body_id``), its sensor mount (``body_id ->
    sensor_id``) and the ``extra`` transforms the caller knows; {} when tf2_msgs is installed (the nodes'
    own /tf is relayed then)."""
    if tf2_msgs_installed():
        return {}
    frames = slam.node_config
    mount = StaticTransform(frames.body_id, frames.sensor_id, slam.config.T_body_sensor)
    return {"tf_from_odometry": [slam.resolve_topic_name("~/odom")], "static_transforms": [mount, *extra]}


class FoxgloveRelayNode(Node):
    """Node ``foxglove_relay``: every topic with a publisher relayed to a Foxglove WebSocket (module
    docstring), discovered every ``discovery_period`` s, including topics that appear later; each
    subscription's QoS hears all of its publishers (best effort if any publisher is, transient local if
    all are: :func:`~nuturtle_tools.recorder.recording_qos`).

    Parameters: :class:`RelayConfig` (read-only). ``exclude`` topics are not relayed;
    ``tf_from_odometry`` and ``static_transforms`` as for :class:`FoxgloveRelay`. kwargs go to rclpy's
    Node. OSError when the server cannot bind, ValueError for an invalid parameter.
    """

    def __init__(
        self,
        exclude: Iterable[str] = (),
        tf_from_odometry: Collection[str] = (),
        static_transforms: Sequence[StaticTransform] = (),
        **kwargs: Any,
    ) -> None:
        super().__init__("foxglove_relay", **kwargs)
        self.config = declare_dataclass(self, RelayConfig)
        self.relay = FoxgloveRelay(
            self.config.host,
            self.config.port,
            name=self.get_fully_qualified_name(),
            tf_from_odometry=tf_from_odometry,
            static_transforms=static_transforms,
        )
        self.get_logger().info(f"Foxglove WebSocket on {self.relay.url} (Foxglove: Open connection)")
        self.tap = TopicTap(self, self.relay, exclude, self.config.discovery_period, purpose="relaying")

    def destroy_node(self) -> None:
        """Stop the server, then destroy the node."""
        self.relay.close()
        super().destroy_node()


def main(args: list[str] | None = None) -> None:
    sys.exit(run_node(lambda: FoxgloveRelayNode(), "foxglove_relay", __doc__, args))


if __name__ == "__main__":
    main()
