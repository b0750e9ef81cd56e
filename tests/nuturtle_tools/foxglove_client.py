"""A Foxglove WebSocket client for the tests, independent of foxglove-sdk: Python ``websockets`` (sync client)
speaking subprotocol ``foxglove.sdk.v1``, and rosbags for the CDR, decoded with a typestore built only from
each channel's own ``ros2msg`` schema text.

Protocol (https://github.com/foxglove/ws-protocol): JSON text frames ``serverInfo``, ``advertise``
(``channels``: id, topic, encoding, schemaName, schemaEncoding, schema), ``unadvertise``; the client sends
``subscribe`` (``subscriptions``: id, channelId). Binary frames: opcode 1 message data (u32 subscription id,
u64 log time ns, payload), opcode 2 time (u64 ns); little endian.
"""

from __future__ import annotations

import contextlib
import json
import struct
import time
from collections import defaultdict
from collections.abc import Callable, Iterable
from dataclasses import dataclass
from typing import Any

from rosbags.typesys import Stores, get_types_from_msg, get_typestore
from websockets.exceptions import ConnectionClosed
from websockets.sync.client import ClientConnection, connect

SUBPROTOCOL = "foxglove.sdk.v1"
MESSAGE_DATA = 1
TIME = 2


@dataclass(frozen=True)
class Received:
    topic: str
    log_time_ns: int
    data: bytes


class FoxgloveClient:
    """Connects to ``url`` (retrying until ``timeout_s``), keeps the advertised ``channels`` by topic, the
    ``server_info``, every message of the subscribed topics (``messages[topic]``) and the broadcast
    ``times``; ``closed`` once the server has gone."""

    def __init__(self, url: str, timeout_s: float = 15.0) -> None:
        deadline = time.monotonic() + timeout_s
        self._stack = contextlib.ExitStack()
        while True:
            try:
                self.ws: ClientConnection = self._stack.enter_context(
                    connect(url, subprotocols=[SUBPROTOCOL], open_timeout=2.0)
                )
                break
            except OSError:
                if time.monotonic() > deadline:
                    raise
                time.sleep(0.1)
        self.server_info: dict[str, Any] = {}
        self.channels: dict[str, dict[str, Any]] = {}
        self.messages: dict[str, list[Received]] = defaultdict(list)
        self.times: list[int] = []
        self.closed = False
        self._subscriptions: dict[int, str] = {}
        self._stores: dict[str, Any] = {}

    def close(self) -> None:
        self._stack.close()

    def receive(self, timeout_s: float = 0.2) -> None:
        """Handle the frames that arrive within ``timeout_s``."""
        deadline = time.monotonic() + timeout_s
        while not self.closed and time.monotonic() < deadline:
            try:
                frame = self.ws.recv(timeout=max(deadline - time.monotonic(), 0.0))
            except TimeoutError:
                return
            except ConnectionClosed:
                self.closed = True
                return
            if isinstance(frame, str):
                self._on_json(json.loads(frame))
            elif frame[0] == MESSAGE_DATA:
                subscription, log_time_ns = struct.unpack_from("<IQ", frame, 1)
                topic = self._subscriptions[subscription]
                self.messages[topic].append(Received(topic, log_time_ns, bytes(frame[13:])))
            elif frame[0] == TIME:
                self.times.append(struct.unpack_from("<Q", frame, 1)[0])

    def _on_json(self, message: dict[str, Any]) -> None:
        if message["op"] == "serverInfo":
            self.server_info = message
        elif message["op"] == "advertise":
            self.channels.update({channel["topic"]: channel for channel in message["channels"]})

    def wait_for(self, predicate: Callable[[], bool], timeout_s: float = 10.0) -> bool:
        deadline = time.monotonic() + timeout_s
        while not predicate():
            if self.closed or time.monotonic() > deadline:
                return predicate()
            self.receive()
        return True

    def send_until_received(self, send: Callable[[int], None], topic: str, timeout_s: float = 10.0) -> bool:
        """``send(k)`` for k = 0, 1, ... until a message of ``topic`` has arrived (a subscription reaches the
        server some time after it is sent)."""
        deadline = time.monotonic() + timeout_s
        k = 0
        while not self.messages[topic] and not self.closed and time.monotonic() < deadline:
            send(k)
            k += 1
            self.receive(0.05)
        return bool(self.messages[topic])

    def subscribe(self, topics: Iterable[str]) -> None:
        subscriptions = []
        for topic in topics:
            subscription = len(self._subscriptions) + 1
            self._subscriptions[subscription] = topic
            subscriptions.append({"id": subscription, "channelId": self.channels[topic]["id"]})
        self.ws.send(json.dumps({"op": "subscribe", "subscriptions": subscriptions}))

    def decode(self, received: Received) -> Any:
        """The message, decoded by rosbags with the types of its channel's schema text only."""
        channel = self.channels[received.topic]
        assert (channel["encoding"], channel["schemaEncoding"]) == ("cdr", "ros2msg")
        store = self._stores.get(received.topic)
        if store is None:
            store = self._stores[received.topic] = get_typestore(Stores.EMPTY)
            store.register(get_types_from_msg(channel["schema"], channel["schemaName"]))
        return store.deserialize_cdr(received.data, channel["schemaName"])
